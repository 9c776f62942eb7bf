# Render passes of the RaySplats engine, all from the core's film channel table (_native.film_channels(),
# native/include/raysplats/render/film.h): registration (update_render_passes), the check boxes in View Layer >
# Passes, and the final render's writes. A channel the core adds appears here with no change to this module.
import bpy
import numpy as np

from .. import native
from ..blender import compat

# Passes Blender already has a view-layer check box for; the others get one in RaySplatsViewLayerPasses.
_BLENDER_TOGGLES = {"Depth": "use_pass_z", "Normal": "use_pass_normal", "Mist": "use_pass_mist",
                    "Position": "use_pass_position", "IndexOB": "use_pass_object_index",
                    "IndexMA": "use_pass_material_index", "Env": "use_pass_environment"}
# Passes whose check box is the Cycles add-on's (its view-layer property group, which every Blender here has), so that
# one check box serves both engines; without Cycles, a RaySplats check box.
_CYCLES_TOGGLES = {"Shadow Catcher": "use_pass_shadow_catcher"}
_ALWAYS = "Combined"
# Blender's (and Cycles') value for "nothing there" in float passes, e.g. the depth of the background.
_FAR = 1e10
# Without the native module only Combined exists (the engine then reports the missing module on render).
_COMBINED_ONLY = ({"key": "rgba", "pass_name": "Combined", "components": "RGBA", "kind": "COLOR",
                   "description": "Linear radiance"},)


def channels():
    try:
        return native.core().film_channels()
    except native.NativeModuleMissing:
        return _COMBINED_ONLY


def _toggle(view_layer, channel):
    """(owner, property name) of a channel's check box; None for Combined, which is always on."""
    name = channel["pass_name"]
    if name == _ALWAYS:
        return None
    if name in _BLENDER_TOGGLES:
        return view_layer, _BLENDER_TOGGLES[name]
    cycles = getattr(view_layer, "cycles", None)
    if name in _CYCLES_TOGGLES and hasattr(cycles, _CYCLES_TOGGLES[name]):
        return cycles, _CYCLES_TOGGLES[name]
    return view_layer.raysplats_passes, "use_pass_" + channel["key"]


def enabled(view_layer, channel):
    toggle = _toggle(view_layer, channel)
    return toggle is None or bool(getattr(*toggle, False))


# The denoiser's guides: the core computes them only when asked (RenderSettings.denoising_data).
DENOISING_KEYS = ("denoising_albedo", "denoising_normal")


def denoising_passes_enabled(view_layer):
    """Whether the view layer writes a Denoising Albedo or Normal pass."""
    return any(enabled(view_layer, channel) for channel in channels() if channel["key"] in DENOISING_KEYS)


def shadow_catcher_pass_enabled(view_layer):
    """Whether the view layer writes the Shadow Catcher pass (Combined then leaves shadow catchers transparent)."""
    return any(enabled(view_layer, channel) for channel in channels() if channel["key"] == "shadow_catcher")


def blender_name(channel):
    """The render pass's name in this Blender (5.0 renamed some)."""
    return compat.render_pass_name(channel["pass_name"])


def register_passes(engine, scene, view_layer):
    for channel in channels():
        if enabled(view_layer, channel):
            engine.register_pass(scene, view_layer, blender_name(channel), len(channel["components"]),
                                 channel["components"], channel["kind"])


def written_keys(render_layer):
    """The keys of the film channels the render layer has passes for: what write_passes writes."""
    return [channel["key"] for channel in channels() if render_layer.passes.get(blender_name(channel)) is not None]


def write_passes(render_layer, film, rows, cols):
    """Writes every pass the render layer has from the film (rows top to bottom), one bulk write each."""
    for channel in channels():
        render_pass = render_layer.passes.get(blender_name(channel))
        if render_pass is None:
            continue
        # Film rows run top to bottom; Blender's from the bottom up.
        values = film[channel["key"]][rows, cols][::-1]
        values = np.where(np.isfinite(values), values, _FAR)
        compat.set_render_pass(render_pass, values)


def draw_pass_toggles(layout, view_layer):
    column = layout.column(heading="Include", align=True)
    for channel in channels():
        toggle = _toggle(view_layer, channel)
        if toggle is None:
            row = column.row()
            row.enabled = False
            row.label(text=blender_name(channel), icon="CHECKBOX_HLT")
        else:
            column.prop(*toggle, text=blender_name(channel))


def _pass_properties_class():
    annotations = {}
    for channel in channels():
        if channel["pass_name"] != _ALWAYS and channel["pass_name"] not in _BLENDER_TOGGLES:
            # No update callback (Cycles' calls view_layer.update_render_passes()): with one, the official
            # Blender as a Python module (bpy 4.2) crashes at exit even after unregistering. Renders register
            # their passes when they start, so only the compositor's sockets wait for the next render.
            annotations["use_pass_" + channel["key"]] = bpy.props.BoolProperty(
                name=channel["pass_name"], description=channel["description"], default=False)
    return type("RaySplatsViewLayerPasses", (bpy.types.PropertyGroup,), {"__annotations__": annotations})


_registered = []


def register():
    cls = _pass_properties_class()
    bpy.utils.register_class(cls)
    bpy.types.ViewLayer.raysplats_passes = bpy.props.PointerProperty(type=cls)
    _registered.append(cls)


def unregister():
    del bpy.types.ViewLayer.raysplats_passes
    while _registered:
        bpy.utils.unregister_class(_registered.pop())
