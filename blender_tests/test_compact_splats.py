# Compact splat objects (compact_splats.py, issue 17): one point per Gaussian that keeps the file's values, renders
# like the polygon import of the same file, exports exactly under any object transform (covariances checked here
# with numpy, independently of the core), and hands a selected region to a polygon object and takes it back.
import unittest
from unittest import mock

import bpy
import numpy as np

import splat_testing as st
from raysplats import axes, compact_splats, io_import, native_splats
from raysplats.engine import sync

SCENE = "small_sh3_inria.ply"  # 9,080 Gaussians, SH degree 3
KEYS = ("positions", "rotations", "scales", "opacities", "sh")


def import_points(name=SCENE, **options):
    return st.import_file(name, representation="POINTS", **options)


def covariances(rotations, scales):
    """Σ = R diag(s)² Rᵀ per Gaussian, in float64 (quaternions w x y z, normalised here)."""
    q = rotations.astype(np.float64)
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    w, x, y, z = q.T
    r = np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
                  2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
                  2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=1).reshape(-1, 3, 3)
    m = r * scales.astype(np.float64)[:, None, :]
    return m @ m.transpose(0, 2, 1)


class CompactImport(unittest.TestCase):
    def setUp(self):
        st.reset_scene()

    def test_every_value_of_the_file_is_kept(self):
        obj = import_points()
        self.assertTrue(compact_splats.is_compact_object(obj))
        self.assertEqual(len(bpy.data.meshes[obj.data.name].polygons) if obj.type == "MESH" else 0, 0)
        expected = st.native().read_splats(st.data_file(SCENE))
        got = native_splats.read_native_splats(obj.data)
        self.assertEqual(len(got["opacities"]), len(expected["opacities"]))  # the invisible ones too
        for key in KEYS:
            np.testing.assert_array_equal(got[key], expected[key], err_msg=key)
        self.assertEqual(tuple(obj.rotation_euler), tuple(np.float32(axes.object_rotation_euler("-Y"))))

    def test_untouched_export_is_exact(self):
        import_points()
        written = st.export_file("compact_untouched.ply")
        expected = st.native().read_splats(st.data_file(SCENE))
        for key in KEYS:
            np.testing.assert_array_equal(written[key], expected[key], err_msg=key)

    def test_export_maps_each_gaussian_by_the_object_transform(self):
        obj = import_points()
        obj.location = (1.0, -2.0, 0.5)
        obj.rotation_euler = (0.3, -1.1, 0.7)
        obj.scale = (1.5, 0.5, 2.0)  # non-uniform: the Gaussians shear
        bpy.context.view_layer.update()
        written = st.export_file("compact_moved.ply", up_axis="Z")
        original = st.native().read_splats(st.data_file(SCENE))
        world = np.array(obj.matrix_world, dtype=np.float64)
        expected_positions = original["positions"] @ world[:3, :3].T + world[:3, 3]
        np.testing.assert_allclose(written["positions"], expected_positions, rtol=1e-5, atol=1e-5)
        a = world[:3, :3]
        expected = a @ covariances(original["rotations"], original["scales"]) @ a.T
        actual = covariances(written["rotations"], written["scales"])
        scale = np.abs(expected).max(axis=(1, 2))[:, None, None]
        self.assertLess(float(np.max(np.abs(actual - expected) / scale)), 1e-4)
        np.testing.assert_array_equal(written["opacities"], original["opacities"])

    def test_renders_like_the_polygon_import(self):
        images = {}
        for representation in ("POLYGONS", "POINTS"):
            scene = st.reset_render_scene(96, 72, 8)
            st.import_file(SCENE, representation=representation)
            camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
            scene.collection.objects.link(camera)
            camera.location = (0.0, -6.0, 1.0)
            camera.rotation_euler = (1.45, 0.0, 0.0)
            scene.camera = camera
            images[representation] = st.render_to_array(f"compact_{representation.lower()}")
        polygons, points = images["POLYGONS"], images["POINTS"]
        self.assertGreater(float(np.mean(polygons[..., 3])), 0.05)  # the scene is in view
        mse = float(np.mean((polygons[..., :3] - points[..., :3]) ** 2))
        psnr = 10 * np.log10(max(float(polygons[..., :3].max()), 1e-6) ** 2 / max(mse, 1e-20))
        # The polygon import recovers each Gaussian in float (and leaves out invisible ones): not bit for bit.
        self.assertGreater(psnr, 45.0)

    def test_auto_imports_points_when_polygons_do_not_fit(self):
        real = st.native()
        count = 9080
        polygons = real.import_memory_bytes(count, 3, 8)
        points = real.compact_import_memory_bytes(count, 3)
        self.assertLess(points, polygons)

        class Machine:
            def __getattr__(self, name):
                return getattr(real, name)

            @staticmethod
            def available_memory_bytes():
                return (points + polygons) // 2

        with mock.patch.object(io_import.native, "core", return_value=Machine()):
            representation, needed, note = io_import.check_import_memory(Machine(), st.data_file(SCENE), 8, 0,
                                                                         "AUTO")
            self.assertEqual((representation, needed), ("POINTS", points))
            self.assertIn("imported as compact points", note)
            obj = st.import_file(SCENE)  # the operator's default is AUTO
        self.assertTrue(compact_splats.is_compact_object(obj))
        with self.assertRaisesRegex(io_import.NotEnoughMemory, "import as Compact Points"):
            io_import.check_import_memory(Machine(), st.data_file(SCENE), 8, 0, "POLYGONS")


class RegionEditing(unittest.TestCase):
    def setUp(self):
        st.reset_scene()
        self.obj = import_points()
        self.original = native_splats.read_native_splats(self.obj.data)
        self.mask = self.original["positions"][:, 0] > 0.5

    def test_a_region_becomes_polygons_and_merges_back_unchanged(self):
        region, _ = compact_splats.edit_region_as_polygons(bpy.context, self.obj, self.mask)
        visible = self.mask & (self.original["opacities"] * 255 > 1)  # invisible Gaussians get no polygon
        self.assertEqual(len(region.data.polygons), int(visible.sum()))
        self.assertEqual(compact_splats.point_count(self.obj.data), int((~self.mask).sum()))
        bpy.context.view_layer.update()
        self.assertEqual(region.matrix_world, self.obj.matrix_world)  # the same place, to the last bit
        self.assertIs(compact_splats.region_target(region), self.obj)

        merged = compact_splats.merge_region_back(bpy.context, region)
        self.assertEqual(merged, int(visible.sum()))
        self.assertEqual([obj.name for obj in bpy.data.objects], [self.obj.name])  # the region object is gone
        cloud = native_splats.read_native_splats(self.obj.data)
        rest = int((~self.mask).sum())
        for key in KEYS:  # the points outside the region are untouched, in order
            np.testing.assert_array_equal(cloud[key][:rest], self.original[key][~self.mask], err_msg=key)
        # The region's Gaussians come back as they went (unedited polygons return their stored values).
        np.testing.assert_allclose(cloud["positions"][rest:], self.original["positions"][visible], atol=1e-6)
        np.testing.assert_allclose(cloud["scales"][rest:], self.original["scales"][visible], rtol=1e-5, atol=1e-7)
        np.testing.assert_allclose(cloud["opacities"][rest:], self.original["opacities"][visible], atol=1e-6)

    def test_a_moved_region_merges_back_where_it_is_seen(self):
        region, _ = compact_splats.edit_region_as_polygons(bpy.context, self.obj, self.mask)
        region.location.x += 2.0  # world +X; the compact object's frame is rotated about X only, so its +X too
        bpy.context.view_layer.update()
        compact_splats.merge_region_back(bpy.context, region)
        cloud = native_splats.read_native_splats(self.obj.data)
        visible = self.mask & (self.original["opacities"] * 255 > 1)
        rest = int((~self.mask).sum())
        expected = self.original["positions"][visible] + np.array([2.0, 0.0, 0.0], dtype=np.float32)
        np.testing.assert_allclose(cloud["positions"][rest:], expected, atol=1e-5)

    def test_nothing_selected_is_a_clear_error_and_changes_nothing(self):
        with self.assertRaisesRegex(ValueError, "no splats selected"):
            compact_splats.edit_region_as_polygons(bpy.context, self.obj, np.zeros_like(self.mask))
        self.assertEqual(compact_splats.point_count(self.obj.data), len(self.original["opacities"]))

    def test_the_operators_use_the_edit_mode_selection(self):
        bpy.context.view_layer.objects.active = self.obj
        selection = np.zeros(len(self.mask), dtype=bool)
        selection[:100] = True
        self.obj.data.vertices.foreach_set("select", selection)  # (a mesh below Blender 5.3)
        self.assertEqual(bpy.ops.object.raysplats_edit_region(), {"FINISHED"})
        region = bpy.context.view_layer.objects.active
        self.assertEqual(region.get(compact_splats.REGION_OF_PROPERTY), self.obj.name)
        self.assertEqual(compact_splats.point_count(self.obj.data), len(self.mask) - 100)
        self.assertEqual(bpy.ops.object.raysplats_merge_region(), {"FINISHED"})
        self.assertIs(bpy.context.view_layer.objects.active, self.obj)
        invisible = int(np.sum(self.original["opacities"][:100] * 255 <= 1))
        self.assertEqual(compact_splats.point_count(self.obj.data), len(self.mask) - invisible)


class Rendering(unittest.TestCase):
    def test_the_render_scene_holds_every_point(self):
        st.reset_scene()
        obj = import_points()
        scene_sync = sync.SceneSync(bpy.context.evaluated_depsgraph_get())
        self.assertEqual(scene_sync.stats.splats, compact_splats.point_count(obj.data))


if __name__ == "__main__":
    unittest.main()
