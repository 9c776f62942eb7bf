# glTF files with KHR_gaussian_splatting through File > Import > Gaussian Splats: the splats become a Gaussian object
# (the core's reader, as every splat format), the file's meshes come through Blender's own glTF importer, a glTF
# without splats is refused with a message that points to that importer; and the automatic up axis finds a Z-up scene.
import os
import unittest

import bpy
import numpy as np

import mesh_export_testing as mt
import splat_testing as st
from raysplats.io import format_table
from raysplats.objects import polygon_mesh

DONUT = "donut_sh0.ply"  # a Blender-made object: Z up in its file


def world_gaussians(obj):
    depsgraph = bpy.context.evaluated_depsgraph_get()
    return polygon_mesh.recover_object_gaussians(st.native(), obj, depsgraph, np.array(obj.matrix_world, np.float64))


def gaussian_objects():
    return [obj for obj in bpy.data.objects if polygon_mesh.is_gaussian_object(obj)]


class GltfImport(unittest.TestCase):
    def setUp(self):
        st.reset_scene()

    def test_exported_splats_come_back_the_same_and_upright(self):
        original = st.import_file(DONUT, max_count=4000)
        self.assertEqual(original.raysplats.up_axis, "Z", "the donut's up should be found from its data")
        before = world_gaussians(original)
        path = mt.export_mesh("donut_khr.glb", gaussian_splatting=True, limit_to="SELECTED")
        st.reset_scene()
        result = bpy.ops.import_scene.gaussian_splats(filepath=path, gltf_meshes=False)
        self.assertEqual(result, {"FINISHED"})
        [back] = gaussian_objects()
        # glTF is +Y up by specification: taken at its word (not detected), and converted to the core's -Y.
        self.assertEqual(back.raysplats.up_axis, "-Y")
        after = world_gaussians(back)
        size = np.abs(before["positions"]).max()
        # Same Gaussians in the same world places: the scene stands as it stood before export.
        np.testing.assert_allclose(after["positions"], before["positions"], atol=1e-5 * size)
        np.testing.assert_allclose(after["scales"], before["scales"], rtol=1e-4, atol=1e-7 * size)
        np.testing.assert_allclose(after["opacities"], before["opacities"], atol=1e-6)
        np.testing.assert_allclose(after["sh"], before["sh"], atol=1e-5)

    def test_file_with_meshes_and_splats_gives_both(self):
        # A file made by the core directly: 500 Gaussians (points only, no patches) and a triangle mesh.
        # (visible ones: Gaussians below opacity 1/255 get no polygon)
        cloud = st.native().read_splats(st.data_file(DONUT), max_count=500, min_opacity=0.01)
        scene = st.native().MeshExportScene()
        scene.add_splats("Donut", cloud["positions"], cloud["rotations"], cloud["scales"], cloud["opacities"],
                         cloud["sh"], keep_gaussians=True, patches=False)
        positions = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], np.float32)
        triangles = np.array([0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3], np.uint32)
        scene.add_triangles("Tetrahedron", positions, triangles, transform=np.eye(4))
        path = st.tmp_file("splats_and_mesh.glb")
        scene.write(path, gaussian_splatting=True)
        result = bpy.ops.import_scene.gaussian_splats(filepath=path)
        self.assertEqual(result, {"FINISHED"})
        [splats] = gaussian_objects()
        self.assertEqual(len(splats.data.polygons), len(cloud["opacities"]))
        others = [obj for obj in bpy.data.objects if obj not in (splats,) and obj.type == "MESH"]
        self.assertEqual([len(obj.data.polygons) for obj in others], [4], "the tetrahedron, and no point cloud")
        self.assertIs(bpy.context.view_layer.objects.active, splats)
        # Without its meshes: the splats only.
        st.reset_scene()
        self.assertEqual(bpy.ops.import_scene.gaussian_splats(filepath=path, gltf_meshes=False), {"FINISHED"})
        self.assertEqual([obj.type for obj in bpy.data.objects if obj.type == "MESH"], ["MESH"])

    def test_gltf_without_splats_is_refused_with_a_pointer_to_the_gltf_importer(self):
        scene = st.native().MeshExportScene()
        scene.add_triangles("Triangle", np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32),
                            np.array([0, 1, 2], np.uint32), transform=np.eye(4))
        path = st.tmp_file("no_splats.glb")
        scene.write(path)
        objects = len(bpy.data.objects)
        with self.assertRaises(RuntimeError) as raised:
            bpy.ops.import_scene.gaussian_splats(filepath=path)
        message = str(raised.exception)
        self.assertIn("no KHR_gaussian_splatting primitives", message)
        self.assertIn("File > Import > glTF 2.0", message)
        self.assertIn(path, message)
        self.assertNotIn("internal error", message)
        self.assertEqual(len(bpy.data.objects), objects, "nothing imported")

    def test_splat_export_points_to_the_mesh_export_for_gltf(self):
        st.import_file(DONUT, max_count=500)
        with self.assertRaises(RuntimeError) as raised:
            bpy.ops.export_scene.gaussian_splats(filepath=st.tmp_file("splats.glb"))
        self.assertIn("File > Export > RaySplats Mesh", str(raised.exception))
        self.assertFalse(os.path.exists(st.tmp_file("splats.glb")))
        self.assertNotIn(".glb", format_table.splat_file_browser_filter(writable_only=True))
        self.assertIn(".glb", format_table.splat_file_browser_filter())


class AutomaticUpAxis(unittest.TestCase):
    def setUp(self):
        st.reset_scene()

    def test_detected_by_default_convention_on_request(self):
        donut = st.import_file(DONUT, max_count=4000)
        self.assertEqual(donut.raysplats.up_axis, "Z")
        self.assertEqual(tuple(donut.rotation_euler), (0.0, 0.0, 0.0))
        st.reset_scene()
        donut = st.import_file(DONUT, max_count=4000, up_axis="AUTO")
        self.assertEqual(donut.raysplats.up_axis, "-Y")
        st.reset_scene()
        unicorn = st.import_file("unicorn_sh3_reordered.ply")
        self.assertEqual(unicorn.raysplats.up_axis, "-Y")
        # The unicorn stands: its head (the top of its Gaussians) is up in Blender, its extent along Z the largest.
        positions = world_gaussians(unicorn)["positions"]
        extent = np.percentile(positions, 99, axis=0) - np.percentile(positions, 1, axis=0)
        self.assertEqual(int(np.argmax(extent)), 2)


if __name__ == "__main__":
    unittest.main()
