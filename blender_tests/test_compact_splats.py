# Compact splat objects (objects/compact_points.py): one point per Gaussian that keeps the file's values, renders
# like the polygon import of the same file, exports exactly under any object transform (covariances checked here
# with numpy, independently of the core), and hands a selected region to a polygon object and takes it back.
import unittest
from unittest import mock

import bpy
import numpy as np

import splat_testing as st
from raysplats import native
from raysplats.blender import compat
from raysplats.io import import_policy
from raysplats.objects import axes, blender_splats, compact_points, splat_object
from raysplats.tools import region_editing
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
        self.assertEqual(splat_object.kind_of(obj), splat_object.POINTS)
        self.assertEqual(len(bpy.data.meshes[obj.data.name].polygons) if obj.type == "MESH" else 0, 0)
        expected = st.native().read_splats(st.data_file(SCENE))
        got = blender_splats.read_blender_splats(obj.data)
        self.assertEqual(len(got["opacities"]), len(expected["opacities"]))  # the invisible ones too
        for key in KEYS:
            np.testing.assert_array_equal(got[key], expected[key], err_msg=key)
        self.assertEqual(tuple(obj.rotation_euler), tuple(np.float32(axes.object_rotation_euler("-Y"))))

    def test_the_up_axis_is_stored_once_for_every_kind(self):
        obj = import_points()
        self.assertEqual(splat_object.kind_of(obj), splat_object.POINTS)
        self.assertEqual(splat_object.up_axis_of(obj), "-Y")  # the file's, as recorded by the import
        self.assertEqual(obj.raysplats.up_axis, "-Y")
        self.assertNotIn("raysplats_up_axis", obj.keys())
        # A point object whose up axis was never recorded has its importer's axes (Blender's own: Z)...
        obj.raysplats.property_unset("up_axis")
        self.assertEqual(splat_object.up_axis_of(obj), blender_splats.BLENDER_MADE_UP_AXIS)
        # ...unless a file saved by an earlier version kept it in a custom property.
        obj["raysplats_up_axis"] = "X"
        self.assertEqual(splat_object.up_axis_of(obj), "X")
        splat_object.set_up_axis(obj, "Y")
        self.assertEqual(splat_object.up_axis_of(obj), "Y")

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

        with mock.patch.object(native, "core", return_value=Machine()):
            representation, needed, note = import_policy.check_import_memory(Machine(), st.data_file(SCENE), 8, 0,
                                                                         "AUTO")
            self.assertEqual((representation, needed), ("POINTS", points))
            self.assertIn(f"imported as {import_policy.POINTS_NAME.lower()}", note)
            obj = st.import_file(SCENE)  # the operator's default is AUTO
        self.assertEqual(splat_object.kind_of(obj), splat_object.POINTS)
        with self.assertRaisesRegex(import_policy.NotEnoughMemory, f"import as {import_policy.POINTS_NAME}"):
            import_policy.check_import_memory(Machine(), st.data_file(SCENE), 8, 0, "POLYGONS")


def shown(obj):
    """The Gaussians compact object `obj` shows (renders, exports), in object space."""
    return compact_points.object_cloud(obj)


class RegionEditing(unittest.TestCase):
    def setUp(self):
        st.reset_scene()
        self.obj = import_points()
        self.original = blender_splats.read_blender_splats(self.obj.data)
        self.mask = self.original["positions"][:, 0] > 0.5
        self.visible = self.mask & region_editing.visible_gaussians(self.original["opacities"])

    def assert_cloud_equal(self, got, expected):
        for key in KEYS:
            np.testing.assert_array_equal(got[key], expected[key], err_msg=key)

    def test_a_region_becomes_polygons_and_merges_back_unchanged(self):
        data = self.obj.data
        region, _ = region_editing.edit_region_as_polygons(bpy.context, self.obj, self.mask)
        self.assertEqual(len(region.data.polygons), int(self.visible.sum()))
        # The points stay where they are, marked as the region's: the compact data is not rebuilt.
        self.assertIs(self.obj.data, data)
        self.assertEqual(compat.point_count(self.obj.data), len(self.mask))
        self.assertEqual(compact_points.gaussian_count(self.obj.data), int((~self.visible).sum()))
        if hasattr(self.obj.data, "vertices"):  # (a point cloud, 5.3 on, has no hiding)
            hidden = np.zeros(len(self.mask), dtype=bool)
            self.obj.data.vertices.foreach_get("hide", hidden)
            np.testing.assert_array_equal(hidden, self.visible)  # Edit Mode does not show the points out in the region
        bpy.context.view_layer.update()
        self.assertEqual(region.matrix_world, self.obj.matrix_world)  # the same place, to the last bit
        self.assertIs(region_editing.region_target(region), self.obj)

        merged = region_editing.merge_region_back(bpy.context, region)
        self.assertEqual(merged, int(self.visible.sum()))
        self.assertEqual([obj.name for obj in bpy.data.objects], [self.obj.name])  # the region object is gone
        self.assertIs(self.obj.data, data)
        self.assertEqual(region_editing.open_regions(self.obj), {})
        # Every point back where it was, bit for bit (unedited polygons return their stored values).
        self.assert_cloud_equal(blender_splats.read_blender_splats(self.obj.data), self.original)
        self.assertFalse(compact_points.region_marks(self.obj.data).any())
        if hasattr(self.obj.data, "vertices"):
            self.obj.data.vertices.foreach_get("hide", hidden)
            self.assertFalse(hidden.any())

    def test_taken_points_are_skipped_by_render_and_export(self):
        region, _ = region_editing.edit_region_as_polygons(bpy.context, self.obj, self.mask)
        rest = {key: self.original[key][~self.visible] for key in KEYS}
        self.assert_cloud_equal(shown(self.obj), rest)
        scene_sync = sync.SceneSync(bpy.context.evaluated_depsgraph_get())
        self.assertEqual(scene_sync.stats.splats, len(self.mask))  # the rest, and the region as polygons
        self.assertEqual([count for _, count in scene_sync.compact.values()], [int((~self.visible).sum())])
        # Export writes the rest once and the region once (as recovered from its polygons).
        written = st.export_file("compact_region_out.ply", up_axis="Z")
        self.assertEqual(len(written["opacities"]), len(self.mask))

    def test_a_moved_region_merges_back_where_it_is_seen(self):
        region, _ = region_editing.edit_region_as_polygons(bpy.context, self.obj, self.mask)
        region.location.x += 2.0  # world +X; the compact object's frame is rotated about X only, so its +X too
        bpy.context.view_layer.update()
        region_editing.merge_region_back(bpy.context, region)
        cloud = blender_splats.read_blender_splats(self.obj.data)
        self.assertEqual(len(cloud["opacities"]), len(self.mask))  # in place: no point added or removed
        expected = self.original["positions"][self.visible] + np.array([2.0, 0.0, 0.0], dtype=np.float32)
        np.testing.assert_allclose(cloud["positions"][self.visible], expected, atol=1e-5)
        for key in KEYS:  # the points outside the region are untouched
            np.testing.assert_array_equal(cloud[key][~self.visible], self.original[key][~self.visible], err_msg=key)

    def _edit_region_faces(self, region, operation):
        bpy.context.view_layer.objects.active = region
        bpy.ops.object.mode_set(mode="EDIT")
        bpy.ops.mesh.select_mode(type="FACE")
        bpy.ops.mesh.select_all(action="DESELECT")
        bpy.ops.object.mode_set(mode="OBJECT")
        selection = np.zeros(len(region.data.polygons), dtype=bool)
        selection[:10] = True
        region.data.polygons.foreach_set("select", selection)
        bpy.ops.object.mode_set(mode="EDIT")
        operation()
        bpy.ops.object.mode_set(mode="OBJECT")

    def test_deleted_faces_remove_their_points_and_duplicates_are_added(self):
        rows = np.flatnonzero(self.visible)
        region, _ = region_editing.edit_region_as_polygons(bpy.context, self.obj, self.mask)
        self._edit_region_faces(region, lambda: bpy.ops.mesh.delete(type="FACE"))
        region_editing.merge_region_back(bpy.context, region)
        self.assertEqual(compat.point_count(self.obj.data), len(self.mask))  # removed in place
        keep = np.ones(len(self.mask), dtype=bool)
        keep[rows[:10]] = False
        self.assert_cloud_equal(shown(self.obj), {key: self.original[key][keep] for key in KEYS})
        written = st.export_file("compact_region_deleted.ply")
        self.assertEqual(len(written["opacities"]), int(keep.sum()))

        # A second region that duplicates 10 faces: they first fill the 10 points removed, nothing is appended.
        region, _ = region_editing.edit_region_as_polygons(bpy.context, self.obj, self.mask)
        self._edit_region_faces(region, lambda: bpy.ops.mesh.duplicate())
        region_editing.merge_region_back(bpy.context, region)
        self.assertEqual(compat.point_count(self.obj.data), len(self.mask))
        self.assertEqual(compact_points.gaussian_count(self.obj.data), len(self.mask))
        got = shown(self.obj)
        self.assert_cloud_equal({key: got[key][keep] for key in KEYS}, {key: self.original[key][keep] for key in KEYS})
        # The duplicates are copies of the region's first 10 (which were rows[10:20] of the original).
        np.testing.assert_array_equal(np.sort(got["opacities"][~keep]), np.sort(self.original["opacities"][rows[10:20]]))

        # A third duplicates 10 again: nothing free, so 10 points are appended.
        region, _ = region_editing.edit_region_as_polygons(bpy.context, self.obj, self.mask)
        self._edit_region_faces(region, lambda: bpy.ops.mesh.duplicate())
        region_editing.merge_region_back(bpy.context, region)
        self.assertEqual(compat.point_count(self.obj.data), len(self.mask) + 10)
        self.assertEqual(compact_points.gaussian_count(self.obj.data), len(self.mask) + 10)

    def test_taking_a_small_region_does_not_rebuild_the_compact_data(self):
        data, count = self.obj.data, len(self.mask)
        small = np.zeros(count, dtype=bool)
        small[np.flatnonzero(region_editing.visible_gaussians(self.original["opacities"]))[:50]] = True
        views = []
        real = region_editing._PointViews

        def recording(data):
            views.append(real(data))
            return views[-1]

        with mock.patch.object(blender_splats, "new_blender_splat_data",
                               side_effect=AssertionError("rebuilt")), \
                mock.patch.object(blender_splats, "read_blender_splats",
                                  side_effect=AssertionError("read whole")), \
                mock.patch.object(region_editing, "_PointViews", side_effect=recording):
            region, _ = region_editing.edit_region_as_polygons(bpy.context, self.obj, small)
            self.assertIs(self.obj.data, data)
            self.assertEqual(compat.point_count(data), count)
            region_editing.merge_region_back(bpy.context, region)
        self.assertIs(self.obj.data, data)
        self.assertEqual(compat.point_count(data), count)
        # The values were read and written in Blender's arrays in place, not as whole copies.
        self.assertTrue(views)
        self.assertEqual([view.copies for view in views], [[]] * len(views))
        self.assert_cloud_equal(blender_splats.read_blender_splats(data), self.original)

    def test_nothing_selected_is_a_clear_error_and_changes_nothing(self):
        with self.assertRaisesRegex(ValueError, "no splats selected"):
            region_editing.edit_region_as_polygons(bpy.context, self.obj, np.zeros_like(self.mask))
        self.assertEqual(compat.point_count(self.obj.data), len(self.original["opacities"]))

    def test_points_out_in_a_region_are_not_taken_again(self):
        region, _ = region_editing.edit_region_as_polygons(bpy.context, self.obj, self.mask)
        with self.assertRaisesRegex(ValueError, "out in a region already"):
            region_editing.edit_region_as_polygons(bpy.context, self.obj, self.visible)
        other, _ = region_editing.edit_region_as_polygons(bpy.context, self.obj, np.ones_like(self.mask))
        self.assertEqual(len(other.data.polygons),
                         int((region_editing.visible_gaussians(self.original["opacities"]) & ~self.mask).sum()))
        region_editing.merge_region_back(bpy.context, other)
        region_editing.merge_region_back(bpy.context, region)
        self.assert_cloud_equal(blender_splats.read_blender_splats(self.obj.data), self.original)

    def test_a_deleted_region_is_listed_and_restored(self):
        region, _ = region_editing.edit_region_as_polygons(bpy.context, self.obj, self.mask)
        region_id = region[region_editing.REGION_ID_PROPERTY]
        self.assertEqual(region_editing.orphaned_regions(self.obj), [])
        bpy.data.objects.remove(region)
        self.assertEqual(region_editing.orphaned_regions(self.obj), [region_id])
        bpy.context.view_layer.objects.active = self.obj
        self.assertEqual(bpy.ops.object.raysplats_restore_regions(), {"FINISHED"})
        self.assertEqual(region_editing.orphaned_regions(self.obj), [])
        self.assert_cloud_equal(shown(self.obj), self.original)

    def test_a_region_survives_save_and_reload(self):
        region, _ = region_editing.edit_region_as_polygons(bpy.context, self.obj, self.mask)
        region.location.z += 1.0
        name, region_name = self.obj.name, region.name
        path = st.tmp_file("compact_region_open.blend")
        bpy.ops.wm.save_as_mainfile(filepath=path)
        bpy.ops.wm.open_mainfile(filepath=path)
        obj, region = bpy.data.objects[name], bpy.data.objects[region_name]
        self.assertEqual(compact_points.gaussian_count(obj.data), int((~self.visible).sum()))
        self.assertEqual(region_editing.orphaned_regions(obj), [])
        region_editing.merge_region_back(bpy.context, region)
        cloud = blender_splats.read_blender_splats(obj.data)
        self.assertEqual(len(cloud["opacities"]), len(self.mask))
        self.assertEqual(compact_points.gaussian_count(obj.data), len(self.mask))
        for key in KEYS:
            np.testing.assert_array_equal(cloud[key][~self.visible], self.original[key][~self.visible], err_msg=key)

    def test_the_operators_use_the_edit_mode_selection(self):
        bpy.context.view_layer.objects.active = self.obj
        selection = np.zeros(len(self.mask), dtype=bool)
        selection[:100] = True
        if hasattr(self.obj.data, "vertices"):  # a mesh below Blender 5.3
            self.obj.data.vertices.foreach_set("select", selection)
        else:  # a Gaussian-splat point cloud keeps Edit Mode's selection in ".selection"
            self.obj.data.attributes.new(".selection", "BOOLEAN", "POINT").data.foreach_set("value", selection)
        self.assertEqual(bpy.ops.object.raysplats_edit_region(), {"FINISHED"})
        region = bpy.context.view_layer.objects.active
        self.assertEqual(region.get(region_editing.REGION_OF_PROPERTY), self.obj.name)
        self.assertEqual(region.raysplats.vertices_per_polygon, region_editing.REGION_VERTICES_PER_POLYGON)
        visible = int(region_editing.visible_gaussians(self.original["opacities"][:100]).sum())
        self.assertEqual(len(region.data.polygons), visible)
        self.assertEqual(compact_points.gaussian_count(self.obj.data), len(self.mask) - visible)
        self.assertEqual(bpy.ops.object.raysplats_merge_region(), {"FINISHED"})
        self.assertIs(bpy.context.view_layer.objects.active, self.obj)
        self.assertEqual(compact_points.gaussian_count(self.obj.data), len(self.mask))
        self.assert_cloud_equal(blender_splats.read_blender_splats(self.obj.data), self.original)


class Rendering(unittest.TestCase):
    def test_the_render_scene_holds_every_point(self):
        st.reset_scene()
        obj = import_points()
        scene_sync = sync.SceneSync(bpy.context.evaluated_depsgraph_get())
        self.assertEqual(scene_sync.stats.splats, compat.point_count(obj.data))


if __name__ == "__main__":
    unittest.main()
