# Memory per Gaussian of a polygon import: the exact layers of the imported mesh (a byte colour attribute,
# 4 bytes a corner; no float colour, no selection layers, no thickness or radius), Polygon Vertices Auto (8 up to 1 M
# Gaussians, 4 above), and the peak resident memory of a real import (showroom_1.5M.ply, the default settings) against
# the core's estimate (memory_budget.h) and TARGET_BYTES_PER_GAUSSIAN. Each test fails when its cut is reverted.
# examples/benchmark_import_memory.py prints the same figures.
import unittest

import bpy
import numpy as np

import splat_testing as st
from raysplats.blender import compat, mesh_memory
from raysplats.io import import_policy, import_splats
from raysplats.objects import creation, polygon_mesh

BIG = "showroom_1.5M.ply"  # 1,495,636 Gaussians, SH degree 0
SMALL = "donut_sh0.ply"    # 45,624 Gaussians, SH degree 0
# Peak resident memory of the default import of BIG above Blender before it, per Gaussian: the target. Measured
# with examples/benchmark_import_memory.py: 3.4 about 615 (the mesh, 276, and the copy the operator's undo step keeps,
# which background mode makes too), 4.5 and 5.0 about 350 (their undo step shares the mesh's arrays).
TARGET_BYTES_PER_GAUSSIAN = 700


def expected_layers(faces, k, sh_degree):
    """{name: (domain, bytes)} of a Gaussian mesh of `faces` K-gons as this Blender stores it."""
    corners = faces * k
    if compat.MESH_TOPOLOGY_IN_INT32_ARRAYS:  # 3.6+: position float3, edge int2, corner vertex and edge int32
        layers = {"vertices": ("POINT", 12 * corners), "edges": ("EDGE", 8 * corners),
                  "corners": ("CORNER", 4 * corners), ".corner_edge": ("CORNER", 4 * corners),
                  "faces": ("FACE", 4 * (faces + 1))}
    else:  # 3.4: MVert 16, MEdge 12, MLoop 8, MPoly 12 bytes
        layers = {"vertices": ("POINT", 16 * corners), "edges": ("EDGE", 12 * corners),
                  "corners": ("CORNER", 8 * corners), "faces": ("FACE", 12 * faces)}
    layers.update({polygon_mesh.ATTR_OPACITY: ("FACE", 4 * faces),
                   polygon_mesh.ATTR_REST_CENTER: ("FACE", 12 * faces),
                   polygon_mesh.ATTR_REST_ROTATION: ("FACE", 16 * faces),
                   polygon_mesh.ATTR_REST_SCALE: ("FACE", 12 * faces),
                   polygon_mesh.ATTR_COLOR: ("CORNER", 4 * corners),
                   # 3.5+ a float2 attribute; 3.4 MLoopUV {float uv[2]; int flag;}
                   polygon_mesh.UV_MAP: ("CORNER", (8 if compat.UV_MAPS_ARE_ATTRIBUTES else 12) * corners)})
    for k_sh in range((sh_degree + 1) ** 2):
        layers[polygon_mesh.sh_attribute_name(k_sh)] = ("FACE", 12 * faces)
    return layers


class ImportMemory(unittest.TestCase):
    def test_a_real_import_peaks_within_the_estimate_and_the_target(self):
        # (First in the file, so that no earlier test's freed memory hides part of the peak.)
        st.reset_scene()
        path = st.data_file(BIG)
        summary = st.native().probe_splat_file(path)
        before = mesh_memory.process_memory_bytes("VmRSS")
        if not mesh_memory.reset_peak_memory():
            self.skipTest("VmHWM cannot be reset here (/proc/self/clear_refs)")
        bpy.ops.import_scene.gaussian_splats(filepath=path)  # the defaults
        peak = mesh_memory.process_memory_bytes("VmHWM") - before
        active = bpy.context.view_layer.objects.active
        pieces = polygon_mesh.scene_pieces(active.parent)  # Auto: 6 M vertices are split into pieces
        self.assertGreater(len(pieces), 10)
        count = sum(len(piece.data.polygons) for piece in pieces)
        self.assertGreater(count, 1_000_000)
        for piece in pieces:
            self.assertEqual(piece.raysplats.vertices_per_polygon, 4)  # Auto above 1 M Gaussians
            self.assertEqual(len(piece.data.loops), 4 * len(piece.data.polygons))
        estimate = st.native().import_memory_bytes(summary["count"], summary["sh_degree"], 4)
        print(f"\n  {BIG}: peak {peak / 1e6:.0f} MB above Blender before the import ({peak / count:.0f} B/Gaussian), "
              f"estimate {estimate / 1e6:.0f} MB ({estimate / count:.0f} B/Gaussian)")
        # The estimate counts an undo copy of the mesh (which Blender 4.x shares with the mesh): the peak is below it,
        # but not far below (a stale estimate refuses imports that fit or lets through ones that do not).
        self.assertLess(peak, estimate)
        self.assertGreater(peak, 0.35 * estimate)
        self.assertLess(peak / count, TARGET_BYTES_PER_GAUSSIAN)
        # The meshes themselves: the layers below, at K = 4.
        for piece in pieces:
            self.assertEqual(mesh_memory.layer_sizes(piece.data),
                             expected_layers(len(piece.data.polygons), 4, summary["sh_degree"]))

    def test_auto_polygon_vertices_are_8_up_to_a_million_gaussians_and_4_above(self):
        core = st.native()
        path = st.data_file(BIG)
        self.assertEqual(creation.auto_vertices_per_polygon(1_000_000), 8)
        self.assertEqual(creation.auto_vertices_per_polygon(1_000_001), 4)
        self.assertEqual(import_policy.resolve_vertices_per_polygon(core, path, 0), 4)
        self.assertEqual(import_policy.resolve_vertices_per_polygon(core, path, 0, max_count=1_000_000), 8)
        self.assertEqual(import_policy.resolve_vertices_per_polygon(core, path, 0, max_count=1_000_001), 4)
        self.assertEqual(import_policy.resolve_vertices_per_polygon(core, path, 8), 8)  # explicit K is kept
        self.assertEqual(import_policy.resolve_vertices_per_polygon(core, path, 6, max_count=10), 6)
        for impossible in (1, 2):  # (the operator's range starts at 0, Auto): a clear error, not the core's
            with self.assertRaisesRegex(ValueError, f"Polygon Vertices {impossible}: a polygon needs at least 3"):
                import_policy.resolve_vertices_per_polygon(core, path, impossible)
        # The operator's default is Auto.
        self.assertEqual(bpy.ops.import_scene.gaussian_splats.get_rna_type().properties["vertices_per_polygon"].default,
                         0)

    def test_a_small_import_has_exactly_the_expected_layers(self):
        for k, expected_k in ((0, 8), (8, 8), (5, 5)):
            with self.subTest(k=k):
                st.reset_scene()
                bpy.ops.import_scene.gaussian_splats(filepath=st.data_file(SMALL), vertices_per_polygon=k)
                obj = bpy.context.view_layer.objects.active
                mesh = obj.data
                self.assertEqual(obj.raysplats.vertices_per_polygon, expected_k)
                faces = len(mesh.polygons)
                self.assertEqual(len(mesh.loops), expected_k * faces)
                self.assertEqual(mesh_memory.layer_sizes(mesh), expected_layers(faces, expected_k, 0))
                color = mesh.color_attributes[polygon_mesh.ATTR_COLOR]
                self.assertEqual((color.data_type, color.domain), ("BYTE_COLOR", "CORNER"))
                self.assertFalse([a.name for a in mesh.attributes if a.data_type == "FLOAT_COLOR"
                                  and a.domain == "CORNER"])
                for name in compat.MESH_SELECTION_ATTRIBUTES + (polygon_mesh.ATTR_THICKNESS,
                                                                         polygon_mesh.ATTR_RADIUS):
                    self.assertNotIn(name, mesh.attributes)

    def test_byte_colours_show_the_float_colours_to_8_bits(self):
        st.reset_scene()
        cloud = st.native().read_splats(st.data_file(SMALL), max_count=2000)
        keep = cloud["opacities"].astype(np.float64) * 255.0 > 1.0
        obj, _, _ = import_splats.import_gaussian_splats(bpy.context, st.data_file(SMALL), max_count=2000, up_axis="-Y")
        mesh = obj.data
        colors = np.empty(len(mesh.loops) * 4, dtype=np.float32)
        mesh.color_attributes[polygon_mesh.ATTR_COLOR].data.foreach_get("color", colors)
        colors = colors.reshape(-1, 8, 4)[:, 0, :]
        display = np.clip(0.5 + st.C0 * cloud["sh"][keep][:, 0, :].astype(np.float64), 0, 1)
        # Blender's .color is linear: the sRGB byte decoded. The byte is the display value rounded, so the decoded
        # value lies within half a byte step of the display value, decoded.
        shown = np.where(colors[:, :3] <= 0.0031308, colors[:, :3] * 12.92,
                         1.055 * np.maximum(colors[:, :3], 0) ** (1 / 2.4) - 0.055)
        np.testing.assert_allclose(shown, display, atol=0.5 / 255 + 1e-4)
        np.testing.assert_allclose(colors[:, 3], cloud["opacities"][keep], atol=0.5 / 255 + 1e-6)

    def test_nothing_is_selected_after_an_import(self):
        st.reset_scene()
        obj, _, _ = import_splats.import_gaussian_splats(bpy.context, st.data_file(SMALL), max_count=500)
        bpy.context.view_layer.objects.active = obj
        bpy.ops.object.mode_set(mode="EDIT")
        bpy.ops.object.mode_set(mode="OBJECT")
        mesh = obj.data
        for elements in (mesh.vertices, mesh.edges, mesh.polygons):
            selected = np.empty(len(elements), dtype=bool)
            elements.foreach_get("select", selected)
            self.assertFalse(selected.any())

    def test_filling_the_mesh_takes_every_array_out_of_the_polygons(self):
        # fill_mesh frees each array as soon as Blender holds it (the caller's dict keeps none of them), so the import's
        # peak is not the polygon arrays and the whole mesh at once.
        core = st.native()
        cloud = core.read_splats(st.data_file(SMALL), max_count=300)
        polygons = core.gaussians_to_polygons(cloud["positions"], cloud["rotations"], cloud["scales"],
                                              cloud["opacities"], cloud["sh"], vertices_per_polygon=4, radius=3.0)
        arrays = {key for key, value in polygons.items() if isinstance(value, np.ndarray)}
        self.assertIn("corner_colors", arrays)
        self.assertEqual(polygons["corner_colors"].dtype, np.uint8)
        mesh = bpy.data.meshes.new("filled")
        polygon_mesh.fill_mesh(mesh, polygons)
        self.assertFalse({key for key, value in polygons.items() if isinstance(value, np.ndarray)})
        self.assertEqual(len(mesh.polygons), len(cloud["opacities"]) - int((cloud["opacities"] * 255.0 <= 1.0).sum()))
        bpy.data.meshes.remove(mesh)

    def test_colours_written_through_foreach_set_and_over_an_older_float_attribute(self):
        # Where the bytes cannot be copied in place, foreach_set writes the same colours; a float colour attribute of
        # that name (files from before byte colours) becomes a byte one.
        from unittest import mock
        st.reset_scene()
        obj, _, _ = import_splats.import_gaussian_splats(bpy.context, st.data_file(SMALL), max_count=500)
        mesh = obj.data
        corners = len(mesh.loops)
        in_place = np.empty(4 * corners, dtype=np.float32)
        mesh.color_attributes[polygon_mesh.ATTR_COLOR].data.foreach_get("color", in_place)
        mesh.color_attributes.remove(mesh.color_attributes[polygon_mesh.ATTR_COLOR])
        mesh.color_attributes.new(polygon_mesh.ATTR_COLOR, "FLOAT_COLOR", "CORNER")
        rgba8 = np.round(in_place.reshape(-1, 4) * 255).astype(np.uint8)  # (any bytes will do)
        with mock.patch.object(polygon_mesh, "write_bytes_in_place", return_value=False):
            polygon_mesh.write_corner_colors(mesh, rgba8)
        color = mesh.color_attributes[polygon_mesh.ATTR_COLOR]
        self.assertEqual((color.data_type, color.domain), ("BYTE_COLOR", "CORNER"))
        self.assertEqual(mesh.color_attributes.active_color.name, polygon_mesh.ATTR_COLOR)
        written = np.empty(4 * corners, dtype=np.float32)
        color.data.foreach_get("color", written)
        np.testing.assert_allclose(written.reshape(-1, 4), st.native().srgb8_to_linear(rgba8), atol=1e-6)

    def test_the_estimate_follows_the_layout(self):
        core = st.native()
        # Quadrilaterals need little more than half of what octagons do, and SH add 12 bytes a coefficient per copy.
        self.assertLess(core.import_memory_bytes(1000, 0, 4), 0.65 * core.import_memory_bytes(1000, 0, 8))
        self.assertGreater(core.import_memory_bytes(1000, 3, 4), core.import_memory_bytes(1000, 0, 4) + 1000 * 15 * 12)


if __name__ == "__main__":
    unittest.main()
