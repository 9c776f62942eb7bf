# How 3D views show a new object: Solid view coloured by its colour attribute, and enough EEVEE samples for
# Material Preview's stochastic transparency (what the splat import asks for).
from . import compat



def show_splat_colors_in_solid_views(context, obj):
    """Switches the Solid shading colour of every 3D view that shows `obj` to its colour attribute (the splat
    colour, polygon_mesh.ATTR_COLOR, the mesh's active colour attribute), so Solid and Edit Mode show the scene
    instead of grey polygons. Views of other scenes or whose local view leaves `obj` out keep their setting.
    Returns how many views were switched; without a window manager or windows (headless scripts), none."""
    window_manager = getattr(context, "window_manager", None)
    switched = 0
    for window in getattr(window_manager, "windows", ()):
        screen = window.screen
        if screen is None or window.scene != context.scene:
            continue
        for area in screen.areas:
            if area.type != "VIEW_3D":
                continue
            for space in area.spaces:
                if space.type == "VIEW_3D" and obj.visible_in_viewport_get(space):
                    space.shading.color_type = compat.SOLID_COLOR_TYPE_ATTRIBUTE
                    switched += 1
            area.tag_redraw()
    return switched


def raise_material_preview_samples(scene, samples):
    """Raises the scene's EEVEE viewport samples to at least `samples` (never lowers them). The import material's
    hashed (dithered) transparency is noisy until enough samples have accumulated: on unicorn_sh3_reordered.ply
    EEVEE's agreement with the RaySplats render was 23.5 / 22.6 dB PSNR (front / back) at EEVEE's default 16 samples
    and 27.8 / 27.2 dB at 64 (examples/material_preview_agreement.py, Blender 3.4)."""
    eevee = getattr(scene, "eevee", None)
    if eevee is not None and samples > 0 and eevee.taa_samples < samples:
        eevee.taa_samples = samples
