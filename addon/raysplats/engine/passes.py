# Render passes of the RaySplats engine, all from the core's film channel table (_native.film_channels(),
# native/include/raysplats/render/film.h): registration (update_render_passes), the check boxes in View Layer >
# Passes, and the final render's writes. A channel the core adds appears here with no change to this module.
# The Cryptomatte passes (_native.cryptomatte_passes(), native/include/raysplats/render/cryptomatte.h) are Blender's
# own settings (View Layer > Passes > Cryptomatte), registered, written and described by their metadata here too.
import json

import bpy
import numpy as np

from .. import native
from ..blender import compat

# Passes Blender already has a view-layer check box for; the others get one in RaySplatsViewLayerPasses.
_BLENDER_TOGGLES = {"Depth": "use_pass_z", "Normal": "use_pass_normal", "Mist": "use_pass_mist",
                    "Position": "use_pass_position", "IndexOB": "use_pass_object_index",
                    "IndexMA": "use_pass_material_index", "Env": "use_pass_environment", "Vector": "use_pass_vector", "Emit": "use_pass_emit",
                    "DiffDir": "use_pass_diffuse_direct", "DiffInd": "use_pass_diffuse_indirect",
                    "DiffCol": "use_pass_diffuse_color", "GlossDir": "use_pass_glossy_direct",
                    "GlossInd": "use_pass_glossy_indirect", "GlossCol": "use_pass_glossy_color",
                    "TransDir": "use_pass_transmission_direct", "TransInd": "use_pass_transmission_indirect",
                    "TransCol": "use_pass_transmission_color"}
# The check boxes' labels where the pass's name is not one: Blender's own labels of use_pass_object_index,
# use_pass_material_index, use_pass_environment (the passes were named "IndexOB", "IndexMA" and "Env" before 5.0).
_LABELS = {"IndexOB": "Object Index", "IndexMA": "Material Index", "Env": "Environment"}
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


# The light passes, laid out as Cycles' View Layer > Passes > Light panel lays them out: (heading, [(key, label)]).
# The core splits the light only when one of them is written (RenderSettings.light_passes).
LIGHT_PASS_LAYOUT = (
    ("Diffuse", (("diffuse_direct", "Direct"), ("diffuse_indirect", "Indirect"), ("diffuse_color", "Color"))),
    ("Glossy", (("glossy_direct", "Direct"), ("glossy_indirect", "Indirect"), ("glossy_color", "Color"))),
    ("Transmission", (("transmission_direct", "Direct"), ("transmission_indirect", "Indirect"),
                      ("transmission_color", "Color"))),
    ("Other", (("emission", "Emission"),)),
)
LIGHT_KEYS = frozenset(key for _, rows in LIGHT_PASS_LAYOUT for key, _ in rows)


def light_passes_enabled(view_layer):
    """Whether the view layer writes a light pass (Emission, or a Diffuse, Glossy or Transmission one)."""
    return any(enabled(view_layer, channel) for channel in channels() if channel["key"] in LIGHT_KEYS)


def vector_pass_enabled(view_layer):
    """Whether the view layer writes the Vector pass (whose motion the render then reads: final.py)."""
    return any(enabled(view_layer, channel) for channel in channels() if channel["key"] == "vector")


def core_settings(view_layer):
    """The core's render settings that follow the view layer's passes: the Mist pass's sums, the split of the light
    and the Cryptomatte passes are computed only when the layer has them, and Combined leaves shadow catchers
    transparent when it has the Shadow Catcher pass."""
    settings = {"mist_pass": bool(view_layer.use_pass_mist), "light_passes": light_passes_enabled(view_layer),
                "shadow_catcher_pass": shadow_catcher_pass_enabled(view_layer),
                "cryptomatte_levels": int(view_layer.pass_cryptomatte_depth)}
    for crypto in cryptomatte_types():
        settings[crypto["key"]] = bool(getattr(view_layer, crypto["toggle"]))
    return settings


def cryptomatte_types():
    """The Cryptomatte pass types (Object, Material, Asset) with the core's key, the passes' name prefix, Blender's
    check box (ViewLayer.use_pass_cryptomatte_*) and the kind of name their ids hash (the manifest's)."""
    try:
        types = native.core().cryptomatte_passes()
    except native.NativeModuleMissing:
        return []
    return [dict(t, toggle="use_pass_" + t["key"], names=t["key"].split("_", 1)[1]) for t in types]


def cryptomatte_pass_names(view_layer, crypto):
    """The passes of one Cryptomatte type the view layer has: "CryptoObject00", ... (Cycles: blender/addon/engine.py,
    list_render_passes: ceil(min(16, Levels) / 2) RGBA layers of two ranks), none when its check box is off."""
    if not getattr(view_layer, crypto["toggle"]):
        return []
    layers = (min(16, view_layer.pass_cryptomatte_depth) + 1) // 2
    return [f"{crypto['prefix']}{layer:02d}" for layer in range(layers)]


def cryptomatte_metadata(view_layer, names):
    """The render result's metadata of the view layer's Cryptomatte passes, as Cycles writes it
    (blender/session.cpp, add_cryptomatte_layer): for the layer "<view layer>.CryptoObject" (...Material, ...Asset),
    with h the 8 hex digits of its name's hash, "cryptomatte/<h[:7]>/name", "hash", "conversion" and "manifest" (a JSON
    object of every name of that kind in the scene and its hash's 8 hex digits). `names`: kind ("object", "material",
    "asset") -> the names the scene gave the core."""
    core = native.core()
    fields = {}
    for crypto in cryptomatte_types():
        if not getattr(view_layer, crypto["toggle"]):
            continue
        layer = f"{view_layer.name}.{crypto['prefix']}"
        prefix = f"cryptomatte/{core.cryptomatte_hash(layer):08x}"[:-1] + "/"  # the first 7 hex digits
        manifest = {name: f"{core.cryptomatte_hash(name):08x}" for name in sorted(names.get(crypto["names"], ()))}
        fields.update({prefix + "name": layer, prefix + "hash": "MurmurHash3_32",
                       prefix + "conversion": "uint32_to_float32",
                       prefix + "manifest": json.dumps(manifest, separators=(",", ":"), ensure_ascii=False)})
    return fields


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
    for crypto in cryptomatte_types():
        for name in cryptomatte_pass_names(view_layer, crypto):
            # Cycles' channel ids and kind for them.
            engine.register_pass(scene, view_layer, name, 4, "rgba", "COLOR")


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
    for crypto in cryptomatte_types():
        if crypto["key"] not in film:
            continue
        layers = film[crypto["key"]]  # (h, w, layers, 4): layer k is pass <prefix>k
        for layer in range(layers.shape[2]):
            render_pass = render_layer.passes.get(f"{crypto['prefix']}{layer:02d}")
            if render_pass is not None:
                compat.set_render_pass(render_pass, layers[rows, cols, layer][::-1])


def draw_pass_toggles(layout, view_layer):
    """The check boxes of every pass but the light passes (draw_light_pass_toggles)."""
    column = layout.column(heading="Include", align=True)
    for channel in channels():
        if channel["key"] in LIGHT_KEYS:
            continue
        toggle = _toggle(view_layer, channel)
        if toggle is None:
            row = column.row()
            row.enabled = False
            row.label(text=blender_name(channel), icon="CHECKBOX_HLT")
        else:
            column.prop(*toggle, text=_LABELS.get(channel["pass_name"], blender_name(channel)))


def draw_light_pass_toggles(layout, view_layer):
    """Blender's own check boxes of the light passes, in LIGHT_PASS_LAYOUT (none without the native module)."""
    by_key = {channel["key"]: channel for channel in channels()}
    for heading, rows in LIGHT_PASS_LAYOUT:
        column = layout.column(heading=heading, align=True)
        for key, label in rows:
            if key in by_key:
                column.prop(*_toggle(view_layer, by_key[key]), text=label)


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
