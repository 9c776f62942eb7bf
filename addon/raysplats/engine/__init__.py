# The RaySplats render engine (id 'RAYSPLATS'): a thin RenderEngine subclass; final renders go to final.py,
# the viewport to viewport.py, the scene conversion to sync.py (BlendLuxCore's layout).
import bpy

from .. import errors
from . import final, passes, render_properties, sync, ui, viewport


class RaySplatsRenderEngine(bpy.types.RenderEngine):
    bl_idname = "RAYSPLATS"
    bl_label = "RaySplats"
    bl_use_preview = False
    bl_use_shading_nodes_custom = False  # Blender's material and light node UI (Principled etc.)
    bl_use_eevee_viewport = True  # Material Preview stays EEVEE (the splats' falloff material)

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.viewport_state = viewport.ViewportState()
        self.persistent_scene = None  # final.py: the last frame's scene, kept with Persistent Data

    def _fail(self, error):
        """Reports an exception of an entry point (errors.report_exception) and shows it in the render window."""
        self.error_set(errors.report_exception(self.report, error, "RaySplats: "))

    # Blender calls these entry points; an exception must not escape them (it would end a render with a half
    # result and a Python traceback in place of a message).
    def render(self, depsgraph):
        try:
            final.render_final(self, depsgraph)
        except Exception as error:
            self._fail(error)

    def update_render_passes(self, scene=None, renderlayer=None):
        passes.register_passes(self, scene, renderlayer)

    def view_update(self, context, depsgraph):
        try:
            viewport.view_update(self, context, depsgraph)
        except Exception as error:
            self._fail(error)

    def view_draw(self, context, depsgraph):
        try:
            viewport.view_draw(self, context, depsgraph)
        except Exception as error:
            self._fail(error)


def register():
    render_properties.register()
    passes.register()
    bpy.utils.register_class(RaySplatsRenderEngine)
    ui.register()


def unregister():
    ui.unregister()
    bpy.utils.unregister_class(RaySplatsRenderEngine)
    passes.unregister()
    render_properties.unregister()


__all__ = ["RaySplatsRenderEngine", "register", "unregister", "sync"]
