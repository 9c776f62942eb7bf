# The bindings' conversion layer, through the built module with the Python Blender embeds (no Blender needed):
# wrong input is an error with one wording, and the dicts take exactly the core's names.
#   python3 test_conversions.py DIRECTORY_OF_THE_MODULE
import os
import sys
import unittest

# The test command's reporting: skips counted and named, exit 77 (a skip for ctest) when every test skipped.
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scripts", "lib"))
import unittest_report  # noqa: E402

import numpy as np

sys.path.insert(0, sys.argv[1])
import _native  # noqa: E402


def gaussians(n=1, coeffs=1):
    rotations = np.zeros((n, 4), np.float32)
    rotations[:, 0] = 1
    return (np.zeros((n, 3), np.float32), rotations, np.full((n, 3), 0.1, np.float32), np.ones(n, np.float32),
            np.zeros((n, coeffs, 3), np.float32))


def scene():
    s = _native.RenderScene()
    s.add_material()
    s.add_gaussians(*gaussians())
    return s


CAMERA = {"matrix": np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 4], [0, 0, 0, 1]], np.float32)}


class Conversions(unittest.TestCase):
    def assert_error(self, message, call, *args, **kwargs):
        with self.assertRaises(_native.InvalidArgument) as raised:
            call(*args, **kwargs)
        self.assertEqual(str(raised.exception), message)

    def test_misspelt_render_setting_is_an_error(self):
        with self.assertRaises(ValueError) as raised:  # InvalidArgument is a ValueError
            _native.RenderJob(scene(), CAMERA, {"sample": 1000})
        self.assertTrue(str(raised.exception).startswith(
            "unknown render setting 'sample' (known: width, height, samples, max_bounces, seed, compositing,"),
            raised.exception)

    def test_settings_of_the_wrong_type_are_errors(self):
        self.assert_error("render setting 'samples' must be an integer (got 1.5)",
                          _native.RenderJob, scene(), CAMERA, {"samples": 1.5})
        self.assert_error("render setting 'transparent_background' must be true or false (got 1)",
                          _native.RenderJob, scene(), CAMERA, {"transparent_background": 1})
        self.assert_error("unknown compositing 'sorted' (known: SORTED, STOCHASTIC)",
                          _native.RenderJob, scene(), CAMERA, {"compositing": "sorted"})
        self.assert_error("render settings: samples per pixel must be in 1 .. 1048576 (got 0)",
                          _native.RenderJob, scene(), CAMERA, {"samples": 0})

    def test_camera_names(self):
        self.assert_error("unknown camera model 'PERSPECTIVE' (known: PERSP, ORTHO, EQUIRECTANGULAR, "
                          "FISHEYE_EQUIDISTANT, FISHEYE_EQUISOLID)",
                          _native.RenderJob, scene(), dict(CAMERA, type="PERSPECTIVE"), {})
        with self.assertRaises(_native.InvalidArgument) as raised:
            _native.RenderJob(scene(), dict(CAMERA, fov=3.0), {})
        self.assertIn("unknown camera parameter 'fov' (known: type, matrix, lens,", str(raised.exception))
        self.assert_error("array 'matrix' has shape (3,3) but (4,4) was expected",
                          _native.RenderJob, scene(), dict(CAMERA, matrix=np.eye(3)), {})

    def test_dicts_reach_the_render(self):
        settings = {"width": 7, "height": 5, "samples": np.int64(1), "seed": 3, "compositing": "STOCHASTIC",
                    "transmittance_threshold": np.float32(0.01), "jitter": np.bool_(False)}
        camera = dict(CAMERA, type="ORTHO", ortho_scale=2, lens=35.0, shift_x=np.float64(0.1))
        film = _native.RenderJob(scene(), camera, settings).result()
        self.assertEqual(film["rgba"].shape, (5, 7, 4))
        self.assertFalse(film["cancelled"])

    def test_one_shape_wording_for_every_array(self):
        bad = list(gaussians(5))
        bad[0] = np.zeros((5, 2), np.float32)
        expected = "array 'positions' has shape (5,2) but (N,3) was expected"
        self.assert_error(expected, scene().add_gaussians, *bad)
        self.assert_error(expected, _native.write_splats, "/nonexistent/x.ply", *bad)
        self.assert_error(expected, _native.gaussians_to_polygons, *bad)
        self.assert_error(expected, _native.MeshExportScene().add_splats, "name", *bad)
        self.assert_error("array 'rotations' has shape (4,4) but (5,4) was expected", scene().add_gaussians,
                          *gaussians(5)[:1], np.zeros((4, 4), np.float32), *gaussians(5)[2:])
        self.assert_error("array 'sh' has 2 SH coefficients per channel but 1, 4, 9 or 16 were expected",
                          scene().add_gaussians, *gaussians(2, coeffs=2))
        self.assert_error("array 'triangles' has shape (4) but (N,3) was expected", scene().add_mesh,
                          np.zeros((3, 3), np.float32), np.zeros(4, np.uint32))
        self.assert_error("array 'current' has shape (2,3) but (2,4) (the shape of 'previous') was expected",
                          _native.rows_that_differ, np.zeros((2, 4), np.float32), np.zeros((2, 3), np.float32))

    def test_colours(self):
        s = scene()
        s.add_material(base_color=(1.0, 0.5, 0.25, 1.0))  # Blender's RGBA: alpha ignored
        with self.assertRaises(_native.InvalidArgument) as raised:
            s.add_material(base_color=(1.0, 0.5))
        self.assertIn("'base_color' must have 3 components", str(raised.exception))
        self.assert_error("unknown light type 'AREA' (known: POINT, SUN, SPOT, AREA_RECTANGLE, AREA_DISK)",
                          s.add_light, "AREA", (1, 1, 1), 10.0, np.eye(4))

    def test_a_rendering_scene_refuses_changes(self):
        s = scene()
        job = _native.RenderJob(s, CAMERA, {"width": 256, "height": 256, "samples": 100000})
        try:
            with self.assertRaises(_native.Error) as raised:
                s.update_gaussians(0, *gaussians())
            self.assertIn("the scene is being rendered", str(raised.exception))
            with self.assertRaises(_native.Error):
                s.add_material()
        finally:
            job.cancel()
        self.assertTrue(job.result()["cancelled"])
        s.update_gaussians(0, *gaussians())  # idle again

    def test_vocabularies(self):
        formats = {f["name"]: f for f in _native.splat_formats()}
        self.assertLessEqual({"ply", "splat", "spz", "gltf", "compressed_ply", "sog"}, set(formats))
        self.assertEqual(formats["gltf"]["extensions"], [".glb", ".gltf"])
        self.assertEqual(formats["compressed_ply"]["extensions"], [".compressed.ply"])
        self.assertFalse(formats["sog"]["writable"])
        # glTF's +Y up is its specification's, not a habit: the import's automatic up axis takes it at its word.
        self.assertTrue(formats["gltf"]["up_axis_by_specification"])
        self.assertFalse(formats["ply"]["up_axis_by_specification"])
        self.assertEqual(formats["spz"]["extensions"], [".spz"])
        self.assertEqual(formats["sog"]["extensions"], [".sog", "meta.json"])
        self.assertEqual([name for name, f in sorted(formats.items()) if not f["writable"]], ["gltf", "sog"])
        self.assertEqual(formats["spz"]["up_axis"], "-Y")  # read in the core's RDF, like .ply
        # The file-name rule, bound: the longest ending wins, in any case; the ending is the path's own characters.
        self.assertEqual(_native.match_splat_format("/a/S.Compressed.PLY"), {"name": "compressed_ply",
                                                                             "ending": ".Compressed.PLY"})
        self.assertEqual(_native.match_splat_format("/a/compressed.ply"), {"name": "ply", "ending": ".ply"})
        self.assertEqual(_native.match_splat_format("/a/meta.json")["name"], "sog")
        self.assertIsNone(_native.match_splat_format("/a/meta.json", writable_only=True))
        self.assertIsNone(_native.match_splat_format("/a/scene.obj"))
        self.assertIn(".compressed.ply", _native.write_splats.__doc__)
        self.assertNotIn(".sog", _native.write_splats.__doc__)
        self.assertIn("meta.json", _native.read_splats.__doc__)
        self.assertIn("FISHEYE_EQUISOLID", [m["name"] for m in _native.camera_models()])
        settings = {s["name"]: s for s in _native.render_settings()}
        self.assertEqual(settings["samples"]["type"], "int")
        self.assertEqual(settings["compositing"]["choices"], ["SORTED", "STOCHASTIC"])
        self.assertIn("fisheye_fov", [p["name"] for p in _native.camera_parameters()])


if __name__ == "__main__":
    unittest_report.main()
