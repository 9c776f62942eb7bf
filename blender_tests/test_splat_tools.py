# Splat tools and Blender operations on splat objects: what an export limits itself to, the joined object
# that stays a splat object, the selection and clean-up tools against counts computed here in numpy from the files'
# own values, colour adjustments against a numpy colour map, the Gaussian-exact Apply Transform under non-uniform and
# sheared maps, and the topology-changing modifier warnings.
import math
import unittest

import bpy
import numpy as np
from mathutils import Euler, Matrix

import splat_testing as st

DONUT = "donut_sh0.ply"
UNICORN = "unicorn_sh3_reordered.ply"


def read_ply(name):
    """The vertex properties of a binary little-endian float PLY, by name, read here without the core."""
    with open(st.data_file(name), "rb") as f:
        header = b""
        while not header.endswith(b"end_header\n"):
            header += f.readline()
        lines = header.decode("ascii").splitlines()
        count = int(next(line for line in lines if line.startswith("element vertex")).split()[2])
        names = [line.split()[2] for line in lines if line.startswith("property float")]
        data = np.frombuffer(f.read(count * 4 * len(names)), dtype="<f4").reshape(count, len(names))
    return {name: data[:, i].astype(np.float64) for i, name in enumerate(names)}


def file_gaussians(name):
    """Linear opacities, scales, centres (file axes) and SH (N, coeffs, 3) of a 3DGS PLY's visible Gaussians, by the
    INRIA contract."""
    p = read_ply(name)
    rest = sorted((key for key in p if key.startswith("f_rest_")), key=lambda key: int(key[7:]))
    coeffs = len(rest) // 3 + 1
    sh = np.zeros((len(p["x"]), coeffs, 3))
    for c in range(3):
        sh[:, 0, c] = p[f"f_dc_{c}"]
        for k in range(1, coeffs):
            sh[:, k, c] = p[rest[c * (coeffs - 1) + k - 1]]
    gaussians = {"opacity": 1.0 / (1.0 + np.exp(-p["opacity"])),
                 "scales": np.exp(np.stack([p["scale_0"], p["scale_1"], p["scale_2"]], axis=1)),
                 "positions": np.stack([p["x"], p["y"], p["z"]], axis=1), "sh": sh}
    # An import keeps the Gaussians with something visible (opacity a with 255 a > 1, tested on the opacity the core
    # reads, so that the boundary is decided the same way); the tools see only those.
    keep = st.native().read_splats(st.data_file(name))["opacities"].astype(np.float64) * 255.0 > 1.0
    return {key: value[keep] for key, value in gaussians.items()}


def world_positions(obj, file_positions):
    """Centres in Blender world coordinates: the import keeps file coordinates in the mesh and rotates the object."""
    world = np.array(obj.matrix_world, dtype=np.float64)
    return file_positions @ world[:3, :3].T + world[:3, 3]


def selected_faces(obj):
    flags = np.empty(len(obj.data.polygons), dtype=bool)
    obj.data.polygons.foreach_get("select", flags)
    return flags


def edit_mode(obj):
    bpy.context.view_layer.objects.active = obj
    obj.select_set(True)
    bpy.ops.object.mode_set(mode="EDIT")


def object_mode():
    bpy.ops.object.mode_set(mode="OBJECT")


class ExportLimit(unittest.TestCase):
    def setUp(self):
        st.reset_scene()
        self.donut = st.import_file(DONUT)
        self.unicorn = st.import_file(UNICORN)
        self.donut_count, self.unicorn_count = len(self.donut.data.polygons), len(self.unicorn.data.polygons)

    def test_hidden_objects_are_not_exported_by_default(self):
        self.unicorn.hide_set(True)
        self.unicorn.hide_render = True
        self.assertEqual(len(st.export_file("visible.ply")["opacities"]), self.donut_count)
        # Asking for everything that renders leaves the unicorn out too, asking for the selection gives it.
        self.assertEqual(len(st.export_file("renderable.ply", limit_to="RENDERABLE")["opacities"]), self.donut_count)
        self.unicorn.hide_render = False
        self.assertEqual(len(st.export_file("renderable2.ply", limit_to="RENDERABLE")["opacities"]),
                         self.donut_count + self.unicorn_count)
        self.unicorn.hide_set(False)
        bpy.ops.object.select_all(action="DESELECT")
        self.unicorn.select_set(True)
        self.assertEqual(len(st.export_file("selected.ply", limit_to="SELECTED")["opacities"]), self.unicorn_count)
        # The stable keyword from before Limit to (docs/reference.md) still selects.
        self.assertEqual(len(st.export_file("selected_old.ply", use_selection=True)["opacities"]), self.unicorn_count)
        path = st.tmp_file("selected_old.glb")
        self.assertEqual(bpy.ops.export_scene.raysplats_mesh(filepath=path, use_selection=True), {"FINISHED"})

    def test_excluded_collection_and_active_collection(self):
        collection = bpy.data.collections.new("Elsewhere")
        bpy.context.scene.collection.children.link(collection)
        for users in list(self.unicorn.users_collection):
            users.objects.unlink(self.unicorn)
        collection.objects.link(self.unicorn)
        layer_collection = bpy.context.view_layer.layer_collection.children["Elsewhere"]
        bpy.context.view_layer.active_layer_collection = layer_collection
        self.assertEqual(len(st.export_file("active.ply", limit_to="ACTIVE_COLLECTION")["opacities"]),
                         self.unicorn_count)
        layer_collection.exclude = True
        self.assertEqual(len(st.export_file("excluded.ply")["opacities"]), self.donut_count)

    def test_mesh_export_leaves_hidden_objects_out(self):
        from raysplats.io import export_mesh
        path = st.tmp_file("visible.glb")
        everything = export_mesh.export_mesh_file(bpy.context, path)["gaussians"]
        self.assertEqual(everything, self.donut_count + self.unicorn_count)
        self.donut.hide_set(True)
        self.assertEqual(export_mesh.export_mesh_file(bpy.context, path)["gaussians"], self.unicorn_count)
        self.assertEqual(export_mesh.export_mesh_file(bpy.context, path, limit_to="RENDERABLE")["gaussians"],
                         self.donut_count + self.unicorn_count)


class JoinAndMark(unittest.TestCase):
    def test_join_into_an_ordinary_mesh_keeps_a_splat_object(self):
        st.reset_scene()
        splats = st.import_file(UNICORN)
        count = len(splats.data.polygons)
        bpy.ops.mesh.primitive_cube_add()
        cube = bpy.context.active_object
        splats.select_set(True)
        bpy.ops.object.join()  # the cube is active: Blender keeps its (non-splat) settings
        self.assertIs(bpy.context.active_object, cube)
        settings = cube.raysplats
        self.assertTrue(settings.is_gaussian)
        self.assertEqual((settings.vertices_per_polygon, settings.sh_degree), (8, 3))
        self.assertAlmostEqual(settings.radius, 3.0, places=4)
        # The cube's 6 faces become added Gaussians; the unicorn's are exported as they were.
        exported = st.export_file("joined.ply")
        self.assertEqual(len(exported["opacities"]), count + 6)

    def test_a_mostly_ordinary_mesh_stays_ordinary_and_can_be_marked_by_hand(self):
        st.reset_scene()
        splats = st.import_file(DONUT, max_count=10)
        bpy.ops.mesh.primitive_uv_sphere_add()  # 512 faces: the splat faces are a minority
        sphere = bpy.context.active_object
        splats.select_set(True)
        bpy.ops.object.join()
        self.assertFalse(sphere.raysplats.is_gaussian)
        sphere.raysplats.radius = 1.0
        bpy.ops.object.raysplats_mark_splats()
        self.assertTrue(sphere.raysplats.is_gaussian)
        self.assertAlmostEqual(sphere.raysplats.radius, 3.0, places=4)  # read back from the corner UVs


class SelectionTools(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.file = file_gaussians(DONUT)

    def setUp(self):
        st.reset_scene()
        self.obj = st.import_file(DONUT)
        self.assertEqual(len(self.obj.data.polygons), len(self.file["opacity"]))

    def select(self, operator, **options):
        edit_mode(self.obj)
        result = operator(**options)
        self.assertEqual(result, {"FINISHED"})
        object_mode()
        return selected_faces(self.obj)

    def test_select_by_opacity(self):
        expected = (self.file["opacity"] >= 0.02) & (self.file["opacity"] <= 0.2)
        self.assertGreater(expected.sum(), 100)
        selected = self.select(bpy.ops.mesh.raysplats_select_opacity, min_opacity=0.02, max_opacity=0.2)
        self.assertEqual(selected.sum(), expected.sum())
        np.testing.assert_array_equal(selected, expected)
        # Vertices follow their faces (8 corners per splat, no shared vertices).
        vertices = np.empty(len(self.obj.data.vertices), dtype=bool)
        self.obj.data.vertices.foreach_get("select", vertices)
        self.assertEqual(vertices.sum(), 8 * expected.sum())

    def test_select_by_size_extends_and_subtracts(self):
        largest = self.file["scales"].max(axis=1)
        threshold = float(np.quantile(largest, 0.95))
        expected = largest >= threshold
        selected = self.select(bpy.ops.mesh.raysplats_select_size, min_size=threshold, max_size=1e6)
        self.assertLessEqual(abs(int(selected.sum()) - int(expected.sum())), 2)  # float32 world scales at the edge
        self.assertGreaterEqual((selected == expected).mean(), 0.9999)
        faint = (self.file["opacity"] <= 0.1)
        both = self.select(bpy.ops.mesh.raysplats_select_opacity, min_opacity=0.0, max_opacity=0.1, action="ADD")
        self.assertLessEqual(abs(int(both.sum()) - int((expected | faint).sum())), 2)
        rest = self.select(bpy.ops.mesh.raysplats_select_opacity, min_opacity=0.0, max_opacity=0.1,
                           action="SUBTRACT")
        self.assertLessEqual(abs(int(rest.sum()) - int((expected & ~faint).sum())), 2)

    def test_select_by_color(self):
        display = np.clip(0.5 + st.C0 * self.file["sh"][:, 0, :], 0.0, 1.0)
        target = np.array([0.85, 0.55, 0.35])
        distance = np.linalg.norm(display - target, axis=1)
        expected = distance <= 0.15
        self.assertGreater(expected.sum(), 100)
        selected = self.select(bpy.ops.mesh.raysplats_select_color, color=tuple(target), distance=0.15)
        self.assertEqual(selected.sum(), expected.sum())

    def test_select_floaters(self):
        # Mean distance to the 8 nearest other centres, brute force (distances do not change under the import's
        # rotation, so the file's centres serve), over the file's first 12,000 Gaussians to keep it quick.
        count = 12000
        st.reset_scene()
        self.obj = st.import_file(DONUT, max_count=count)
        # Those of them the import kept: the visible ones (255 a > 1).
        first = st.native().read_splats(st.data_file(DONUT), max_count=count)
        positions = first["positions"][first["opacities"].astype(np.float64) * 255.0 > 1.0].astype(np.float64)
        k = 8
        mean_distances = np.empty(len(positions))
        for start in range(0, len(positions), 512):
            block = positions[start:start + 512]
            d2 = ((block[:, None, :] - positions[None, :, :]) ** 2).sum(axis=2)
            d2[np.arange(len(block)), np.arange(start, start + len(block))] = np.inf
            nearest = np.partition(d2, k - 1, axis=1)[:, :k]
            mean_distances[start:start + len(block)] = np.sqrt(nearest).mean(axis=1)
        expected = mean_distances > mean_distances.mean() + 3.0 * mean_distances.std()
        self.assertGreater(expected.sum(), 10)
        selected = self.select(bpy.ops.mesh.raysplats_select_floaters, neighbors=k, threshold=3.0)
        self.assertLessEqual(np.count_nonzero(selected != expected), 1)
        self.assertEqual(selected.sum(), expected.sum())

    def test_select_outside_a_rotated_crop_box_and_delete(self):
        world = world_positions(self.obj, self.file["positions"])
        centre = np.median(world, axis=0)
        bpy.ops.mesh.primitive_cube_add(location=tuple(centre), rotation=(0.3, 0.1, 0.7))
        crop = bpy.context.active_object
        crop.scale = tuple(np.percentile(np.abs(world - centre), 60, axis=0) * (1.0, 1.3, 0.8))
        bpy.context.view_layer.update()
        local = (world - np.array(crop.matrix_world.translation)) @ np.array(crop.matrix_world.to_3x3().inverted()).T
        outside = ~np.all(np.abs(local) <= 1.0, axis=1)
        self.assertTrue(0.1 < outside.mean() < 0.9)
        bpy.ops.object.select_all(action="DESELECT")
        selected = self.select(bpy.ops.mesh.raysplats_select_crop_box, crop_object=crop.name, inside=False)
        self.assertEqual(selected.sum(), outside.sum())
        edit_mode(self.obj)
        self.assertEqual(bpy.ops.mesh.raysplats_delete_selected(), {"FINISHED"})
        object_mode()
        self.assertEqual(len(self.obj.data.polygons), (~outside).sum())
        self.assertEqual(len(st.export_file("cropped.ply")["opacities"]), (~outside).sum())


class CleanUpAndColors(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.file = file_gaussians(UNICORN)

    def setUp(self):
        st.reset_scene()
        self.obj = st.import_file(UNICORN)

    def test_reduce_sh_degree(self):
        self.assertEqual(bpy.ops.object.raysplats_reduce_sh_degree(degree=1), {"FINISHED"})
        self.assertEqual(self.obj.raysplats.sh_degree, 1)
        self.assertIsNone(self.obj.data.attributes.get("gs_sh_4"))
        exported = st.export_file("reduced.ply")
        self.assertEqual(exported["sh"].shape[1:], (4, 3))
        np.testing.assert_allclose(exported["sh"][:, 0, :], self.file["sh"][:, 0, :], atol=1e-6)
        # Band 1 is kept as it was (rotated back to file axes on export).
        np.testing.assert_allclose(exported["sh"][:, 1:4, :], self.file["sh"][:, 1:4, :], atol=2e-5)

    def test_color_adjustments_reach_the_export_and_the_viewport(self):
        adjustment = {"exposure": 0.5, "brightness": -0.05, "saturation": 0.7, "hue": 0.1, "temperature": 0.4}
        for name, value in adjustment.items():
            setattr(self.obj.raysplats, name, value)
        # In the UI the message bus reports the edit; headless it is never delivered, and any update of the object
        # shows the adjustments too.
        self.obj.update_tag()
        bpy.context.view_layer.update()
        # The same map, written out here: exposure, temperature gains, saturation about Rec. 709 luma, hue rotation
        # about the grey axis, brightness offset.
        gain = 2.0 ** 0.5 * np.diag([1 + 0.2 * 0.4, 1.0, 1 - 0.2 * 0.4])
        luma = np.tile([0.2126, 0.7152, 0.0722], (3, 1))
        saturation = 0.7 * np.eye(3) + 0.3 * luma
        theta, u = 2 * math.pi * 0.1, np.ones(3) / math.sqrt(3)
        cross = np.array([[0, -u[2], u[1]], [u[2], 0, -u[0]], [-u[1], u[0], 0]])
        hue = math.cos(theta) * np.eye(3) + math.sin(theta) * cross + (1 - math.cos(theta)) * np.outer(u, u)
        m = hue @ saturation @ gain
        expected = self.file["sh"] @ m.T
        expected[:, 0, :] += ((m @ np.full(3, 0.5)) - 0.05 - 0.5) / st.C0
        exported = st.export_file("adjusted.ply")
        np.testing.assert_allclose(exported["sh"][:, 0, :], expected[:, 0, :], atol=2e-5)
        np.testing.assert_allclose(exported["sh"][:, 1:, :], expected[:, 1:, :], atol=5e-5)
        # The viewport's colour attribute (Solid and Material Preview) shows the adjusted DC colour.
        colors = np.empty(len(self.obj.data.loops) * 4, dtype=np.float32)
        self.obj.data.color_attributes["gs_color"].data.foreach_get("color", colors)
        display = np.clip(0.5 + st.C0 * expected[:, 0, :], 0, 1)
        # (A byte colour attribute: the display value's sRGB byte, which Blender gives back decoded to linear.)
        linear = np.where(np.round(display * 255) / 255 <= 0.04045, np.round(display * 255) / 255 / 12.92,
                          ((np.round(display * 255) / 255 + 0.055) / 1.055) ** 2.4)
        np.testing.assert_allclose(colors.reshape(-1, 8, 4)[:, 0, :3], linear, atol=1e-4)
        # Back to neutral: the imported colours exactly.
        for name in adjustment:
            self.obj.raysplats.property_unset(name)
        self.obj.raysplats.exposure = 0.0
        np.testing.assert_allclose(st.export_file("neutral.ply")["sh"], self.file["sh"], atol=2e-5)

    def test_render_sync_applies_the_adjustments(self):
        from raysplats.engine import sync
        from raysplats.objects import polygon_mesh
        from raysplats import native
        self.obj.raysplats.exposure = 1.0
        depsgraph = bpy.context.evaluated_depsgraph_get()
        scene_sync = sync.SceneSync(depsgraph)
        source = scene_sync._read(self.obj.evaluated_get(depsgraph), depsgraph)
        cloud = scene_sync._recover(self.obj, source)
        np.testing.assert_allclose(cloud["sh"][:, 1:, :].std(), 2.0 * source.attributes["sh_local"][:, 1:, :].std(),
                                   rtol=1e-5)
        self.assertIsNotNone(polygon_mesh and native)


def covariances_and_colors(cloud, directions):
    return st.covariances(cloud), st.sh_colors(cloud["sh"], directions)


class ExactApplyTransform(unittest.TestCase):
    def setUp(self):
        st.reset_scene()
        self.obj = st.import_file(UNICORN)
        rng = np.random.default_rng(5)
        directions = rng.normal(size=(len(self.obj.data.polygons), 3))
        self.directions = directions / np.linalg.norm(directions, axis=1, keepdims=True)

    def assert_same_gaussians(self, actual, expected, tolerance):
        np.testing.assert_allclose(actual["positions"], expected["positions"], atol=tolerance * 10)
        cov_a, col_a = covariances_and_colors(actual, self.directions)
        cov_e, col_e = covariances_and_colors(expected, self.directions)
        errors = st.relative_errors(cov_a, cov_e)
        self.assertLess(np.max(errors), tolerance, f"covariance off by up to {np.max(errors):.3g}")
        np.testing.assert_allclose(col_a, col_e, atol=tolerance * 10)
        thickness_a = np.min(actual["scales"], axis=1) / np.sqrt(np.prod(np.sort(actual["scales"])[:, 1:], axis=1))
        thickness_e = np.min(expected["scales"], axis=1) / np.sqrt(np.prod(np.sort(expected["scales"])[:, 1:], axis=1))
        np.testing.assert_allclose(thickness_a, thickness_e, rtol=tolerance * 10, atol=1e-7)

    def test_non_uniform_apply_scale_and_rotation(self):
        self.obj.scale = (1.0, 2.0, 0.7)
        self.obj.rotation_euler = Euler((0.4, -0.3, 0.9))
        self.obj.location = (0.5, -1.0, 2.0)
        bpy.context.view_layer.update()
        reference = st.export_file("transform_on.ply")
        self.assertEqual(bpy.ops.object.raysplats_apply_transform(location=False, rotation=False, scale=True),
                         {"FINISHED"})
        self.assertEqual(tuple(self.obj.scale), (1.0, 1.0, 1.0))
        self.assert_same_gaussians(st.export_file("scale_applied.ply"), reference, 2e-4)
        self.assertEqual(bpy.ops.object.raysplats_apply_transform(location=True, rotation=True, scale=True),
                         {"FINISHED"})
        self.assertEqual(tuple(self.obj.matrix_basis), tuple(Matrix.Identity(4)))
        self.assert_same_gaussians(st.export_file("all_applied.ply"), reference, 2e-4)

    def test_blenders_own_apply_scale_changes_thickness(self):
        # What the exact operator exists for: Blender's Apply Scale moves the corners only.
        self.obj.scale = (1.0, 2.0, 1.0)
        bpy.context.view_layer.update()
        reference = st.export_file("scaled.ply")
        bpy.ops.object.transform_apply(location=False, rotation=False, scale=True)
        with self.assertRaises(AssertionError):
            self.assert_same_gaussians(st.export_file("blender_applied.ply"), reference, 2e-4)
        # ... and the export says so; the exact operator afterwards clears it.
        from raysplats.io import export_splats
        warnings = export_splats.export_gaussian_splats(bpy.context, st.tmp_file("warned.ply"))[1]["warnings"]
        self.assertEqual(len(warnings), 1)
        self.assertIn("Blender's Apply Transform moved only", warnings[0])
        bpy.ops.object.raysplats_apply_transform()
        self.assertEqual(export_splats.export_gaussian_splats(bpy.context, st.tmp_file("clear.ply"))[1]["warnings"], [])

    def test_blenders_own_apply_of_a_rotation_is_exact_and_not_reported(self):
        from raysplats.io import export_splats
        self.obj.rotation_euler = Euler((0.3, 0.4, 0.5))
        self.obj.scale = (2.0, 2.0, 2.0)
        bpy.context.view_layer.update()
        reference = st.export_file("rotated.ply")
        bpy.ops.object.transform_apply(location=False, rotation=True, scale=True)
        self.assert_same_gaussians(st.export_file("rotation_applied.ply"), reference, 2e-4)
        self.assertEqual(export_splats.export_gaussian_splats(bpy.context, st.tmp_file("quiet.ply"))[1]["warnings"], [])

    def test_sheared_world_matrix_baked(self):
        from raysplats.tools import exact_apply
        parent = bpy.data.objects.new("Stretch", None)
        bpy.context.scene.collection.objects.link(parent)
        parent.scale = (1.0, 2.5, 0.6)
        self.obj.parent = parent
        self.obj.rotation_euler = Euler((0.7, 0.2, -0.5))  # rotated inside a non-uniform scale: a shear
        bpy.context.view_layer.update()
        world = np.array(self.obj.matrix_world, dtype=np.float64)
        linear = world[:3, :3]
        self.assertGreater(abs(np.dot(linear[:, 0], linear[:, 1])), 0.1)  # the columns are not orthogonal
        reference = st.export_file("sheared.ply")
        exact_apply.bake_matrix_into_gaussians(self.obj, world)
        self.obj.parent = None
        self.obj.matrix_basis = Matrix.Identity(4)
        bpy.context.view_layer.update()
        self.assert_same_gaussians(st.export_file("shear_baked.ply"), reference, 2e-4)


class TopologyWarnings(unittest.TestCase):
    def test_decimate_is_named_once_in_export_and_render(self):
        from raysplats.io import export_mesh, export_splats
        from raysplats.engine import sync
        st.reset_scene()
        obj = st.import_file(DONUT, max_count=2000)
        obj.modifiers.new("Fewer", "DECIMATE")
        obj.modifiers.new("Bend", "SIMPLE_DEFORM")  # a deformation: exact, not reported
        _, stats, _ = export_splats.export_gaussian_splats(bpy.context, st.tmp_file("decimated.ply"))
        self.assertEqual(len(stats["warnings"]), 1)
        self.assertIn("'Fewer' (Decimate)", stats["warnings"][0])
        mesh_stats = export_mesh.export_mesh_file(bpy.context, st.tmp_file("decimated.glb"))
        self.assertEqual(sum("'Fewer'" in w for w in mesh_stats["warnings"]), 1)
        warnings = []
        sync.build_render_scene(bpy.context.evaluated_depsgraph_get(), warn=warnings.append)
        self.assertEqual(sum("'Fewer' (Decimate)" in w for w in warnings), 1)
        obj.modifiers["Fewer"].show_viewport = False
        self.assertEqual(export_splats.export_gaussian_splats(bpy.context, st.tmp_file("plain.ply"))[1]["warnings"], [])


class Dialogs(unittest.TestCase):
    def test_several_files_at_once(self):
        st.reset_scene()
        result = bpy.ops.import_scene.gaussian_splats(directory=st.DATA_DIR,
                                                      files=[{"name": DONUT}, {"name": "small.splat"}])
        self.assertEqual(result, {"FINISHED"})
        objects = sorted(bpy.context.scene.objects, key=lambda obj: obj.name)
        self.assertEqual([obj.name for obj in objects], ["donut_sh0", "small"])
        # One polygon per visible Gaussian (donut_sh0 has 1,518 below 1/255; small.splat none).
        self.assertEqual(len(objects[0].data.polygons), len(file_gaussians(DONUT)["opacity"]))
        self.assertEqual(len(objects[0].data.polygons), len(read_ply(DONUT)["x"]) - 1518)
        self.assertEqual(len(objects[1].data.polygons), 728448 // 32)  # .splat: 32-byte records
        self.assertTrue(all(obj.select_get() for obj in objects))
        self.assertEqual(bpy.context.view_layer.objects.active.name, "small")

    def test_add_menu_and_format_extensions(self):
        from raysplats.io import export_mesh, format_table, import_splats
        self.assertIn(import_splats.menu_add, bpy.types.VIEW3D_MT_add._dyn_ui_initialize())
        self.assertEqual(export_mesh.with_extension("/a/scene.glb", ".obj", export_mesh.MESH_EXTENSIONS),
                         "/a/scene.obj")
        self.assertEqual(export_mesh.with_extension("/a/scene.v2", ".ply", export_mesh.MESH_EXTENSIONS),
                         "/a/scene.v2.ply")
        # A two-dot splat extension is replaced whole, both ways (by the core's endings); a read-only one is kept.
        self.assertEqual(format_table.with_splat_extension("/a/scene.compressed.ply", ".spz"), "/a/scene.spz")
        self.assertEqual(format_table.with_splat_extension("/a/scene.ply", ".compressed.ply"),
                         "/a/scene.compressed.ply")
        self.assertEqual(format_table.with_splat_extension("/a/Scene.SPZ", ".ply"), "/a/Scene.ply")
        self.assertEqual(format_table.with_splat_extension("/a/scene.sog", ".ply"), "/a/scene.sog.ply")
        self.assertEqual(format_table.splat_format_of("/a/S.Compressed.PLY")["name"], "compressed_ply")
        self.assertEqual(format_table.splat_format_of("/a/s.ply")["name"], "ply")
        self.assertEqual(export_mesh.mesh_format_of("x.GLTF"), "GLTF")


class MirroredColour(unittest.TestCase):
    """A mirrored Gaussian shows its original's view-dependent colour seen through the mirror: c'(d) = c(P d)."""

    def setUp(self):
        st.reset_scene()
        self.obj = st.import_file(UNICORN)
        self.count = len(self.obj.data.polygons)
        self.reference = st.export_file("unmirrored.ply")
        rng = np.random.default_rng(2)
        d = rng.normal(size=(self.count, 3))
        self.directions = d / np.linalg.norm(d, axis=1, keepdims=True)
        # The export is in the file's axes, in which the object's (and the mesh's) X is still X.
        self.mirror = np.array([-1.0, 1.0, 1.0])

    def assert_mirrored(self, sh):
        expected = st.sh_colors(self.reference["sh"], self.directions * self.mirror)
        copied = st.sh_colors(self.reference["sh"], self.directions)
        actual = st.sh_colors(sh, self.directions)
        # An unmirrored copy is off by about 0.07 here; the reflection is exact to float precision.
        self.assertGreater(np.abs(copied - expected).max(), 0.03)
        np.testing.assert_allclose(actual, expected, atol=2e-5)

    def test_mirror_modifier(self):
        modifier = self.obj.modifiers.new("Mirror", "MIRROR")
        modifier.use_mirror_merge = False
        exported = st.export_file("mirrored.ply")
        self.assertEqual(len(exported["opacities"]), 2 * self.count)
        np.testing.assert_allclose(exported["positions"][self.count:], self.reference["positions"] * self.mirror,
                                   atol=1e-6)
        np.testing.assert_array_equal(exported["sh"][:self.count], self.reference["sh"])
        self.assert_mirrored(exported["sh"][self.count:])

    def test_negative_object_scale(self):
        self.obj.scale = (-1.0, 1.0, 1.0)
        bpy.context.view_layer.update()
        exported = st.export_file("negative_scale.ply")
        np.testing.assert_allclose(exported["positions"], self.reference["positions"] * self.mirror, atol=1e-6)
        self.assert_mirrored(exported["sh"])
