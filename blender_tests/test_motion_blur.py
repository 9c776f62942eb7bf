# Motion blur from Blender's own settings (Render Properties > Motion Blur: render.use_motion_blur, Shutter,
# Position; Object Properties > Motion Blur: Object.cycles.use_motion_blur, Steps), in F12:
# - analytic: an emissive bar moving at v pixels per frame, seen by an orthographic camera, is smeared over v x
#   shutter pixels: the image's variance along the motion grows by (v shutter)^2 / 12 (within 3 %) and its total stays
#   (within 1.5 %), for each shutter position (whose interval shifts the smear's centre by +-v shutter / 2); a moving
#   splat object (polygons, compact points, spatial pieces under a moving empty, Blender 5.3's splats) grows by the
#   same amount;
# - against Cycles: a mesh scene with a moving cube and a moving camera (512 samples): mean absolute difference of
#   the images within the tolerance below;
# - a seed gives one frame, a still scene renders as with motion blur off (bit for bit), an object whose motion
#   blur is off stays sharp, the frame is put back after the shutter's steps, and Camera Rays as Splats steps aside
#   for a moving splat object and says so in the status bar.
import unittest
from types import SimpleNamespace

import bpy
import numpy as np

import splat_testing as st
from raysplats.blender import compat
from raysplats.engine import final, motion_blur, ui

WIDTH, HEIGHT = 120, 60
ORTHO_SCALE = 4.0                 # scene units across the image's width
PIXELS_PER_UNIT = WIDTH / ORTHO_SCALE
SPEED = 1.0                       # scene units per frame: 30 pixels per frame
CYCLES_SAMPLES = 512
CYCLES_TOLERANCE = 0.025          # mean |difference| over the mean pixel value


def slide(obj, speed):
    """Moves an object along +X at `speed` scene units per frame, through x = 0 at frame 5."""
    st.drive(obj, "location", 0, f"(frame - 5) * {speed}")


def ortho_scene(samples=128):
    """A black world, an orthographic camera looking down -Z at the plane z = 0 (4 units across 120 pixels), frame 5."""
    scene = st.camera_above_scene(WIDTH, HEIGHT, samples, "ORTHO", ORTHO_SCALE)
    scene.view_settings.view_transform = "Standard"
    scene.raysplats.max_bounces = 0
    scene.raysplats.blend_space = "LINEAR"  # a pixel's value is the mean of its samples' linear values
    scene.frame_set(5)
    return scene


def add_bar():
    """A thin emissive bar (2 x 30 pixels) moving along +X at SPEED, at x = 0 on frame 5."""
    bpy.ops.mesh.primitive_plane_add(size=1.0)
    bar = bpy.context.object
    bar.scale = (2.0 / PIXELS_PER_UNIT, 30.0 / PIXELS_PER_UNIT, 1.0)
    bar.data.materials.append(st.emission_material("Bar"))
    slide(bar, SPEED)
    bpy.context.scene.frame_set(5)
    return bar


def spread_x(image):
    """(total, mean x, variance along x in pixels^2) of the image's luminance-free sum of RGB."""
    values = image[..., :3].astype(np.float64).sum(axis=2)
    x = np.arange(values.shape[1]) + 0.5
    total = values.sum()
    column = values.sum(axis=0)
    mean = (column * x).sum() / total
    return total, mean, (column * (x - mean) ** 2).sum() / total


def bar_scene(name):
    """The moving bar's scene with motion blur on, and spread_x of its render with motion blur off."""
    scene = ortho_scene()
    add_bar()
    scene.render.use_motion_blur = False
    still = spread_x(st.render_to_array(name))
    scene.render.use_motion_blur = True
    return scene, still


def assert_smear(test, label, still, moving, shutter):
    """Asserts that `moving` (spread_x of a render blurred over `shutter` frames) is `still` smeared over SPEED x
    shutter: variance growth (within 3 %) and total (within 1.5 %); returns the smear in pixels."""
    smear = SPEED * shutter * PIXELS_PER_UNIT
    growth = moving[2] - still[2]
    print(f"\n{label}, Blender {bpy.app.version_string}, shutter {shutter}: variance growth {growth:.2f} px^2 (smear "
          f"{smear:.0f} px: {smear ** 2 / 12:.2f}), total {moving[0]:.2f} (still {still[0]:.2f}), centre "
          f"{moving[1] - still[1]:+.2f} px")
    test.assertGreater(still[0], 1.0, "the object is in view")
    test.assertAlmostEqual(growth, smear ** 2 / 12, delta=0.03 * smear ** 2 / 12)
    test.assertAlmostEqual(moving[0], still[0], delta=0.015 * still[0])
    return smear


class MovingBar(unittest.TestCase):
    def test_smear_is_speed_times_shutter_at_every_position(self):
        scene, still = bar_scene("motion_bar_still")
        for shutter, position, shift in ((0.5, "CENTER", 0.0), (1.0, "START", 0.5), (0.5, "END", -0.5)):
            scene.render.motion_blur_shutter = shutter
            motion_blur.position_settings(scene).motion_blur_position = position
            moving = spread_x(st.render_to_array(f"motion_bar_{position.lower()}"))
            smear = assert_smear(self, f"Moving bar, {position}", still, moving, shutter)
            self.assertAlmostEqual(moving[1] - still[1], shift * smear, delta=0.3)
        self.assertEqual(scene.frame_current, 5)
        self.assertEqual(scene.frame_subframe, 0.0)

    def test_shutter_curve_shapes_the_smear(self):
        # A triangular curve (closed, fully open at the middle, closed again): times drawn with a triangular density,
        # whose variance is 1/24 of the shutter squared (a box's is 1/12).
        scene, still = bar_scene("motion_curve_still")
        scene.render.motion_blur_shutter = 1.0
        mapping = scene.render.motion_blur_shutter_curve
        points = mapping.curves[0].points
        points.new(0.5, 1.0)
        points[0].location, points[-1].location = (0.0, 0.0), (1.0, 0.0)
        for point in points:
            point.handle_type = "VECTOR"  # straight segments
        mapping.update()
        self.assertIsNotNone(motion_blur.shutter_curve(scene.render))
        moving = spread_x(st.render_to_array("motion_curve_triangle"))
        smear = SPEED * PIXELS_PER_UNIT
        growth = moving[2] - still[2]
        print(f"\nTriangular shutter curve, Blender {bpy.app.version_string}: variance growth {growth:.2f} px^2 "
              f"(smear {smear:.0f} px: {smear ** 2 / 24:.2f}), total {moving[0]:.2f} (still {still[0]:.2f})")
        self.assertAlmostEqual(growth, smear ** 2 / 24, delta=0.03 * smear ** 2 / 24)
        self.assertAlmostEqual(moving[0], still[0], delta=0.015 * still[0])

    def test_object_switch_and_still_scene(self):
        scene = ortho_scene(16)
        bar = add_bar()
        scene.render.use_motion_blur = False
        off = st.render_to_array("motion_switch_off")
        scene.render.use_motion_blur = True
        bar.cycles.use_motion_blur = False  # Object Properties > Motion Blur
        np.testing.assert_array_equal(st.render_to_array("motion_switch_object_off"), off)
        bar.cycles.use_motion_blur = True
        blurred = st.render_to_array("motion_switch_on")
        self.assertFalse(np.array_equal(blurred, off))
        np.testing.assert_array_equal(st.render_to_array("motion_switch_on_again"), blurred)  # one frame per seed
        scene.raysplats.seed = 4
        self.assertFalse(np.array_equal(st.render_to_array("motion_switch_other_seed"), blurred))
        # Nothing moves: motion blur on renders what off renders, bit for bit.
        bar.driver_remove("location", 0)
        bar.location = (0.0, 0.0, 0.0)
        scene.raysplats.seed = 3
        np.testing.assert_array_equal(st.render_to_array("motion_switch_still"), off)

    def test_persistent_data_renders_as_fresh(self):
        # Persistent Data keeps the native scene between renders: frames 5 and 6 with motion blur, then frame 6
        # without, each equal to a render that built its scene anew (the kept scene takes each frame's motion and
        # gives it back when motion blur is turned off).
        images = {}
        for persistent in (False, True):
            scene = ortho_scene(8)
            add_bar()
            scene.render.use_persistent_data = persistent
            scene.render.use_motion_blur = True
            for frame, blur in ((5, True), (6, True), (6, False)):
                scene.frame_set(frame)
                scene.render.use_motion_blur = blur
                images[persistent, frame, blur] = st.render_to_array(f"motion_persistent_{persistent}_{frame}_{blur}")
            self.assertEqual(final.last_render["scene"] != "new", persistent)
        for frame, blur in ((5, True), (6, True), (6, False)):
            np.testing.assert_array_equal(images[True, frame, blur], images[False, frame, blur])
        self.assertFalse(np.array_equal(images[False, 6, True], images[False, 6, False]))

    def test_motion_steps_follow_cycles(self):
        scene = ortho_scene()
        bar = add_bar()
        self.assertEqual(motion_blur.motion_step_count(bar), 3)
        bar.cycles.motion_steps = 3
        self.assertEqual(motion_blur.motion_step_count(bar), 9)
        bar.cycles.use_motion_blur = False
        self.assertEqual(motion_blur.motion_step_count(bar), 0)
        self.assertIsNone(motion_blur.shutter_curve(scene.render), "Blender's default curve is flat")
        scene.render.use_motion_blur = False
        self.assertIsNone(motion_blur.shutter_motion(None, bpy.context.evaluated_depsgraph_get()))


class MovingSplats(unittest.TestCase):
    def test_every_kind_of_splat_object_smears_by_speed_times_shutter(self):
        kinds = {"POLYGONS": {"representation": "POLYGONS"}, "POINTS": {"representation": "POINTS"},
                 "PIECES": {"objects": "PIECES"}}
        if compat.HAS_NATIVE_GAUSSIAN_SPLATS:
            kinds["BLENDER_SPLATS"] = {"representation": "POLYGONS"}
        for kind, options in kinds.items():
            scene = ortho_scene(128)
            obj = st.import_file("donut_sh0.ply", **options)
            if kind == "BLENDER_SPLATS":
                obj = st.convert_to_blender_splats(obj)
            obj.scale = (5.0, 5.0, 5.0)  # about 32 pixels across
            bpy.context.view_layer.update()
            slide(obj, SPEED)
            scene.frame_set(5)
            scene.render.use_motion_blur = False
            still = spread_x(st.render_to_array(f"motion_splats_{kind.lower()}_still"))
            scene.render.use_motion_blur = True
            scene.render.motion_blur_shutter = 0.5
            image = st.render_to_array(f"motion_splats_{kind.lower()}")
            edges = image[:, :4, :3].sum() + image[:, -4:, :3].sum()
            self.assertLess(edges, 1e-3 * still[0], "the smear stays inside the frame")
            assert_smear(self, f"Moving splats ({kind})", still, spread_x(image), 0.5)

    def test_camera_rays_as_splats_steps_aside_and_says_so(self):
        scene = ortho_scene(4)
        scene.camera.data.type = "PERSP"
        obj = st.import_file("small_sh3_inria.ply")
        scene.raysplats.camera_ray_splatting = True
        scene.render.use_motion_blur = True
        st.render_to_array("motion_notice_still")
        self.assertTrue(final.last_render["camera_ray_splatting"])
        self.assertEqual(final.last_render["notice"], "")
        slide(obj, 0.1)
        scene.frame_set(5)
        st.render_to_array("motion_notice_moving")
        self.assertFalse(final.last_render["camera_ray_splatting"])
        self.assertEqual(final.last_render["notice"], "Camera Rays as Splats needs a scene without motion blur: "
                                                      "this render's camera rays were ray traced")


class Panels(unittest.TestCase):
    def test_panels_draw_every_setting_the_engine_reads(self):
        scene = ortho_scene(1)
        bar = add_bar()
        context = SimpleNamespace(engine=scene.render.engine, scene=scene, object=bar)
        drawn = []
        for panel in (ui.RAYSPLATS_RENDER_PT_motion_blur, ui.RAYSPLATS_RENDER_PT_motion_blur_curve,
                      ui.RAYSPLATS_OBJECT_PT_motion_blur):
            self.assertTrue(panel.poll(context), panel.__name__)
            stand_in = SimpleNamespace(layout=st.RecordingLayout(drawn))
            for method in ("draw_header", "draw"):
                if hasattr(panel, method):
                    getattr(panel, method)(stand_in, context)
        names = {name for _, name, _ in drawn}
        self.assertLessEqual({"use_motion_blur", "motion_blur_shutter", "motion_blur_position",
                              "motion_blur_shutter_curve", "motion_steps"}, names)
        self.assertIn(type(motion_blur.position_settings(scene)).__name__,
                      {owner for owner, name, _ in drawn if name == "motion_blur_position"})


def emissive_cubes_scene(location):
    """Emissive cubes on a dark world, 160 x 120: an orange one (returned) at `location`, a still blue one, and a 35 mm
    perspective camera (returned, unplaced)."""
    scene = st.reset_render_scene(160, 120, CYCLES_SAMPLES)
    scene.view_settings.view_transform = "Standard"
    world = bpy.data.worlds.new("World")
    world.use_nodes = False
    st.set_world_color(world, (0.02, 0.02, 0.02))
    scene.world = world
    bpy.ops.mesh.primitive_cube_add(size=0.8, location=location)
    cube = bpy.context.object
    cube.data.materials.append(st.emission_material("Moving", (0.9, 0.4, 0.1)))
    bpy.ops.mesh.primitive_cube_add(size=0.6, location=(1.2, 0.6, -0.5))
    bpy.context.object.data.materials.append(st.emission_material("Still", (0.1, 0.5, 0.9)))
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    scene.collection.objects.link(camera)
    scene.camera = camera
    camera.data.lens = 35.0
    return scene, cube, camera


def assert_blur_agrees_with_cycles(test, scene, label, unblur):
    """Renders `scene` with Cycles and RaySplats (CYCLES_SAMPLES, direct light only) and asserts their mean absolute
    difference is within CYCLES_TOLERANCE of the mean pixel, and that RaySplats after `unblur()` differs from Cycles'
    blurred image by more than twice that (the blur is what makes them agree)."""
    scene.render.engine = "CYCLES"
    st.use_cycles_on_cpu(scene, CYCLES_SAMPLES).max_bounces = 0
    name = label.lower().replace(" ", "_")
    cycles = st.render_to_array(f"{name}_cycles")[..., :3].astype(np.float64)
    scene.render.engine = "RAYSPLATS"
    scene.raysplats.samples = CYCLES_SAMPLES
    scene.raysplats.use_adaptive_sampling = False
    scene.raysplats.max_bounces = 0
    scene.raysplats.seed = 1
    raysplats = st.render_to_array(f"{name}_raysplats")[..., :3].astype(np.float64)
    mad = np.abs(raysplats - cycles).mean() / cycles.mean()
    unblur()
    sharp = st.render_to_array(f"{name}_raysplats_sharp")[..., :3].astype(np.float64)
    sharp_mad = np.abs(sharp - cycles).mean() / cycles.mean()
    print(f"\n{label} against Cycles, Blender {bpy.app.version_string} (160x120, {CYCLES_SAMPLES} spp): mean "
          f"|difference| {100 * mad:.2f} % of the mean pixel (limit {100 * CYCLES_TOLERANCE:.1f} %); without it "
          f"{100 * sharp_mad:.2f} %")
    test.assertLessEqual(mad, CYCLES_TOLERANCE)
    test.assertGreater(sharp_mad, 2 * mad, "the blur is what makes them agree")


def cycles_scene():
    """Emissive cubes on a dark world: one moving along +X, one still, seen by a perspective camera moving along +X and
    -Z (towards them) while turning about its view axis (the still cube smeared by the camera alone, about 8 px);
    frame 5."""
    scene, moving, camera = emissive_cubes_scene((0.0, 0.0, 0.0))
    slide(moving, 0.5)
    st.drive(camera, "location", 0, "(frame - 5) * 0.4")
    st.drive(camera, "location", 2, "8 - (frame - 5) * 0.25")
    st.drive(camera, "rotation_euler", 2, "(frame - 5) * 0.1")
    scene.frame_set(5)
    scene.render.use_motion_blur = True
    scene.render.motion_blur_shutter = 1.0
    return scene


class AgainstCycles(unittest.TestCase):
    def test_moving_object_and_camera_agree_with_cycles(self):
        scene = cycles_scene()
        assert_blur_agrees_with_cycles(self, scene, "Motion blur",
                                       lambda: setattr(scene.render, "use_motion_blur", False))


if __name__ == "__main__":
    unittest.main()
