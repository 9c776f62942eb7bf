"""The renderer against what splat viewers show: the real scenes of ../shared/data under 100 k Gaussians
rendered by RaySplats (through the built module) and by the independent numpy 3DGS EWA rasterizer
(ewa_rasterizer.py), from two views each, compared as a display shows them (sRGB, clamped). Volumetric Gaussians in
the default DISPLAY blend space must reach MIN_PSNR dB on every view; LINEAR blend space (the engine's compositing
before Display existed) must fall short of it on the hazy unicorn, so the test tells the two apart.

    python3 test_viewer_agreement.py MODULE_DIR DATA_DIR [--table | --attribution [SCENE...]]

--table prints PSNR per scene, view, Gaussian mode and blend space (docs/validation.md has them), --attribution
the split below (slow: ray_reference.py is dense numpy); neither asserts anything. The renderer draws its camera rays
through the pixel centres with one sample, black world, compositing stopped at T < 1e-4 and Gaussians cut near the
camera (at 1 % of its distance to the scene), the rasterizer's conventions. It also shares the rasterizer's alpha
cap 0.99, its 1/255 cut and its SH colour clamp at 0 (not above 1): the engine agrees with ray_reference.py's numpy
model of it, which has those, to 100 dB on small.splat (test_engine_is_the_exact_ray_model checks >= 50 dB).

Measured (640 x 480, volumetric, DISPLAY; PSNR in dB against the EWA rasterizer):

    scene                             front   side   MIN_PSNR
    small_sh3_inria.ply               30.9    32.6   30
    donut_sh0.ply                     36.4    32.6   30
    unicorn_sh3_reordered.ply         33.1    33.6   30
    small.splat                       26.1    26.5   25
    guitar_supersplat.compressed.ply  35.9    26.3   25

What differs is not compositing (LINEAR is 19-21 dB on small.splat) but how a Gaussian is drawn, and small.splat and
guitar's side view are below 30 dB for that reason. --attribution (ray_reference.py) draws each scene with the exact
maximum response of the 3D Gaussian along each pixel's ray, as the engine does, but with the rasterizer's one global
sort by centre depth, and splits the difference in two: "footprint" (EWA vs exact ray response, both in centre
order) and "order" (centre order vs the engine's per-ray order of the response maxima, both with the exact response):

    scene / view          engine vs EWA   footprint   order
    small.splat front          26.1          27.1      34.6
    small.splat side           26.5          31.5      28.8
    guitar side                26.3          28.3      30.5
    small_sh3_inria front      30.9          31.7      40.3
    small_sh3_inria side       32.6          36.1      35.9
    unicorn front              33.1          36.6      35.8
    unicorn side               33.6          37.4      36.1

(measured the other way round, EWA footprint with the per-ray order, small.splat gives footprint 26.8 / 31.3 and
order 33.9 / 29.5, front / side). Both parts are what ray tracing 3D Gaussians is, against splatting them:
- Footprint. EWA replaces each Gaussian by a 2D Gaussian through the perspective Jacobian at its centre, plus
  0.3 px^2. small.splat's Gaussians are huge for their distance (standard deviation s_max / depth: median 0.035,
  99th percentile 0.18; a third of them above 0.05; the unicorn's 99th percentile is 0.05), where the affine
  projection is not the 3D Gaussian any more: drawn from its Gaussians with s_max / depth <= 0.01, 0.02, 0.05, 0.1
  alone (which also thins their overlap, so the order part shrinks too), small.splat agrees to 45.5, 44.3, 36.0, 31.8 dB (front; side 47.5, 45.5, 39.4, 30.1). Neither the
  Jacobian's 1.3 tan(fov / 2) clamp (EWA without it against the engine: 26.3 / 26.5 dB) nor the dilation (26.1 /
  26.5 dB) is it. (small_sh3_inria, an earlier training of the same capture, has Gaussians as large,
  footprint 31.7 dB: 9 k of median opacity 0.06 against small.splat's 23 k of 0.11.) guitar's Gaussians are small
  (99th percentile 0.03) but many are thin (largest / middle axis: median 5.4, 90th percentile 23), and the side
  view sees the guitar's face obliquely (the front view is at 35.9 dB): there the 0.3 px^2 dilation (which widens thin Gaussians without lowering their opacity) is the whole footprint difference
  (EWA without it against the exact ray response: 53.9 dB; the engine against EWA without it: 30.3 dB). Dilation is
  screen space, a rasterizer's anti-aliasing: the engine's pixel filter with 32 samples does not reproduce it
  (Blackman-Harris 1.5 px: 26.7 dB; a Gaussian of 0.3 px^2 variance: 26.8 dB).
- Order. Where large or elongated semi-transparent Gaussians overlap, the depth of a Gaussian's response maximum along
  a ray is not its centre's depth, and the two orders composite the same Gaussians differently (small.splat's
  Gaussians overlap most: median opacity 0.11 over a whole frame of them). It is the sort key more than sorting per
  ray: per ray but keyed by the depth of the centre's projection onto the ray, small.splat's side view is 37.3 dB from
  the global centre sort, and 30.4 dB from EWA (ray_reference order "ray_centre").
- The rest is the same or immaterial: the engine stops after the Gaussian that takes T below 1e-4, the rasterizer
  before it (the two rules, both EWA, on the donut, the most opaque scene: 73 dB apart); the engine cuts each
  Gaussian at Mahalanobis radius 3, EWA at a square of 3 sqrt(lambda_max) pixels (EWA with the engine's cut: 50.6 /
  43.5 dB from EWA on small.splat, 58.5 on guitar's side); no Gaussian centre of these
  views lies nearer than the near cut, and culling centres (the rasterizer) or response maxima (the engine) there
  together with the two stop rules changes small.splat by 89.1 / 85.5 dB (exact ray response, centre order); the .splat readers (engine and
  reference) give the same values (rotations to float rounding), and the test hands the reference's to both.
The views are the scenes' fixed two (front, side), not chosen to pass; the thresholds of small.splat and guitar are
set below their figures with this explanation.

Camera-ray splatting (RenderSettings::camera_ray_splatting: off in the core, on in the add-on) is the answer to both parts: camera rays
draw the Gaussians with the rasterizer's model (EWA footprint with the dilation, one sort by centre depth), so what is
left is float rounding and the stop rules (the engine composites the Gaussian that takes T below 1e-4, the rasterizer
stops before it). --table, 640 x 480, DISPLAY, dB against the EWA rasterizer, traced (the core's default) / splatted (the add-on's):

    scene                             front (traced / splatted)   side (traced / splatted)
    small_sh3_inria.ply               30.9 / 76.3                 32.6 / 80.0
    donut_sh0.ply                     36.4 / 70.5                 32.6 / 65.9
    unicorn_sh3_reordered.ply         33.1 / 72.1                 33.6 / 71.6
    small.splat                       26.1 / 67.7                 26.5 / 61.8
    guitar_supersplat.compressed.ply  35.9 / 75.4                 26.3 / 70.9

(volumetric; in flat mode the splatted figures are the same, as the footprint is the whole 3D Gaussian's in both modes,
while flat mode traced is 24.5-35.6 dB.)
"""
import functools
import math
import os
import sys
import unittest

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
# The test command's reporting: skips counted and named, exit 77 (a skip for ctest) when every test skipped.
sys.path.insert(0, os.path.join(HERE, "..", "..", "..", "scripts", "lib"))
import ewa_rasterizer as ewa  # noqa: E402
import ray_reference  # noqa: E402
import unittest_report  # noqa: E402

MODULE_DIR = sys.argv[1] if len(sys.argv) > 1 else None
DATA_DIR = sys.argv[2] if len(sys.argv) > 2 else None
TABLE = "--table" in sys.argv
ATTRIBUTION = "--attribution" in sys.argv
sys.argv[1:] = [a for a in sys.argv[3:] if a not in ("--table", "--attribution")]  # unittest's own arguments
if MODULE_DIR:
    sys.path.insert(0, MODULE_DIR)

# The real scenes of ../shared/data under 100 k Gaussians (all of them: the reference reads each format).
SCENES = ("small_sh3_inria.ply", "donut_sh0.ply", "unicorn_sh3_reordered.ply", "small.splat",
          "guitar_supersplat.compressed.ply")
# 640 x 480: at lower resolutions many Gaussians are smaller than a pixel, where the rasterizer's 0.3 px^2 dilation
# widens them and one ray per pixel point-samples them, which dominates the difference (at 160 x 120 the unicorn
# agrees to 22 dB in either blend space).
WIDTH, HEIGHT = 640, 480
LENS, SENSOR = 30.0, 36.0  # mm: horizontal field of view 61.9 degrees
# Volumetric, DISPLAY blend space, every view (the table in the docstring): small.splat (26.1-26.5 dB) and guitar
# (35.9 front, 26.3 side) are below 30 dB by what ray tracing 3D Gaussians is against EWA splatting (docstring).
MIN_PSNR = {"small_sh3_inria.ply": 30.0, "donut_sh0.ply": 30.0, "unicorn_sh3_reordered.ply": 30.0, "small.splat": 25.0,
            "guitar_supersplat.compressed.ply": 25.0}
# Azimuth and elevation (degrees) of the two views around each scene's median, at DISTANCE x its 10-90 % extent.
VIEWS = {"front": (0.0, 15.0), "side": (120.0, 35.0)}
# Camera-ray splatting (RenderSettings::camera_ray_splatting) draws camera rays' Gaussians with the rasterizer's model:
# what is left between them is float rounding and the two stop rules (62-80 dB, docstring), so 50 dB on every view
# (not the 25-30 dB of MIN_PSNR that tracing is held to) holds it to being the same model.
MIN_PSNR_SPLATTING = 50.0
DISTANCE = 1.3


def look_at(eye, target, up):
    """Blender camera matrix (camera to world; the camera looks down -Z, +Y up)."""
    f = target - eye
    f /= np.linalg.norm(f)
    r = np.cross(f, up)
    r /= np.linalg.norm(r)
    u = np.cross(r, f)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = r, u, -f, eye
    return m


def view_camera(splats, view):
    """The camera of `view`: Blender's matrix, and the OpenCV world-to-view matrix the rasterizer takes."""
    p = splats.positions.astype(np.float64)
    center = np.median(p, axis=0)
    extent = float(np.max(np.percentile(p, 90, axis=0) - np.percentile(p, 10, axis=0)))
    azimuth, elevation = (math.radians(a) for a in VIEWS[view])
    # The scenes are stored y down (COLMAP / 3DGS): up is -y; the orbit turns about it, starting at -z.
    direction = np.array([math.sin(azimuth) * math.cos(elevation), -math.sin(elevation),
                          -math.cos(azimuth) * math.cos(elevation)])
    camera_to_world = look_at(center + DISTANCE * extent * direction, center, np.array([0.0, -1.0, 0.0]))
    world_to_view = np.diag([1.0, -1.0, -1.0, 1.0]) @ np.linalg.inv(camera_to_world)
    return camera_to_world, world_to_view, 0.01 * DISTANCE * extent


def render_raysplats(native, splats, camera_to_world, near, gaussian_mode, blend_space, width=WIDTH, height=HEIGHT,
                     splatting=False, film=None):
    scene = native.RenderScene()
    scene.add_material()
    scene.add_gaussians(splats.positions, splats.rotations, splats.scales, splats.opacities, splats.sh)
    scene.set_world([0.0, 0.0, 0.0])
    scene.build(gaussian_mode)
    camera = {"type": "PERSP", "matrix": camera_to_world.astype(np.float32), "lens": LENS, "sensor_width": SENSOR,
              "sensor_fit": "HORIZONTAL", "clip_start": near, "clip_end": 1e6}
    settings = {"width": width, "height": height, "samples": 1, "jitter": False, "max_bounces": 0,
                "gaussian_mode": gaussian_mode, "blend_space": blend_space, "transmittance_threshold": 1e-4,
                "camera_ray_splatting": splatting}
    job = native.RenderJob(scene, camera, settings)
    while not job.wait(1.0):
        pass
    result = job.result()
    if film is not None:
        film.update(result)
    rgba = np.asarray(result["rgba"], np.float64).reshape(height, width, 4)
    return ewa.linear_to_srgb(rgba[..., :3])  # as Blender's Standard view transform shows the linear film


@functools.lru_cache(maxsize=None)
def scene_views(data_dir, name):
    """A scene's splats and, per view, its camera and the EWA rasterizer's image of it: computed once, as the tests
    below compare the engine's several settings with the same references."""
    splats = ewa.read_splats(os.path.join(data_dir, name))
    fx = WIDTH * LENS / SENSOR
    views = {}
    for view in VIEWS:
        camera_to_world, world_to_view, near = view_camera(splats, view)
        views[view] = (camera_to_world, near, ewa.rasterize(splats, world_to_view, fx, fx, WIDTH, HEIGHT, near=near))
    return splats, views


def measure(native, data_dir, modes=("VOLUMETRIC",), spaces=("DISPLAY", "LINEAR"), splattings=(False,)):
    """{(scene, view, mode, space, camera_ray_splatting): PSNR}."""
    results = {}
    for name in SCENES:
        splats, views = scene_views(data_dir, name)
        for view, (camera_to_world, near, reference) in views.items():
            for mode in modes:
                for space in spaces:
                    for splatting in splattings:
                        image = render_raysplats(native, splats, camera_to_world, near, mode, space,
                                                 splatting=splatting)
                        results[(name, view, mode, space, splatting)] = ewa.psnr(reference, image)
    return results


def attribution(native, data_dir, names):
    """{(scene, view): {figure: PSNR}} of the volumetric, DISPLAY blend space render, splitting its difference from
    the EWA rasterizer with ray_reference.py: "engine" the test's figure (engine vs EWA); "footprint" the exact
    ray response against the EWA footprint, both with the rasterizer's global sort by centre depth (EWA vs exact
    ray, centre order); "order" the per-ray order against that sort, both with the exact ray response (exact ray,
    centre order vs the engine); "model" the engine against ray_reference's numpy model of it (exact ray, per-ray
    order, the engine's near cut and stop: all that is left is rounding)."""
    results = {}
    fx = WIDTH * LENS / SENSOR
    for name in names:
        splats = ewa.read_splats(os.path.join(data_dir, name))
        for view in VIEWS:
            camera_to_world, world_to_view, near = view_camera(splats, view)
            reference = ewa.rasterize(splats, world_to_view, fx, fx, WIDTH, HEIGHT, near=near)
            engine = render_raysplats(native, splats, camera_to_world, near, "VOLUMETRIC", "DISPLAY")
            ray_centre = ray_reference.render(splats, world_to_view, fx, fx, WIDTH, HEIGHT, near=near, footprint="ray",
                                              order="centre", cull="centre", stop="before")
            model = ray_reference.render(splats, world_to_view, fx, fx, WIDTH, HEIGHT, near=near)
            results[(name, view)] = {"engine": ewa.psnr(reference, engine), "footprint": ewa.psnr(reference, ray_centre),
                                     "order": ewa.psnr(ray_centre, engine), "model": ewa.psnr(model, engine)}
    return results


class ReferenceRasterizer(unittest.TestCase):
    """The reference's own conventions, on cases with known answers (so that the comparison below rests on a
    rasterizer that is right)."""

    def test_one_gaussian_head_on(self):
        # An isotropic Gaussian of scale s at depth z straight ahead: a 2D Gaussian of variance (f s / z)^2 + 0.3 px^2
        # at the image centre, peak alpha = opacity.
        s, z, f = 0.05, 2.0, 100.0
        splats = ewa.Splats([[0, 0, z]], [[1, 0, 0, 0]], [[s, s, s]], [0.8], np.full((1, 1, 3), (0.7 - 0.5) / ewa.SH_C0))
        image = ewa.rasterize(splats, np.eye(4), f, f, 64, 64)
        var = (f * s / z) ** 2 + 0.3
        for px, py in ((32, 32), (35, 30), (40, 32)):
            dx, dy = px + 0.5 - 32.0, py + 0.5 - 32.0
            alpha = 0.8 * math.exp(-0.5 * (dx * dx + dy * dy) / var)
            self.assertAlmostEqual(image[py, px, 0], 0.7 * alpha if alpha >= 1 / 255 else 0.0, places=6)

    def test_front_to_back_in_display_space(self):
        # Two opaque-ish Gaussians, the nearer one (red) given second: sorting puts it first; C = a1 c1 + (1-a1) a2 c2.
        sh = np.zeros((2, 1, 3))
        sh[0, 0] = (np.array([0.0, 0.0, 1.0]) - 0.5) / ewa.SH_C0
        sh[1, 0] = (np.array([1.0, 0.0, 0.0]) - 0.5) / ewa.SH_C0
        splats = ewa.Splats([[0, 0, 3], [0, 0, 2]], [[1, 0, 0, 0]] * 2, [[0.5] * 3] * 2, [0.6, 0.5], sh)
        image = ewa.rasterize(splats, np.eye(4), 50.0, 50.0, 8, 8)
        red, blue = image[4, 4, 0], image[4, 4, 2]
        a1 = 0.5 * math.exp(-0.5 * 0.5 ** 2 * 2 / ((50 * 0.5 / 2) ** 2 + 0.3))
        self.assertAlmostEqual(red, a1, places=6)
        self.assertGreater(blue, 0.0)
        self.assertLess(blue, 0.6 * (1 - a1) + 1e-9)

    def test_sh_degree_one_sign_convention(self):
        # Reference computeColorFromSH: - C1 y sh1 + C1 z sh2 - C1 x sh3.
        sh = np.zeros((1, 4, 3))
        sh[0, 1] = 1.0
        self.assertAlmostEqual(ewa.sh_to_display(sh, np.array([[0.0, 1.0, 0.0]]))[0, 0], 0.5 - ewa.SH_C1)


@unittest.skipUnless(MODULE_DIR and DATA_DIR, "needs the module and data directories")
class ViewerAgreement(unittest.TestCase):
    def test_display_blend_space_matches_the_viewer(self):
        import _native
        results = measure(_native, DATA_DIR)
        for (name, view, mode, space, _), value in results.items():
            if space == "DISPLAY":
                self.assertGreaterEqual(value, MIN_PSNR[name], f"{name} {view} {mode}: {value:.2f} dB")
        # Linear compositing is the grey halo of haze and floaters that viewers never show: the hazy unicorn falls short
        # by several dB.
        for view in VIEWS:
            linear = results[("unicorn_sh3_reordered.ply", view, "VOLUMETRIC", "LINEAR", False)]
            display = results[("unicorn_sh3_reordered.ply", view, "VOLUMETRIC", "DISPLAY", False)]
            self.assertLess(linear, display - 3.0, f"unicorn {view}: linear {linear:.2f} dB, display {display:.2f} dB")

    def test_camera_ray_splatting_matches_the_viewer(self):
        # With camera-ray splatting every camera ray draws the Gaussians as the rasterizer does: every view of every
        # scene, the two that tracing leaves at 26 dB included, agrees to MIN_PSNR_SPLATTING (50 dB; the figures are
        # 62-80 dB, the docstring's table). Flat mode too (the add-on's default): the footprint is the whole 3D
        # Gaussian's in both modes.
        import _native
        results = measure(_native, DATA_DIR, modes=("VOLUMETRIC", "FLAT"), spaces=("DISPLAY",), splattings=(True,))
        for (name, view, mode, space, _), value in results.items():
            self.assertGreaterEqual(value, MIN_PSNR_SPLATTING, f"{name} {view} {mode} splatted: {value:.2f} dB")
        # It is the setting that does it: the render says it splatted, and without it small.splat is still traced.
        splats = ewa.read_splats(os.path.join(DATA_DIR, "small.splat"))
        camera_to_world, _, near = view_camera(splats, "front")
        for splatting in (False, True):
            film = {}
            render_raysplats(_native, splats, camera_to_world, near, "VOLUMETRIC", "DISPLAY", WIDTH // 4, HEIGHT // 4,
                             splatting=splatting, film=film)
            self.assertEqual(film["camera_ray_splatting"], splatting)

    def test_engine_is_the_exact_ray_model(self):
        # What the figures above measure is the difference between two models, not a defect of either: the engine
        # agrees with ray_reference.py's independent numpy model of a ray tracer (each pixel's ray, the exact maximum
        # response of each 3D Gaussian on it, composited in the order of those maxima) to rounding, on the scene of
        # the largest difference from EWA (small.splat: 26 dB). At 320 x 240 (the numpy model is slow).
        import _native
        splats = ewa.read_splats(os.path.join(DATA_DIR, "small.splat"))
        width, height = WIDTH // 2, HEIGHT // 2
        fx = width * LENS / SENSOR
        camera_to_world, world_to_view, near = view_camera(splats, "front")
        model = ray_reference.render(splats, world_to_view, fx, fx, width, height, near=near)
        engine = render_raysplats(_native, splats, camera_to_world, near, "VOLUMETRIC", "DISPLAY", width, height)
        self.assertGreaterEqual(ewa.psnr(model, engine), 50.0)


def print_table(module_dir, data_dir):
    sys.path.insert(0, module_dir)
    import _native
    results = measure(_native, data_dir, modes=("VOLUMETRIC", "FLAT"), splattings=(False, True))
    print(f"{'scene':<34} {'view':<6} {'mode':<11} {'LINEAR traced':>14} {'DISPLAY traced':>15} "
          f"{'DISPLAY splatted':>17}")
    for name in SCENES:
        for view in VIEWS:
            for mode in ("VOLUMETRIC", "FLAT"):
                print(f"{name:<34} {view:<6} {mode:<11} {results[(name, view, mode, 'LINEAR', False)]:>14.2f} "
                      f"{results[(name, view, mode, 'DISPLAY', False)]:>15.2f} "
                      f"{results[(name, view, mode, 'DISPLAY', True)]:>17.2f}")


def print_attribution(module_dir, data_dir, names):
    sys.path.insert(0, module_dir)
    import _native
    results = attribution(_native, data_dir, names)
    print(f"{'scene':<34} {'view':<6} {'engine vs EWA':>14} {'footprint':>10} {'order':>8} {'model':>8}")
    for (name, view), r in results.items():
        print(f"{name:<34} {view:<6} {r['engine']:>14.2f} {r['footprint']:>10.2f} {r['order']:>8.2f} {r['model']:>8.2f}")


if __name__ == "__main__":
    if ATTRIBUTION:
        print_attribution(MODULE_DIR, DATA_DIR, [a for a in sys.argv[1:] if not a.startswith("-")] or SCENES)
    elif TABLE:
        print_table(MODULE_DIR, DATA_DIR)
    elif sys.argv[1:]:  # unittest's own arguments: a test's name, -k PATTERN
        unittest.main()
    else:
        unittest_report.main()
