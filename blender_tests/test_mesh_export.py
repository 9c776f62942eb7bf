# Mesh export (export_scene.raysplats_mesh): every glTF/GLB passes the Khronos validator, Draco primitives
# decode to the exported counts, and OBJ/PLY/glTF come back through Blender's importers and assimp with the
# expected objects, vertex and face counts and colours. Options and errors are checked on small scenes.
import os
import unittest

import bpy
import numpy as np

import mesh_export_testing as mt
import splat_testing as st

SPLATS = "small_sh3_inria.ply"
N = 9080                  # Gaussians in SPLATS
K = 8                     # polygon vertices (import default)
PATCH_VERTICES, PATCH_TRIANGLES = (K + 1) * N, K * N
CUBE_VERTICES, CUBE_TRIANGLES = 8, 12


def splat_scene(with_cube):
    st.reset_scene()
    splats = st.import_file(SPLATS)
    cube = mt.add_red_cube() if with_cube else None
    return splats, cube


class GltfValidity(unittest.TestCase):
    def setUp(self):
        reason = mt.gltf_tools_missing()
        if reason:
            self.skipTest(reason)

    def test_every_gltf_and_glb_export_passes_the_validator_and_draco_decodes(self):
        for with_cube in (False, True):
            splat_scene(with_cube)
            vertices = PATCH_VERTICES + (CUBE_VERTICES if with_cube else 0)
            triangles = PATCH_TRIANGLES + (CUBE_TRIANGLES if with_cube else 0)
            for extension in (".gltf", ".glb"):
                for draco in (False, True):
                    with self.subTest(mixed=with_cube, extension=extension, draco=draco):
                        path = mt.export_mesh(f"validate_{int(with_cube)}_{int(draco)}{extension}", draco=draco)
                        report = mt.check_gltf(path)
                        self.assertEqual(report["errors"], 0, report["messages"])
                        doc = mt.gltf_json(path)
                        primitives = [p for m in doc["meshes"] for p in m["primitives"]]
                        self.assertEqual(sum(doc["accessors"][p["attributes"]["POSITION"]]["count"] for p in primitives),
                                         vertices)
                        self.assertEqual(sum(doc["accessors"][p["indices"]]["count"] for p in primitives), 3 * triangles)
                        for p in primitives:
                            self.assertEqual(set(p["attributes"]) >= {"POSITION", "NORMAL"}, True)
                        if draco:
                            self.assertIn("KHR_draco_mesh_compression", doc["extensionsRequired"])
                            self.assertEqual(len(report["draco"]), len(primitives))
                            for part in report["draco"]:
                                self.assertTrue(part["ok"], part["error"])
                                self.assertEqual(part["points"], part["accessor_points"])
                                self.assertEqual(part["faces"], part["accessor_faces"])
                                self.assertTrue(all(v > 0 for v in part["attributes"].values()), part)
                            self.assertEqual(sum(p["points"] for p in report["draco"]), vertices)
                            self.assertEqual(sum(p["faces"] for p in report["draco"]), triangles)
                        else:
                            self.assertNotIn("extensionsRequired", doc)

    def test_mixed_scene_materials_are_alpha_blended_splats_and_principled_values(self):
        splat_scene(with_cube=True)
        doc = mt.gltf_json(mt.export_mesh("materials.glb"))
        by_name = {m["name"]: m for m in doc["materials"]}
        splat = by_name["RaySplats Gaussian"]
        self.assertEqual(splat["alphaMode"], "BLEND")
        red = by_name["Red Metal"]["pbrMetallicRoughness"]
        np.testing.assert_allclose(red["baseColorFactor"], [0.8, 0.1, 0.05, 1.0], atol=1e-6)
        self.assertAlmostEqual(red["metallicFactor"], 0.25, places=6)
        self.assertAlmostEqual(red["roughnessFactor"], 0.4, places=6)
        splat_primitive = next(p for m in doc["meshes"] for p in m["primitives"]
                               if doc["materials"][p["material"]]["name"] == "RaySplats Gaussian")
        self.assertEqual(set(splat_primitive["attributes"]), {"POSITION", "NORMAL", "TEXCOORD_0", "COLOR_0"})
        color = doc["accessors"][splat_primitive["attributes"]["COLOR_0"]]
        self.assertEqual((color["componentType"], color["type"], color["normalized"]), (5121, "VEC4", True))

    def test_gltf_is_y_up_with_the_cube_where_blender_has_it(self):
        splat_scene(with_cube=True)
        doc = mt.gltf_json(mt.export_mesh("axes.glb", limit_to="SELECTED"))  # the cube is selected
        self.assertEqual(len(doc["meshes"]), 1)
        position = doc["accessors"][doc["meshes"][0]["primitives"][0]["attributes"]["POSITION"]]
        # Blender (1, 2, 3) ± 1 -> glTF (x, z, -y)
        np.testing.assert_allclose(position["min"], [0, 2, -3], atol=1e-6)
        np.testing.assert_allclose(position["max"], [2, 4, -1], atol=1e-6)
        # Local coordinates: vertices around the origin, the node carries the transform.
        doc = mt.gltf_json(mt.export_mesh("axes_local.glb", limit_to="SELECTED", coordinates="LOCAL"))
        position = doc["accessors"][doc["meshes"][0]["primitives"][0]["attributes"]["POSITION"]]
        np.testing.assert_allclose(position["min"], [-1, -1, -1], atol=1e-6)
        np.testing.assert_allclose(np.array(doc["nodes"][0]["matrix"]).reshape(4, 4)[3, :3], [1, 3, -2], atol=1e-6)

    def test_khr_gaussian_splatting_points(self):
        splat_scene(with_cube=False)
        path = mt.export_mesh("khr_splats.glb", gaussian_splatting=True)
        doc = mt.gltf_json(path)
        self.assertIn("KHR_gaussian_splatting", doc["extensionsUsed"])
        points = [p for m in doc["meshes"] for p in m["primitives"] if p.get("mode") == 0]
        self.assertEqual(len(points), 1)
        attributes = points[0]["attributes"]
        self.assertEqual(doc["accessors"][attributes["POSITION"]]["count"], N)
        for name in ("ROTATION", "SCALE", "OPACITY", "SH_DEGREE_0_COEF_0", "SH_DEGREE_3_COEF_6"):
            self.assertIn("KHR_gaussian_splatting:" + name, attributes)
        # The validator (2.0.0-dev.3.10) predates the ratified extension and flags exactly its attribute
        # names; nothing else may be wrong.
        # In local coordinates the points' node carries the object transform, like the patches' node.
        doc = mt.gltf_json(mt.export_mesh("khr_splats_local.glb", gaussian_splatting=True, coordinates="LOCAL"))
        matrices = [node.get("matrix") for node in doc["nodes"]]
        self.assertEqual(len(matrices), 2)
        self.assertIsNotNone(matrices[0])
        self.assertEqual(matrices[0], matrices[1])
        report = mt.check_gltf(path)
        other = [m for m in report["messages"]
                 if m.startswith("error") and not ("MESH_PRIMITIVE_INVALID_ATTRIBUTE" in m and "KHR_gaussian_splatting:" in m)]
        self.assertEqual(other, [])


class Reimport(unittest.TestCase):
    """OBJ, PLY and glTF exports read back by Blender's importers and by assimp."""

    @classmethod
    def setUpClass(cls):
        splat_scene(with_cube=True)
        cls.paths = {ext: mt.export_mesh("reimport" + ext) for ext in (".obj", ".ply", ".gltf", ".glb")}
        cloud = st.native().read_splats(st.data_file(SPLATS))
        cls.srgb, cls.linear, cls.alpha = mt.expected_patch_colors(cloud)
        cube_linear = np.array([0.8, 0.1, 0.05])
        cube_srgb = np.where(cube_linear <= 0.0031308, 12.92 * cube_linear, 1.055 * cube_linear ** (1 / 2.4) - 0.055)
        cls.cube_srgb = cube_srgb
        total = PATCH_VERTICES + CUBE_VERTICES
        # Mean per-vertex colour of splats alone, and of splats + cube (PLY merges everything into one mesh).
        cls.splat_linear = cls.linear.mean(axis=0)
        cls.splat_alpha = cls.alpha.mean()
        cls.all_srgb = (cls.srgb.sum(axis=0) * (K + 1) + cube_srgb * CUBE_VERTICES) / total
        cls.all_linear = (cls.linear.sum(axis=0) * (K + 1) + cube_linear * CUBE_VERTICES) / total
        cls.all_alpha = (cls.alpha.sum() * (K + 1) + CUBE_VERTICES) / total

    def setUp(self):
        st.reset_scene()

    def test_assimp_reads_every_format_with_the_expected_counts(self):
        for ext, path in self.paths.items():
            with self.subTest(ext=ext):
                meshes, vertices, faces = mt.assimp_info(path)
                # assimp's OBJ loader makes one vertex per face corner.
                self.assertEqual(vertices, 3 * (PATCH_TRIANGLES + CUBE_TRIANGLES) if ext == ".obj"
                                 else PATCH_VERTICES + CUBE_VERTICES)
                self.assertEqual(faces, PATCH_TRIANGLES + CUBE_TRIANGLES)
                # PLY: one mesh; OBJ: one per object; glTF: one per primitive (2 splat parts + the cube).
                self.assertEqual(meshes, {".ply": 1, ".obj": 2}.get(ext, 3))

    def test_assimp_reads_the_vertex_colours(self):
        for ext, path in self.paths.items():
            with self.subTest(ext=ext):
                mean, count = mt.assimp_mean_color(path, "reimport_dump.assxml")
                # glTF COLOR_0 is linear; OBJ and PLY store display (sRGB) values; OBJ has no alpha.
                expected = self.all_linear if ext in (".gltf", ".glb") else self.all_srgb
                if ext == ".obj":
                    # assimp's OBJ loader gives one vertex per face corner: K triangles x 3 corners per patch.
                    self.assertEqual(count, 3 * (PATCH_TRIANGLES + CUBE_TRIANGLES))
                    expected = (self.srgb.sum(axis=0) * 3 * K + self.cube_srgb * 3 * CUBE_TRIANGLES) / count
                else:
                    self.assertEqual(count, PATCH_VERTICES + CUBE_VERTICES)
                np.testing.assert_allclose(mean[:3], expected, atol=4e-3)
                if ext != ".obj":
                    self.assertAlmostEqual(mean[3], self.all_alpha, delta=4e-3)

    def test_blender_gltf_importer(self):
        for ext in (".gltf", ".glb"):
            with self.subTest(ext=ext):
                st.reset_scene()
                objects = mt.import_with_blender(self.paths[ext])
                self.assertEqual(len(objects), 2)
                splats = max(objects, key=lambda o: len(o.data.vertices))
                cube = min(objects, key=lambda o: len(o.data.vertices))
                self.assertEqual((len(splats.data.vertices), len(splats.data.polygons)), (PATCH_VERTICES, PATCH_TRIANGLES))
                self.assertEqual((len(cube.data.vertices), len(cube.data.polygons)), (CUBE_VERTICES, CUBE_TRIANGLES))
                mean = mt.mean_vertex_color(splats.data)
                self.assertIsNotNone(mean, "COLOR_0 was not imported")
                np.testing.assert_allclose(mean[:3], self.splat_linear, atol=4e-3)
                self.assertAlmostEqual(mean[3], self.splat_alpha, delta=4e-3)
                # The cube where it was: Blender (1, 2, 3) after glTF's Y-up round trip.
                np.testing.assert_allclose(np.array(cube.matrix_world.translation) +
                                           np.mean([v.co for v in cube.data.vertices], axis=0), [1, 2, 3], atol=1e-5)

    def test_blender_obj_importer(self):
        objects = mt.import_with_blender(self.paths[".obj"])
        self.assertEqual(len(objects), 2)
        splats = max(objects, key=lambda o: len(o.data.vertices))
        self.assertEqual((len(splats.data.vertices), len(splats.data.polygons)), (PATCH_VERTICES, PATCH_TRIANGLES))
        self.assertIn("Red_Metal", [m.name for o in objects for m in o.data.materials])
        mean = mt.mean_vertex_color(splats.data)
        if mean is None and bpy.app.version < (3, 5, 0):
            return  # Blender's OBJ importer reads vertex colours from 3.5 on (assimp checks them above)
        self.assertIsNotNone(mean, "OBJ vertex colours were not imported")
        np.testing.assert_allclose(mean[:3], self.splat_linear, atol=4e-3)

    def test_blender_ply_importer(self):
        objects = mt.import_with_blender(self.paths[".ply"])
        self.assertEqual(len(objects), 1)
        mesh = objects[0].data
        self.assertEqual((len(mesh.vertices), len(mesh.polygons)),
                         (PATCH_VERTICES + CUBE_VERTICES, PATCH_TRIANGLES + CUBE_TRIANGLES))
        mean = mt.mean_vertex_color(mesh)
        self.assertIsNotNone(mean, "PLY vertex colours were not imported")
        np.testing.assert_allclose(mean[:3], self.all_linear, atol=4e-3)
        self.assertAlmostEqual(mean[3], self.all_alpha, delta=4e-3)
        self.assertEqual(len(mesh.uv_layers), 1)


class Options(unittest.TestCase):
    def setUp(self):
        self.splats, self.cube = splat_scene(with_cube=True)

    def counts(self, name, **options):
        doc = mt.gltf_json(mt.export_mesh(name, **options))
        primitives = [p for m in doc["meshes"] for p in m["primitives"]]
        return (sum(doc["accessors"][p["attributes"]["POSITION"]]["count"] for p in primitives),
                sum(doc["accessors"][p["indices"]]["count"] for p in primitives) // 3)

    def test_selected_only(self):
        bpy.ops.object.select_all(action="DESELECT")
        self.splats.select_set(True)
        self.assertEqual(self.counts("selected.glb", limit_to="SELECTED"), (PATCH_VERTICES, PATCH_TRIANGLES))

    def test_original_polygons(self):
        # K corners per face, fan-triangulated into K - 2 triangles; plus the cube.
        self.assertEqual(self.counts("polygons.glb", splat_geometry="POLYGONS"),
                         (K * N + CUBE_VERTICES, (K - 2) * N + CUBE_TRIANGLES))

    def test_apply_modifiers(self):
        modifier = self.cube.modifiers.new("Array", "ARRAY")
        modifier.count = 3
        self.assertEqual(self.counts("modifiers.glb")[1], PATCH_TRIANGLES + 3 * CUBE_TRIANGLES)
        self.assertEqual(self.counts("no_modifiers.glb", apply_modifiers=False)[1], PATCH_TRIANGLES + CUBE_TRIANGLES)

    def test_edited_splats_export_where_they_are(self):
        # Moving the splat object moves its patches: compare glTF bounds before and after a translation.
        def bounds(name):
            bpy.ops.object.select_all(action="DESELECT")
            self.splats.select_set(True)
            doc = mt.gltf_json(mt.export_mesh(name, limit_to="SELECTED"))
            accessors = [doc["accessors"][p["attributes"]["POSITION"]] for m in doc["meshes"] for p in m["primitives"]]
            return np.min([a["min"] for a in accessors], axis=0), np.max([a["max"] for a in accessors], axis=0)

        lo0, hi0 = bounds("before_move.glb")
        self.splats.location.z += 10.0  # Blender +Z -> glTF +Y
        bpy.context.view_layer.update()
        lo1, hi1 = bounds("after_move.glb")
        np.testing.assert_allclose(lo1 - lo0, [0, 10, 0], atol=1e-4)
        np.testing.assert_allclose(hi1 - hi0, [0, 10, 0], atol=1e-4)

    def test_obj_and_ply_up_axis(self):
        bpy.ops.object.select_all(action="DESELECT")
        self.cube.select_set(True)
        for up_axis, expected in (("Y", [1, 3, -2]), ("Z", [1, 2, 3])):
            path = mt.export_mesh(f"up_{up_axis}.obj", limit_to="SELECTED", up_axis=up_axis)
            with open(path) as f:
                vertices = np.array([line.split()[1:4] for line in f if line.startswith("v ")], dtype=np.float64)
            np.testing.assert_allclose(vertices.mean(axis=0), expected, atol=1e-5)


class Errors(unittest.TestCase):
    def test_empty_scene(self):
        st.reset_scene()
        with self.assertRaisesRegex(RuntimeError, "Nothing to export"):
            bpy.ops.export_scene.raysplats_mesh(filepath=st.tmp_file("empty.glb"))

    def test_empty_selection(self):
        splat_scene(with_cube=True)
        bpy.ops.object.select_all(action="DESELECT")
        with self.assertRaisesRegex(RuntimeError, "no objects are selected"):
            bpy.ops.export_scene.raysplats_mesh(filepath=st.tmp_file("none.glb"), limit_to="SELECTED")

    def test_unwritable_path_and_no_half_written_file(self):
        splat_scene(with_cube=True)
        with self.assertRaisesRegex(RuntimeError, "cannot write"):
            bpy.ops.export_scene.raysplats_mesh(filepath="/nonexistent-folder/scene.glb")
        # A failed export leaves an existing good file alone, and no temporary files behind.
        good = mt.export_mesh("keep.ply")
        with open(good, "rb") as f:
            before = f.read()
        bpy.ops.object.select_all(action="DESELECT")
        with self.assertRaises(RuntimeError):
            bpy.ops.export_scene.raysplats_mesh(filepath=good, limit_to="SELECTED")
        with open(good, "rb") as f:
            self.assertEqual(f.read(), before)
        folder = os.path.dirname(good)
        self.assertEqual([f for f in os.listdir(folder) if ".tmp" in f and f.startswith("keep")], [])

    def test_unknown_extension_and_draco_outside_gltf(self):
        splat_scene(with_cube=False)
        with self.assertRaisesRegex(RuntimeError, "unknown mesh format"):
            bpy.ops.export_scene.raysplats_mesh(filepath=st.tmp_file("scene.fbx"))
        with self.assertRaisesRegex(RuntimeError, "glTF features"):
            bpy.ops.export_scene.raysplats_mesh(filepath=st.tmp_file("scene.obj"), draco=True)
