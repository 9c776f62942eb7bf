# `raysplats render` reads the core's vocabulary: render settings and camera parameters by the names the add-on
# uses, angles in radians, and unknown names are errors that list the known ones.
#   python3 test_render_command.py RAYSPLATS_EXECUTABLE SPLAT_FILE TMP_DIR
import json
import os
import subprocess
import sys
import unittest

TOOL, SPLATS, TMP = sys.argv[1:4]


def render(scene, *options):
    path = os.path.join(TMP, "scene.json")
    with open(path, "w") as f:
        json.dump(dict(scene, splats={"file": SPLATS}), f)
    output = os.path.join(TMP, "render.pfm")
    if os.path.exists(output):
        os.remove(output)
    run = subprocess.run([TOOL, "render", "--scene", path, "-o", output, *options], capture_output=True, text=True)
    image = open(output, "rb").read() if run.returncode == 0 else None
    return run, image


CAMERA = {"position": [0, 0, -4], "target": [0, 0, 0], "up": [0, -1, 0]}
SMALL = {"width": 24, "height": 16, "samples": 1}


class RenderCommandVocabulary(unittest.TestCase):
    def test_core_names_render(self):
        run, image = render({"camera": dict(CAMERA, type="FISHEYE_EQUIDISTANT", fisheye_fov=3.0),
                             "render": dict(SMALL, max_bounces=1, compositing="STOCHASTIC", gaussian_mode="FLAT",
                                            transmittance_threshold=0.01)})
        self.assertEqual(run.returncode, 0, run.stderr)
        self.assertTrue(image.startswith(b"PF\n24 16\n"), image[:16])
        self.assertIn("(24x16, 1 spp", run.stdout)

    def test_misspelt_render_setting_is_an_error(self):
        run, _ = render({"camera": CAMERA, "render": dict(SMALL, spp=4)})
        self.assertEqual(run.returncode, 1)
        self.assertIn("unknown render setting 'spp' (known: width, height, samples, max_bounces,", run.stderr)

    def test_old_camera_spelling_is_an_error(self):
        run, _ = render({"camera": dict(CAMERA, type="perspective"), "render": SMALL})
        self.assertIn("unknown camera model 'perspective' (known: PERSP, ORTHO, EQUIRECTANGULAR,", run.stderr)
        run, _ = render({"camera": dict(CAMERA, fov=180), "render": SMALL})
        self.assertIn("unknown camera parameter 'fov' (known: type, matrix,", run.stderr)
        run, _ = render({"camera": dict(CAMERA, lens="long"), "render": SMALL})
        self.assertIn("camera parameter 'lens' must be a number (got 'long')", run.stderr)

    def test_command_line_options_are_the_settings_names(self):
        run, image = render({"camera": CAMERA, "render": SMALL}, "--samples", "2", "--max-bounces", "0",
                            "--no-jitter", "--compositing", "SORTED", "--width", "12")
        self.assertEqual(run.returncode, 0, run.stderr)
        self.assertIn("(12x16, 2 spp", run.stdout)
        run, _ = render({"camera": CAMERA, "render": SMALL}, "--spp", "2")
        self.assertIn("unknown option --spp", run.stderr)

    def test_compositing_and_gaussian_mode_options_by_name_in_any_case(self):
        # The command line takes --compositing sorted|stochastic and a flat|volumetric mode: both are the settings
        # table's names (--compositing, --gaussian-mode), accepted in any case on the command line.
        scene = {"camera": CAMERA, "render": SMALL}
        default, image_default = render(scene)
        upper, image_upper = render(scene, "--compositing", "STOCHASTIC", "--gaussian-mode", "VOLUMETRIC")
        lower, image_lower = render(scene, "--compositing", "stochastic", "--gaussian-mode", "volumetric")
        for run in (default, upper, lower):
            self.assertEqual(run.returncode, 0, run.stderr)
        self.assertEqual(image_upper, image_lower)      # the same settings, whatever the case
        self.assertNotEqual(image_upper, image_default)  # and they change the render (default SORTED, FLAT)
        _, image_volumetric = render(scene, "--gaussian-mode", "Volumetric")
        self.assertNotEqual(image_volumetric, image_default)
        run, _ = render(scene, "--compositing", "weighted")
        self.assertEqual(run.returncode, 1)
        self.assertIn("'weighted'", run.stderr)
        self.assertIn("SORTED, STOCHASTIC", run.stderr)

    def test_fisheye_angle_is_radians(self):
        # An equidistant fisheye of 2π rad sees all around; of 2π "degrees" (0.11 rad) it sees a speck. Radians:
        # the two differ; were the value taken as degrees, the 6.28 image would be nearly the 0.11 one.
        images = [render({"camera": dict(CAMERA, type="FISHEYE_EQUIDISTANT", fisheye_fov=fov), "render": SMALL})[1]
                  for fov in (6.28, 0.11, 6.28)]
        self.assertEqual(images[0], images[2])
        self.assertNotEqual(images[0], images[1])


if __name__ == "__main__":
    unittest.main(argv=sys.argv[:1])
