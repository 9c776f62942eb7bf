# Import every real scene, export it untouched, and check that the Gaussians come back unchanged.
import os
import unittest

import bpy
import numpy as np

import splat_testing as st
from raysplats.objects import axes

# (file, splats, SH degree) as documented in shared/data/README.md, and how many of the splats have an opacity
# below 1/255 (invisible: the import skips them, docs/design.md §5).
REAL_FILES = [
    ("small_sh3_inria.ply", 9080, 3, 0),
    ("donut_sh0.ply", 45624, 0, 1518),
    ("unicorn_sh3_reordered.ply", 49602, 3, 39),
    ("small.splat", 22764, 0, 0),
    ("biker_v4.spz", 152746, 0, 0),
    ("guitar_supersplat.compressed.ply", 90854, 0, 0),
    # The same scene as unicorn_sh3_reordered.ply, read from its SOG, whose 8-bit opacities read as byte / 255 exactly:
    # the 7 of byte 0 are invisible; those of byte 1 sit on the 1/255 threshold, and the .ply's logits (float32)
    # round 32 of them below it.
    ("unicorn_sh3.sog", 49602, 3, 7),
]


# The real files whose up the automatic up axis finds in their data (native/tests/up_axis_test.cpp); the others have no
# clear ground in their data and keep the -Y convention.
FOUND_UP_AXES = {"donut_sh0.ply": "Z", "unicorn_sh3_reordered.ply": "-Y"}


def visible_gaussians(cloud):
    """The Gaussians of a file that an import keeps: opacity a with a·255 > 1 (something of them is visible)."""
    keep = cloud["opacities"].astype(np.float64) * 255.0 > 1.0
    return {key: (value[keep] if isinstance(value, np.ndarray) else value) for key, value in cloud.items()}


class ImportExport(unittest.TestCase):
    def setUp(self):
        st.reset_scene()

    def test_every_real_file_imports_as_one_polygon_per_gaussian(self):
        for name, count, degree, invisible in REAL_FILES:
            with self.subTest(name=name):
                st.reset_scene()
                obj = st.import_file(name)
                mesh = obj.data
                cloud = st.native().read_splats(st.data_file(name))
                self.assertEqual(len(cloud["opacities"]), count)
                self.assertEqual(int((cloud["opacities"].astype(np.float64) * 255.0 <= 1.0).sum()), invisible)
                cloud = visible_gaussians(cloud)
                self.assertEqual(len(mesh.polygons), count - invisible)
                self.assertEqual(len(mesh.vertices), 8 * (count - invisible))
                self.assertTrue(obj.raysplats.is_gaussian)
                self.assertEqual(obj.name, name[:name.index(".")])  # the whole extension goes (".compressed.ply")
                self.assertEqual(obj.raysplats.sh_degree, degree)
                # Automatic up axis: found from the data where it shows a ground (the donut, made in Blender, is Z up),
                # else -Y up (COLMAP) for every format (the SPZ reader converts from RUB).
                expected_up = FOUND_UP_AXES.get(name, "-Y")
                self.assertEqual(obj.raysplats.up_axis, expected_up)
                np.testing.assert_allclose(tuple(obj.rotation_euler), axes.object_rotation_euler(expected_up), atol=1e-6)
                for k in range((degree + 1) ** 2):
                    self.assertIn(f"gs_sh_{k}", mesh.attributes)
                self.assertIn("gs_color", mesh.color_attributes)
                self.assertIn("gs_uv", mesh.uv_layers)
                self.assertEqual(mesh.materials[0].name, "RaySplats Gaussian")
                # Colour attribute alpha is the opacity of the face's Gaussian (a byte colour attribute: to 1/510).
                self.assertEqual(mesh.color_attributes["gs_color"].data_type, "BYTE_COLOR")
                colors = np.empty(len(mesh.loops) * 4, dtype=np.float32)
                mesh.color_attributes["gs_color"].data.foreach_get("color", colors)
                k = obj.raysplats.vertices_per_polygon
                np.testing.assert_allclose(colors.reshape(-1, k, 4)[:, 0, 3], cloud["opacities"],
                                           atol=0.5 / 255 + 1e-6)

    def test_untouched_scene_exports_the_gaussians_it_imported(self):
        for name, _, _, _ in REAL_FILES:
            for extension in (".ply",):
                with self.subTest(name=name):
                    st.reset_scene()
                    st.import_file(name)
                    original = visible_gaussians(st.native().read_splats(st.data_file(name)))
                    exported = st.export_file("untouched" + extension)
                    self.assertEqual(len(exported["opacities"]), len(original["opacities"]))
                    cov_err = st.relative_errors(st.covariances(exported), st.covariances(original))
                    self.assertLess(cov_err.max(), 1e-5, f"{name}: covariance")
                    np.testing.assert_allclose(exported["positions"], original["positions"], rtol=1e-5, atol=1e-6)
                    np.testing.assert_allclose(exported["opacities"], original["opacities"], rtol=1e-5, atol=1e-7)
                    np.testing.assert_allclose(exported["sh"], original["sh"], rtol=1e-5, atol=1e-6)

    def test_untouched_import_and_export_in_the_same_format_is_exact(self):
        # .splat: the file comes back byte for byte (before: rotation bytes re-quantised). .ply and .spz: every value
        # reads back exactly as the source's (their files also hold normals / zstd frames we write our own way),
        # except SH bands 1-3, which the mesh keeps in each face's frame (docs/design.md §5): rotated there and back,
        # they differ by float rounding (at most 1.5e-8 on small_sh3_inria.ply).
        # .compressed.ply: every value, and every byte after the header (whose comment names the writer).
        for name in ("small.splat", "small_sh3_inria.ply", "donut_sh0.ply", "biker_v4.spz",
                     "guitar_supersplat.compressed.ply"):
            with self.subTest(name=name):
                st.reset_scene()
                st.import_file(name)
                extension = ".compressed.ply" if name.endswith(".compressed.ply") else os.path.splitext(name)[1]
                exported = st.export_file("untouched_exact" + extension)
                # Gaussians below 1/255 are not imported (they get no polygon); every other one comes back exactly.
                original = visible_gaussians(st.native().read_splats(st.data_file(name)))
                for key in ("positions", "rotations", "scales", "opacities"):
                    np.testing.assert_array_equal(exported[key], original[key], err_msg=f"{name}: {key}")
                np.testing.assert_array_equal(exported["sh"][:, 0], original["sh"][:, 0], err_msg=f"{name}: SH DC")
                np.testing.assert_allclose(exported["sh"], original["sh"], rtol=0, atol=3e-8, err_msg=f"{name}: SH")
                if extension == ".splat":
                    with open(st.data_file(name), "rb") as a, open(st.tmp_file("untouched_exact.splat"), "rb") as b:
                        self.assertTrue(a.read() == b.read(), "the .splat file changed")
                if extension == ".compressed.ply":
                    with open(st.data_file(name), "rb") as a, open(st.tmp_file("untouched_exact" + extension), "rb") as b:
                        x, y = a.read(), b.read()
                    self.assertTrue(x[x.index(b"end_header\n"):] == y[y.index(b"end_header\n"):],
                                    "the compressed PLY's data changed")

    def test_export_to_splat_and_spz_round_trips_within_quantisation(self):
        st.import_file("small_sh3_inria.ply")
        original = st.native().read_splats(st.data_file("small_sh3_inria.ply"))
        for extension, position_tol in ((".splat", 1e-6), (".spz", 2e-3)):
            with self.subTest(extension=extension):
                exported = st.export_file("roundtrip" + extension)
                self.assertEqual(len(exported["opacities"]), 9080)
                np.testing.assert_allclose(exported["positions"], original["positions"], atol=position_tol)
        # The Format drop-down's compressed PLY: SuperSplat's layout, splats in Morton order (so compared as sorted
        # coordinates), positions within half an 11-10-11-bit step of chunks that in this sparse scene span up to
        # 1.6 k units (0.4), opacity within half an 8-bit step.
        exported = st.export_file("roundtrip.compressed.ply", export_format="COMPRESSED_PLY")
        self.assertEqual(st.native().probe_splat_file(st.tmp_file("roundtrip.compressed.ply"))["format"], "compressed_ply")
        self.assertEqual(len(exported["opacities"]), 9080)
        for axis in range(3):
            np.testing.assert_allclose(np.sort(exported["positions"][:, axis]), np.sort(original["positions"][:, axis]),
                                       atol=0.4)
        np.testing.assert_allclose(np.sort(exported["opacities"]), np.sort(original["opacities"]), atol=1 / 510 + 1e-6)

    def test_import_options(self):
        obj = st.import_file("small_sh3_inria.ply", vertices_per_polygon=5, radius=2.0, up_axis="Z",
                             max_count=1000)
        self.assertEqual(len(obj.data.polygons), 1000)
        self.assertEqual(len(obj.data.vertices), 5000)
        self.assertEqual(obj.raysplats.vertices_per_polygon, 5)
        self.assertAlmostEqual(obj.rotation_euler.x, 0.0)
        # The 1000 kept are the core's uniform choice over the file (the same every time, as read_splats makes it).
        original = st.native().read_splats(st.data_file("small_sh3_inria.ply"), max_count=1000)
        exported = st.export_file("options.ply")
        cov_err = st.relative_errors(st.covariances(exported), st.covariances(original))
        self.assertLess(cov_err.max(), 1e-5)
        st.reset_scene()
        obj = st.import_file("small_sh3_inria.ply", min_opacity=0.5)
        every = st.native().read_splats(st.data_file("small_sh3_inria.ply"))
        self.assertEqual(len(obj.data.polygons), int((every["opacities"] >= 0.5).sum()))

    def test_bad_file_reports_an_error_and_adds_nothing(self):
        path = st.tmp_file("truncated.ply")
        with open(st.data_file("small_sh3_inria.ply"), "rb") as source, open(path, "wb") as bad:
            bad.write(source.read(5000))
        objects_before = len(bpy.data.objects)
        with self.assertRaises(RuntimeError) as raised:
            bpy.ops.import_scene.gaussian_splats(filepath=path)
        self.assertIn("truncated.ply", str(raised.exception))
        self.assertEqual(len(bpy.data.objects), objects_before)
        self.assertEqual(len(bpy.data.meshes), 0)

    def test_export_without_gaussians_is_a_clear_error(self):
        bpy.ops.mesh.primitive_cube_add()
        with self.assertRaises(RuntimeError) as raised:
            bpy.ops.export_scene.gaussian_splats(filepath=st.tmp_file("nothing.ply"))
        self.assertIn("Nothing to export", str(raised.exception))

    def test_unknown_extension_is_a_clear_error(self):
        st.import_file("small.splat")
        with self.assertRaises(RuntimeError) as raised:
            bpy.ops.export_scene.gaussian_splats(filepath=st.tmp_file("scene.xyz"))
        self.assertIn("unknown splat format", str(raised.exception))
        # SOG is read, not written: export says so instead of writing something else under that name.
        with self.assertRaises(RuntimeError) as raised:
            bpy.ops.export_scene.gaussian_splats(filepath=st.tmp_file("scene.sog"))
        self.assertIn("SOG is read only", str(raised.exception))
        self.assertFalse(os.path.exists(st.tmp_file("scene.sog")))
