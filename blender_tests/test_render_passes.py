# Render passes come from the core's film channel table: each channel can be switched on in View Layer > Passes,
# F12 fills it, and Blender writes it to a multilayer EXR with the values the geometry predicts (depth of a plane
# at a known distance, its normal, its coverage).
import struct
import unittest

import bpy
import numpy as np

import splat_testing as st
from raysplats.blender.compat import use_multilayer_exr


def _read_exr_header(data, pos):
    """One OpenEXR header from byte `pos`: (channels [(name, pixel type)], data window, compression, chunk count,
    the position after its terminating null byte)."""
    channels, window, compression, chunks = [], None, None, None
    while data[pos] != 0:
        end = data.index(b"\0", pos)
        name = data[pos:end].decode()
        type_end = data.index(b"\0", end + 1)
        (size,) = struct.unpack_from("<i", data, type_end + 1)
        value = data[type_end + 5:type_end + 5 + size]
        if name == "channels":
            at = 0
            while value[at] != 0:
                name_end = value.index(b"\0", at)
                pixel_type = struct.unpack_from("<i", value, name_end + 1)[0]
                channels.append((value[at:name_end].decode(), pixel_type))
                at = name_end + 1 + 16
        elif name == "dataWindow":
            window = struct.unpack("<4i", value)
        elif name == "compression":
            compression = value[0]
        elif name == "chunkCount":
            (chunks,) = struct.unpack("<i", value)
        pos = type_end + 5 + size
    return channels, window, compression, chunks, pos + 1


def read_uncompressed_exr(path):
    """{channel name: float32 array (rows top to bottom)} of an uncompressed, 32-bit float scanline OpenEXR file,
    single-part (Blender 3.4-4.x's multilayer files) or multi-part (Blender 5.0's: one part per pass). Written from
    the OpenEXR file layout (headers, chlist, offset tables, scanline chunks; a multi-part file ends its header list
    with an empty header and starts each chunk with its part number), not with Blender, so that it checks what
    Blender wrote."""
    data = open(path, "rb").read()
    assert data[:4] == b"\x76\x2f\x31\x01", "not an OpenEXR file"
    multipart = bool(struct.unpack_from("<I", data, 4)[0] & 0x1000)
    pos, parts = 8, []
    while True:
        channels, window, compression, chunks, pos = _read_exr_header(data, pos)
        assert compression == 0, "compressed EXR"
        assert all(t == 2 for _, t in channels), "not 32-bit float"
        parts.append((channels, window, chunks if multipart else window[3] - window[1] + 1))
        if not multipart or data[pos] == 0:
            break
    pos += 1 if multipart else 0
    result = {}
    for part, (channels, window, chunks) in enumerate(parts):
        width, height = window[2] - window[0] + 1, window[3] - window[1] + 1
        offsets = struct.unpack_from(f"<{chunks}Q", data, pos)
        pos += 8 * chunks
        for name, _ in channels:
            result[name] = np.empty((height, width), dtype=np.float32)
        for offset in offsets:
            if multipart:
                assert struct.unpack_from("<i", data, offset)[0] == part
                offset += 4
            y, _size = struct.unpack_from("<2i", data, offset)
            at = offset + 8
            for name, _ in channels:
                result[name][y - window[1]] = np.frombuffer(data, dtype="<f4", count=width, offset=at)
                at += 4 * width
    return result


class RenderPasses(unittest.TestCase):
    def setUp(self):
        scene = st.reset_render_scene(40, 30, samples=2)
        world = bpy.data.worlds.new("World")
        world.use_nodes = False
        st.set_world_color(world, (0.1, 0.1, 0.1))
        scene.world = world
        # An orthographic camera 3 units above a plane z = 0 that covers the left half of the view.
        bpy.ops.mesh.primitive_plane_add(size=1.0)
        plane = bpy.context.active_object
        plane.scale = (2.0, 4.0, 1.0)
        plane.location = (-1.0, 0.0, 0.0)
        data = bpy.data.cameras.new("Camera")
        data.type, data.ortho_scale = "ORTHO", 4.0
        camera = bpy.data.objects.new("Camera", data)
        scene.collection.objects.link(camera)
        camera.location = (0.0, 0.0, 3.0)
        scene.camera = camera

    def render_exr(self, name):
        scene = bpy.context.scene
        settings = scene.render.image_settings
        use_multilayer_exr(settings)
        settings.color_depth = "32"
        settings.exr_codec = "NONE"
        scene.render.filepath = st.tmp_file(name + ".exr")
        bpy.ops.render.render(write_still=True)
        return read_uncompressed_exr(scene.render.filepath)

    def test_every_film_channel_has_a_pass_check_box(self):
        view_layer = bpy.context.view_layer
        keys = [channel["key"] for channel in st.native().film_channels()]
        self.assertEqual(keys[:4], ["rgba", "depth", "normal", "alpha"])
        # Alpha has no Blender check box: the add-on made one from the table.
        self.assertFalse(view_layer.raysplats_passes.use_pass_alpha)
        self.assertIn("use_pass_alpha", view_layer.raysplats_passes.bl_rna.properties.keys())

    def test_only_enabled_passes_are_written(self):
        exr = self.render_exr("passes_default")
        layers = {name.split(".")[1] for name in exr}
        self.assertEqual(layers, {"Combined"})

    def test_depth_normal_and_alpha_passes_hold_the_plane(self):
        view_layer = bpy.context.view_layer
        view_layer.use_pass_z = True
        view_layer.use_pass_normal = True
        view_layer.raysplats_passes.use_pass_alpha = True
        exr = self.render_exr("passes_all")
        layer = next(name.split(".")[0] for name in exr)
        depth = exr[f"{layer}.Depth.Z"]
        alpha = exr[f"{layer}.Alpha.A"]
        normal = np.stack([exr[f"{layer}.Normal.{c}"] for c in "XYZ"], axis=-1)
        left, right = np.s_[:, 2:18], np.s_[:, 22:]  # the plane's half and the background's (away from the edge)
        np.testing.assert_allclose(depth[left], 3.0, rtol=1e-5)
        self.assertTrue(np.all(depth[right] == 1e10))  # nothing there: Blender's far value
        np.testing.assert_allclose(normal[left], np.broadcast_to((0.0, 0.0, 1.0), normal[left].shape), atol=1e-6)
        self.assertTrue(np.all(normal[right] == 0.0))
        self.assertTrue(np.all(alpha[left] == 1.0))
        self.assertTrue(np.all(alpha[right] == 0.0))
        combined_alpha = exr[f"{layer}.Combined.A"]
        self.assertTrue(np.all(combined_alpha == 1.0))  # no Film > Transparent: opaque

    def test_film_transparent_makes_the_background_transparent(self):
        bpy.context.scene.render.film_transparent = True  # RaySplats' Film panel draws this check box
        exr = self.render_exr("passes_transparent")
        layer = next(name.split(".")[0] for name in exr)
        combined_alpha = exr[f"{layer}.Combined.A"]
        self.assertTrue(np.all(combined_alpha[:, 2:18] == 1.0))
        self.assertTrue(np.all(combined_alpha[:, 22:] == 0.0))

    def test_gaussian_count_pass_counts_the_splats_each_pixel_composites(self):
        scene = bpy.context.scene
        donut = st.import_file("donut_sh0.ply")
        # The camera 1 unit above the donut's origin (its splats' centroid), seeing it whole.
        scene.camera.location = (donut.location.x, donut.location.y, donut.location.z + 1.0)
        scene.camera.data.ortho_scale = 0.5
        bpy.data.objects.remove(bpy.data.objects["Plane"])
        view_layer = bpy.context.view_layer
        view_layer.raysplats_passes.use_pass_gaussian_count = True
        view_layer.raysplats_passes.use_pass_alpha = True
        exr = self.render_exr("passes_gaussian_count")
        layer = next(name.split(".")[0] for name in exr)
        count = exr[f"{layer}.Gaussian Count.X"]
        alpha = exr[f"{layer}.Alpha.A"]
        self.assertGreater(np.sum(alpha > 0.5), 20)
        # Opaque pixels took several splats (sorted compositing composites every one before the cut-off); where
        # nothing is there, none.
        self.assertGreater(np.mean(count[alpha > 0.5]), 2.0)
        self.assertTrue(np.all(count[alpha == 0.0] == 0.0))
        self.assertTrue(np.all(count == np.round(count * 2) / 2))  # a mean of 2 samples' whole counts


if __name__ == "__main__":
    unittest.main()
