# Cryptomatte Object, Material and Asset, switched on with Blender's own View Layer settings, as a user finishes them:
# a compositor tree Render Layers -> Cryptomatte node (source Render) picking an object by its name, whose matte must
# cover what the Object Index pass says the object covers (IoU), for meshes, a polygon splat object and compact points
# in one scene; the passes' layout (Cycles' names and RGBA layers); the manifest in the saved EXR's metadata names
# every object; and with Cryptomatte off the core computes nothing and the image is the same.
import json
import struct
import unittest
from types import SimpleNamespace

import bpy
import numpy as np

import splat_testing as st
from raysplats.blender import compat
from raysplats.engine import final
from raysplats.objects import creation

WIDTH, HEIGHT = 96, 72
# The matte thresholded at 0.5 against the Object Index pass's pixels of the object. Samples are spread over 1 % of
# a pixel (a Gaussian pixel filter of width 0.01), so that the index's first sample and the matte's mean of 16 see the
# same point: they differ only where an edge or a Gaussian's 0.5 contour passes within that spread of a pixel centre.
MIN_IOU = 0.97
# Object name -> pass index for the Object Index reference.
OBJECTS = {"Floor": 1, "Box": 2, "Splats": 3, "Points": 4}


def new_scene(samples=16):
    """A camera 10 units above z = 0 looking down at a floor, a box on it, a polygon splat object over the floor
    and compact points over the world (the floor covers the left half); materials "Ground" and "Paint"."""
    scene = st.reset_render_scene(WIDTH, HEIGHT, samples=samples)
    scene.raysplats.use_adaptive_sampling = False
    scene.raysplats.pixel_filter, scene.raysplats.filter_width = "GAUSSIAN", 0.01
    world = bpy.data.worlds.new("World")
    world.use_nodes = False
    st.set_world_color(world, (0.1, 0.1, 0.1))
    scene.world = world
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    scene.collection.objects.link(camera)
    camera.location = (0.0, 0.0, 10.0)
    scene.camera = camera
    bpy.ops.mesh.primitive_plane_add(size=1.0, location=(-2.0, 0.0, 0.0))
    floor = bpy.context.active_object
    floor.name, floor.scale = "Floor", (4.0, 8.0, 1.0)
    floor.data.materials.append(bpy.data.materials.new("Ground"))
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(-1.5, -1.2, 0.5))
    box = bpy.context.active_object
    box.name = "Box"
    box.data.materials.append(bpy.data.materials.new("Paint"))
    # The box hangs from an empty: its asset is the empty's name.
    rig = bpy.data.objects.new("Rig", None)
    scene.collection.objects.link(rig)
    box.parent = rig
    splats, _ = creation.add_gaussian_object(
        bpy.context, "Splats", st.flat_gaussian_cloud([(-1.0, 1.2, 2.0), (-0.4, 1.0, 2.0)], 0.5, 0.9), 8, 3.0, "Z")
    points = creation.add_compact_object(
        bpy.context, "Points", st.flat_gaussian_cloud([(1.6, 0.2, 2.0), (2.1, -0.6, 2.0)], 0.45, 0.95), "Z")
    for name, index in OBJECTS.items():
        bpy.data.objects[name].pass_index = index
    return scene


def cryptomatte_matte(scene, layer, names, name):
    """F12 through a compositor tree as a user builds it: Render Layers -> Cryptomatte (source Render, `layer`, the
    matte of `names`) -> the composited image, saved as a 32-bit EXR: its first channel (rows top to bottom)."""
    tree, output = compat.new_compositor(scene)
    render_layers = tree.nodes.new("CompositorNodeRLayers")
    render_layers.scene = scene
    cryptomatte = tree.nodes.new("CompositorNodeCryptomatteV2")
    cryptomatte.source = "RENDER"
    cryptomatte.scene = scene
    cryptomatte.layer_name = f"{bpy.context.view_layer.name}.{layer}"
    cryptomatte.matte_id = names
    tree.links.new(render_layers.outputs["Image"], cryptomatte.inputs["Image"])
    tree.links.new(cryptomatte.outputs["Matte"], output)
    return st.render_to_array(name)[::-1, :, 0]


def object_index_render(name):
    """The Object Index pass of an F12 (rows top to bottom)."""
    view_layer = bpy.context.view_layer
    view_layer.use_pass_object_index = True
    out = st.render_multilayer_exr(name)
    view_layer.use_pass_object_index = False
    return out[f"{view_layer.name}.{compat.render_pass_name('IndexOB')}.X"]


def iou(a, b):
    return np.sum(a & b) / max(1, np.sum(a | b))


def exr_string_attributes(path):
    """The string attributes of an OpenEXR file's first header (its metadata), read from the file layout."""
    data = open(path, "rb").read()
    pos, strings = 8, {}
    while data[pos] != 0:
        end = data.index(b"\0", pos)
        type_end = data.index(b"\0", end + 1)
        (size,) = struct.unpack_from("<i", data, type_end + 1)
        if data[end + 1:type_end] == b"string":
            strings[data[pos:end].decode()] = data[type_end + 5:type_end + 5 + size].decode()
        pos = type_end + 5 + size
    return strings


class Cryptomatte(unittest.TestCase):
    def test_the_panel_is_blenders_own(self):
        # View Layer > Passes > Cryptomatte is Blender's panel, shown for this engine, drawing every setting it reads.
        panel = bpy.types.VIEWLAYER_PT_layer_passes_cryptomatte
        self.assertIn("RAYSPLATS", panel.COMPAT_ENGINES)
        scene = st.reset_render_scene(8, 8, 1)
        layout = st.RecordingLayout()
        panel.draw(SimpleNamespace(layout=layout),
                   SimpleNamespace(engine=scene.render.engine, view_layer=bpy.context.view_layer, scene=scene))
        self.assertLessEqual({"use_pass_cryptomatte_object", "use_pass_cryptomatte_material",
                              "use_pass_cryptomatte_asset", "pass_cryptomatte_depth"},
                             {name for owner, name, _ in layout.log if owner == "ViewLayer"})

    def test_passes_are_cycles_layout(self):
        scene = new_scene(samples=4)
        view_layer = bpy.context.view_layer
        view_layer.use_pass_cryptomatte_object = True
        view_layer.use_pass_cryptomatte_asset = True
        view_layer.pass_cryptomatte_depth = 4
        out = st.render_multilayer_exr("cryptomatte_layout")
        layer = view_layer.name
        passes = {name.split(".")[1] for name in out}
        self.assertEqual(passes, {"Combined", "CryptoObject00", "CryptoObject01", "CryptoAsset00", "CryptoAsset01"})
        self.assertFalse(final.last_render["cancelled"])
        core = st.native()

        def ranks(prefix):
            """(h, w, 4 ranks, (id, coverage)) from the passes' r, g, b, a."""
            layers = [np.stack([out[f"{layer}.{prefix}{k:02d}.{c}"] for c in "rgba"], axis=-1) for k in (0, 1)]
            return np.concatenate(layers, axis=-1).reshape(HEIGHT, WIDTH, 4, 2)

        def float_id(name):
            """The Cryptomatte specification's uint32_to_float32: the exponent clamped to [1, 254]."""
            bits = core.cryptomatte_hash(name)
            exponent = min(max((bits >> 23) & 0xFF, 1), 254)
            bits = (bits & 0x807FFFFF) | exponent << 23
            return np.frombuffer(struct.pack("<I", bits), dtype="<f4")[0]

        objects, assets = ranks("CryptoObject"), ranks("CryptoAsset")
        # Coverage sorted, largest first; every pixel's ranks sum to at most 1 (the world has no id).
        self.assertTrue(np.all(np.diff(objects[..., 1], axis=-1) <= 0.0))
        self.assertTrue(np.all(objects[..., 1].sum(-1) <= 1.0 + 1e-5))
        # The floor's left half is covered by the floor (and what stands on it); the right half's world has no id.
        ids = set(np.unique(objects[..., 0]).tolist())
        for name in OBJECTS:
            self.assertIn(float(float_id(name)), ids, name)
        self.assertEqual(float(objects[0, WIDTH - 1, 0, 1]), 0.0)  # the top right corner: only the world
        # The box's asset is its top-level parent, the others' themselves.
        asset_ids = set(np.unique(assets[..., 0]).tolist())
        self.assertIn(float(float_id("Rig")), asset_ids)
        self.assertNotIn(float(float_id("Box")), asset_ids)

    def test_the_cryptomatte_node_picks_each_object_by_name(self):
        scene = new_scene()
        view_layer = bpy.context.view_layer
        index = object_index_render("cryptomatte_index")
        view_layer.use_pass_cryptomatte_object = True
        view_layer.use_pass_cryptomatte_material = True
        for name, pass_index in OBJECTS.items():
            with self.subTest(name):
                matte = cryptomatte_matte(scene, "CryptoObject", name, f"cryptomatte_matte_{name}")
                reference = index == pass_index
                self.assertGreater(np.sum(reference), 40, name)
                value = iou(matte > 0.5, reference)
                print(f"Cryptomatte {name}: IoU {value:.4f} over {np.sum(reference)} pixels")
                self.assertGreater(value, MIN_IOU, name)
        # Two names at once, and a material: the box's "Paint" is the box's pixels.
        matte = cryptomatte_matte(scene, "CryptoObject", "Splats,Points", "cryptomatte_matte_two")
        self.assertGreater(iou(matte > 0.5, (index == 3) | (index == 4)), MIN_IOU)
        matte = cryptomatte_matte(scene, "CryptoMaterial", "Paint", "cryptomatte_matte_paint")
        self.assertGreater(iou(matte > 0.5, index == 2), MIN_IOU)

    def test_the_manifest_names_every_object(self):
        scene = new_scene(samples=2)
        view_layer = bpy.context.view_layer
        view_layer.use_pass_cryptomatte_object = True
        view_layer.use_pass_cryptomatte_asset = True
        st.render_multilayer_exr("cryptomatte_manifest")
        attributes = exr_string_attributes(scene.render.filepath)
        core = st.native()
        for layer, names in (("CryptoObject", set(OBJECTS)), ("CryptoAsset", {"Floor", "Rig", "Splats", "Points"})):
            with self.subTest(layer):
                full = f"{view_layer.name}.{layer}"
                prefix = f"cryptomatte/{core.cryptomatte_hash(full):08x}"[:-1] + "/"
                found = {k[len(prefix):]: v for k, v in attributes.items() if k.startswith(prefix)}
                self.assertEqual(found.get("name"), full, sorted(attributes))
                self.assertEqual(found.get("hash"), "MurmurHash3_32")
                self.assertEqual(found.get("conversion"), "uint32_to_float32")
                manifest = json.loads(found["manifest"])
                self.assertEqual(set(manifest), names)
                for name, digits in manifest.items():
                    self.assertEqual(digits, f"{core.cryptomatte_hash(name):08x}")

    def test_off_computes_nothing_and_changes_nothing(self):
        new_scene(samples=4)
        view_layer = bpy.context.view_layer
        off = st.render_multilayer_exr("cryptomatte_off")
        from raysplats.engine import passes
        self.assertEqual({k: v for k, v in passes.core_settings(view_layer).items() if k.startswith("crypto")},
                         {"cryptomatte_object": False, "cryptomatte_material": False, "cryptomatte_asset": False,
                          "cryptomatte_levels": 6})
        view_layer.use_pass_cryptomatte_object = True
        on = st.render_multilayer_exr("cryptomatte_on")
        layer = view_layer.name
        for channel in "RGBA":
            key = f"{layer}.Combined.{channel}"
            np.testing.assert_array_equal(on[key], off[key])
        self.assertFalse(any("Crypto" in name for name in off))


if __name__ == "__main__":
    unittest.main()
