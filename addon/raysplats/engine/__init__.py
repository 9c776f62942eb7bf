# The RaySplats render engine (id 'RAYSPLATS'): a thin RenderEngine subclass; final renders go to final.py,
# the viewport to viewport.py, the scene conversion to sync.py (BlendLuxCore's layout).
import traceback

import bpy

from .. import native
from . import final, properties, sync, ui, viewport


class RaySplatsRenderEngine(bpy.types.RenderEngine):
    bl_idname = "RAYSPLATS"
    bl_label = "RaySplats"
    bl_use_preview = False
    bl_use_shading_nodes_custom = False  # Blender's material and light node UI (Principled etc.)
    bl_use_eevee_viewport = True  # Material Preview stays EEVEE (the splats' falloff material)

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.viewport_state = viewport.ViewportState()

    def _fail(self, error):
        message = f"RaySplats: {error}"
        self.report({"ERROR"}, message)
        if hasattr(self, "error_set"):
            self.error_set(message)

    def render(self, depsgraph):
        try:
            final.render_final(self, depsgraph)
        except (native.NativeModuleMissing, RuntimeError, ValueError, OSError) as error:
            self._fail(error)
        except Exception as error:  # never let an unexpected error take Blender down with a half result
            traceback.print_exc()
            self._fail(error)

    def update_render_passes(self, scene=None, renderlayer=None):
        self.register_pass(scene, renderlayer, "Combined", 4, "RGBA", "COLOR")
        if renderlayer.use_pass_z:
            self.register_pass(scene, renderlayer, "Depth", 1, "Z", "VALUE")
        if renderlayer.use_pass_normal:
            self.register_pass(scene, renderlayer, "Normal", 3, "XYZ", "VECTOR")

    def view_update(self, context, depsgraph):
        try:
            viewport.view_update(self, context, depsgraph)
        except Exception as error:
            self._fail(error)

    def view_draw(self, context, depsgraph):
        try:
            viewport.view_draw(self, context, depsgraph)
        except Exception as error:
            traceback.print_exc()
            self._fail(error)


def register():
    properties.register()
    bpy.utils.register_class(RaySplatsRenderEngine)
    ui.register()


def unregister():
    ui.unregister()
    bpy.utils.unregister_class(RaySplatsRenderEngine)
    properties.unregister()


__all__ = ["RaySplatsRenderEngine", "register", "unregister", "sync"]
