# The view transform RaySplats renders are meant to be seen through. Trained splat colours are display-referred
# sRGB values (the 3DGS training images), so the render shows them as trained only through Blender's "Standard"
# view transform (sRGB OETF, no tone curve); Filmic (3.x's default) and AgX (4.x's) compress and desaturate them.
# The RaySplats Film panel says so when another transform is set, with a button (this operator) that switches.
import bpy

from .. import errors

STANDARD_VIEW_TRANSFORM = "Standard"  # the same name in every supported Blender (3.4 to 5.x)


def shows_trained_colors(scene):
    """True when the scene's view transform shows splat colours as they were trained (Standard, no look)."""
    view = scene.view_settings
    return view.view_transform == STANDARD_VIEW_TRANSFORM and view.look in ("None", "")


class RAYSPLATS_OT_use_standard_view_transform(bpy.types.Operator):
    """Set Color Management to the Standard view transform with no look, which shows splat colours as trained"""
    bl_idname = "raysplats.use_standard_view_transform"
    bl_label = "Use Standard View Transform"
    bl_options = {"REGISTER", "UNDO"}

    @errors.reports_failures("Cannot switch the view transform: ")
    def execute(self, context):
        view = context.scene.view_settings
        view.view_transform = STANDARD_VIEW_TRANSFORM
        view.look = "None"
        return {"FINISHED"}


def draw_note(layout, scene):
    """A note with the switch button when the view transform would change the trained colours; nothing otherwise."""
    if shows_trained_colors(scene):
        return
    box = layout.box()
    view = scene.view_settings
    look = "" if view.look in ("None", "") else f" ({view.look})"
    # Two short lines: one long label is cut off at the Properties editor's default width.
    column = box.column(align=True)
    column.label(text=f"{view.view_transform}{look} view transform", icon="INFO")
    column.label(text="changes the trained colours", icon="BLANK1")
    box.operator(RAYSPLATS_OT_use_standard_view_transform.bl_idname, text="Use Standard")


def register():
    bpy.utils.register_class(RAYSPLATS_OT_use_standard_view_transform)


def unregister():
    bpy.utils.unregister_class(RAYSPLATS_OT_use_standard_view_transform)
