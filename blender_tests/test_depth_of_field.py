# Depth of field from Blender's own camera settings (Camera Properties > Depth of Field: Camera.dof's use_dof, Focus
# Object or Distance, F-Stop, Blades, Rotation, Ratio) in F12 and in Rendered shading through the camera:
# - a mesh-only scene (emissive cubes before, at and behind the focus object) agrees with Cycles: mean absolute
#   difference <= 4 % of the mean pixel value, and the 10-90 % width of the out-of-focus cube's edge within 0.5 px of
#   Cycles' (the width the circle of confusion predicts is printed beside them); with use_dof off the same scene
#   agrees as sharply and the depth-of-field settings change nothing; the focus object counts along the view axis
#   (a bone of it too), and animated settings take each frame's values;
# - Gaussians (a polygon object) out of focus equal the average of pinhole renders from points spread over the
#   aperture, each moved across the lens and its image shifted so that the focus plane stays put (the thin lens is
#   that average; with Blend Space As Trained, averaged as display values, as the film averages a pixel's samples):
#   mean absolute difference <= 4 % of the mean pixel value and total light within 1.5 %, while the pinhole render
#   differs by three times more or more; Camera Rays as Splats steps aside and the status bar says so; a seed gives
#   one frame;
# - polygon objects, compact points, spatial pieces (and Blender 5.3's own splats) render the same defocused frame.
import math
import unittest
from types import SimpleNamespace

import bpy
import mathutils
import numpy as np

import splat_testing as st
from raysplats.blender import compat
from raysplats.engine import final, sync, viewport

WIDTH, HEIGHT = 160, 120
CYCLES_SAMPLES = 512
LENS, FSTOP = 35.0, 0.35  # aperture f / N = 0.1 m: the near cube's disc is 8.6 px wide, the far one's 1.5 px


def emission_material(name, color):
    material = bpy.data.materials.new(name)
    material.use_nodes = True
    nodes = material.node_tree.nodes
    nodes.clear()
    output = nodes.new("ShaderNodeOutputMaterial")
    emission = nodes.new("ShaderNodeEmission")
    emission.inputs["Color"].default_value = (*color, 1.0)
    emission.inputs["Strength"].default_value = 1.0
    material.node_tree.links.new(emission.outputs["Emission"], output.inputs["Surface"])
    return material


def add_camera(location, direction, lens=LENS):
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    bpy.context.scene.collection.objects.link(camera)
    camera.location = location
    camera.rotation_euler = mathutils.Vector(direction).to_track_quat("-Z", "Y").to_euler()
    camera.data.lens = lens
    bpy.context.scene.camera = camera
    bpy.context.view_layer.update()  # (matrix_world)
    return camera


def mesh_scene():
    """Emissive cubes at depths 1.25 (near, its left edge at column 36), 3.7 (the focus object, 4.0 away along the
    view axis) and 6.55 from a camera at (0, -4, 0) looking along +Y; a dark world."""
    scene = st.reset_render_scene(WIDTH, HEIGHT, CYCLES_SAMPLES)
    scene.view_settings.view_transform = "Standard"
    world = bpy.data.worlds.new("World")
    world.use_nodes = False
    st.set_world_color(world, (0.03, 0.03, 0.03))
    scene.world = world
    cubes = {}
    for name, color, location, size in (("Near", (0.9, 0.2, 0.1), (-0.1, -2.5, 0.0), 0.5),
                                        ("Focus", (0.1, 0.8, 0.2), (0.25, 0.0, 0.1), 0.6),
                                        ("Far", (0.2, 0.3, 1.0), (0.9, 3.0, -0.2), 0.9)):
        bpy.ops.mesh.primitive_cube_add(size=size, location=location)
        cube = bpy.context.object
        cube.name = name
        cube.data.materials.append(emission_material(name, color))
        cubes[name] = cube
    camera = add_camera((0.0, -4.0, 0.0), (0.0, 1.0, 0.0))
    dof = camera.data.dof
    dof.use_dof, dof.focus_object, dof.aperture_fstop = True, cubes["Focus"], FSTOP
    return scene


def render(scene, engine, name):
    scene.render.engine = engine
    if engine == "CYCLES":
        st.use_cycles_on_cpu(scene, CYCLES_SAMPLES).max_bounces = 0
    else:
        scene.raysplats.samples = CYCLES_SAMPLES
        scene.raysplats.use_adaptive_sampling = False
        scene.raysplats.max_bounces = 0
        scene.raysplats.seed = 1
    return st.render_to_array(name)[..., :3].astype(np.float64)


def edge_width(image):
    """10-90 % width (pixels) of the near cube's left edge: the red channel along rows 45-75 (the cube's middle),
    from the background's level (columns 5-15) to the cube's (columns 52-68), crossings interpolated linearly."""
    profile = image[HEIGHT - 76:HEIGHT - 45, :, 0].mean(axis=0)  # EXR rows run bottom to top
    low, high = profile[5:16].mean(), profile[52:69].mean()
    level = (profile[:70] - low) / (high - low)

    def crossing(fraction):
        i = int(np.argmax(level > fraction))
        return i - 1 + (fraction - level[i - 1]) / (level[i] - level[i - 1])

    return crossing(0.9) - crossing(0.1)


def disc_edge_width(diameter):
    """The 10-90 % width of an edge blurred by a uniform disc of `diameter` pixels: the disc's area to one side of a
    line at distance h from its edge is r^2 (acos(1 - h/r) - (1 - h/r) sqrt(2 h/r - (h/r)^2))."""
    h = np.linspace(0.0, 2.0, 20001)
    share = (np.arccos(1.0 - h) - (1.0 - h) * np.sqrt(np.clip(2.0 * h - h * h, 0.0, None))) / np.pi
    return 0.5 * diameter * (h[np.argmax(share > 0.9)] - h[np.argmax(share > 0.1)])


class MeshesAgainstCycles(unittest.TestCase):
    def compare(self, use_dof):
        scene = mesh_scene()
        scene.camera.data.dof.use_dof = use_dof
        suffix = "dof" if use_dof else "pinhole"
        cycles = render(scene, "CYCLES", f"dof_cycles_{suffix}")
        raysplats = render(scene, "RAYSPLATS", f"dof_raysplats_{suffix}")
        mad = np.abs(raysplats - cycles).mean() / cycles.mean()
        widths = edge_width(raysplats), edge_width(cycles)
        # Cycles' thin lens keeps the pinhole's projection: the disc is A |1/S1 - 1/S2| wide in tangent units.
        px_per_tangent = WIDTH / (36.0 / LENS)
        diameter = LENS * 1e-3 / FSTOP * abs(1.0 / 4.0 - 1.0 / 1.25) * px_per_tangent if use_dof else 0.0
        print(f"\nDepth of field {'on' if use_dof else 'off'} against Cycles, Blender {bpy.app.version_string} "
              f"({WIDTH}x{HEIGHT}, {CYCLES_SAMPLES} spp): mean |difference| {100 * mad:.2f} % of the mean pixel "
              f"(limit 4 %); near cube's edge 10-90 % width {widths[0]:.2f} px (Cycles {widths[1]:.2f} px, "
              f"a {diameter:.1f} px disc's {disc_edge_width(diameter):.2f} px)")
        self.assertLessEqual(mad, 0.04)
        self.assertLess(abs(widths[0] - widths[1]), 0.5)
        return raysplats, widths[0]

    def test_depth_of_field_agrees_with_cycles(self):
        _, blurred = self.compare(True)
        _, sharp = self.compare(False)
        self.assertGreater(blurred, sharp + 2.0, "the near cube is out of focus")

    def test_settings_change_nothing_while_off(self):
        scene = mesh_scene()
        scene.raysplats.samples = 4
        dof = scene.camera.data.dof
        dof.use_dof = False
        before = st.render_to_array("dof_off_a")
        dof.aperture_fstop, dof.aperture_blades, dof.aperture_ratio, dof.focus_object = 0.1, 5, 2.0, None
        self.assertEqual(sync.depth_of_field(scene.camera), {})
        np.testing.assert_array_equal(st.render_to_array("dof_off_b"), before)

    def test_focus_object_distance_is_along_the_view_axis(self):
        scene = mesh_scene()
        camera = scene.camera
        focus = camera.data.dof.focus_object
        focus.location = (1.5, 0.0, -0.7)  # off the axis: 4.0 along it, 4.33 away
        bpy.context.view_layer.update()
        settings = sync.camera_settings(scene, camera, WIDTH, HEIGHT)
        self.assertAlmostEqual(settings["focus_distance"], 4.0, places=5)
        self.assertAlmostEqual(settings["aperture_fstop"], FSTOP, places=6)
        camera.data.dof.focus_object = None
        camera.data.dof.focus_distance = 2.5
        self.assertAlmostEqual(sync.camera_settings(scene, camera, WIDTH, HEIGHT)["focus_distance"], 2.5, places=6)
        # A bone of an armature as the focus (Focus Bone): its head, where Cycles takes it.
        armature = bpy.data.objects.new("Rig", bpy.data.armatures.new("Rig"))
        scene.collection.objects.link(armature)
        bpy.context.view_layer.objects.active = armature
        bpy.ops.object.mode_set(mode="EDIT")
        bone = armature.data.edit_bones.new("Target")
        bone.head, bone.tail = (0.0, 2.0, 0.0), (0.0, 2.0, 0.5)
        bpy.ops.object.mode_set(mode="OBJECT")
        camera.data.dof.focus_object, camera.data.dof.focus_subtarget = armature, "Target"
        bpy.context.view_layer.update()
        self.assertAlmostEqual(sync.camera_settings(scene, camera, WIDTH, HEIGHT)["focus_distance"], 6.0, places=5)

    def test_animated_settings_take_each_frames_values(self):
        # An animation renders each frame from the evaluated camera, as F12 of that frame does (final.py).
        scene = mesh_scene()
        dof = scene.camera.data.dof
        dof.focus_object = None
        for frame, distance, fstop in ((1, 2.0, 1.4), (10, 6.0, 4.0)):
            dof.focus_distance, dof.aperture_fstop = distance, fstop
            dof.keyframe_insert("focus_distance", frame=frame)
            dof.keyframe_insert("aperture_fstop", frame=frame)
        for frame, distance, fstop in ((1, 2.0, 1.4), (10, 6.0, 4.0)):
            scene.frame_set(frame)
            camera = scene.camera.evaluated_get(bpy.context.evaluated_depsgraph_get())
            settings = sync.camera_settings(scene, camera, WIDTH, HEIGHT)
            self.assertAlmostEqual(settings["focus_distance"], distance, places=5)
            self.assertAlmostEqual(settings["aperture_fstop"], fstop, places=5)


def donut_scene(samples):
    scene = st.reset_render_scene(96, 72, samples)
    st.import_file("donut_sh0.ply")
    camera = add_camera((0.0, -0.6, 0.0), (0.0, 1.0, 0.0), lens=50.0)
    dof = camera.data.dof
    dof.use_dof, dof.focus_distance, dof.aperture_fstop = True, 0.4, 1.0  # the donut's disc about 5.5 px wide
    return scene


def linear_to_srgb(c):
    c = np.clip(c, 0.0, None)
    return np.where(c <= 0.0031308, 12.92 * c, 1.055 * np.power(c, 1.0 / 2.4) - 0.055)


def srgb_to_linear(c):
    return np.where(c <= 0.04045, c / 12.92, np.power((c + 0.055) / 1.055, 2.4))


class GaussiansOutOfFocus(unittest.TestCase):
    def test_equals_the_average_of_pinhole_renders_over_the_aperture(self):
        for blend_space in ("DISPLAY", "LINEAR"):
            with self.subTest(blend_space=blend_space):
                self.compare_with_pinholes(blend_space)

    def compare_with_pinholes(self, blend_space):
        scene = donut_scene(256)
        scene.raysplats.use_adaptive_sampling = False
        scene.raysplats.blend_space = blend_space
        blurred = st.render_to_array(f"dof_donut_{blend_space.lower()}")[..., :3].astype(np.float64)

        core = st.native()
        depsgraph = bpy.context.evaluated_depsgraph_get()
        render_scene, _ = sync.build_render_scene(depsgraph)
        camera = sync.camera_settings(scene, scene.camera.evaluated_get(depsgraph), 96, 72)
        radius = 50e-3 / (2.0 * 1.0)
        focus = camera["focus_distance"]
        extent = camera["sensor_width"] / camera["lens"]  # tangent units of the fitted (horizontal) dimension
        pinhole = {name: value for name, value in camera.items()
                   if name not in ("use_dof", "focus_distance", "aperture_fstop", "aperture_blades",
                                   "aperture_rotation", "aperture_ratio")}
        settings = sync.render_settings(scene, 96, 72, 4)
        settings["camera_ray_splatting"] = False
        images = []
        # 64 points spread evenly over the aperture disc (stratified in area: r = R sqrt(u), angle 2 pi v).
        for i in range(8):
            for j in range(8):
                r, angle = radius * math.sqrt((i + 0.5) / 8), 2.0 * math.pi * (j + 0.5) / 8
                lx, ly = r * math.cos(angle), r * math.sin(angle)
                moved = dict(pinhole)
                matrix = np.array(camera["matrix"], dtype=np.float64)
                matrix[:3, 3] += matrix[:3, 0] * lx + matrix[:3, 1] * ly  # the matrix is normalized: unit axes
                moved["matrix"] = matrix.astype(np.float32)
                # The focus plane keeps its image: the ray of an image position from the moved camera must meet the
                # original's at the focus distance, so the tangent shifts by -l / S1.
                moved["shift_x"] = camera["shift_x"] - lx / (focus * extent)
                moved["shift_y"] = camera["shift_y"] - ly / (focus * extent)
                settings["seed"] = 8 * i + j
                rgba = core.RenderJob(render_scene, moved, settings).result()["rgba"]
                images.append(rgba[::-1, :, :3].astype(np.float64))  # film rows top to bottom, EXR bottom to top
        if blend_space == "DISPLAY":
            # As Trained, a pixel's samples (its lens samples too) are averaged as display values, as the pixel
            # filter's are (the film's display parts; here, on a black world, the pixel is linear(mean display)).
            reference = srgb_to_linear(np.mean([linear_to_srgb(image) for image in images], axis=0))
        else:
            reference = np.mean(images, axis=0)
        settings["seed"], settings["samples"] = 0, 64
        sharp = core.RenderJob(render_scene, pinhole, settings).result()["rgba"][::-1, :, :3]
        mean = reference.mean()
        mad = np.abs(blurred - reference).mean() / mean
        mad_pinhole = np.abs(sharp - reference).mean() / mean
        flux = blurred.sum() / reference.sum() - 1.0
        print(f"\nGaussians out of focus ({blend_space}), Blender {bpy.app.version_string}: mean |difference| "
              f"against the average of 64 pinhole renders {100 * mad:.2f} % of the mean pixel (limit 4 %), total "
              f"light {100 * flux:+.2f} % (limit 1.5 %); the pinhole render's {100 * mad_pinhole:.2f} %")
        self.assertGreater(mean, 0.02, "the donut is in view")
        self.assertLessEqual(mad, 0.04)
        self.assertLess(abs(flux), 0.015)
        self.assertGreater(mad_pinhole, 3.0 * mad, "the blur is real")

    def test_camera_rays_as_splats_steps_aside_and_a_seed_gives_one_frame(self):
        scene = donut_scene(4)
        scene.raysplats.camera_ray_splatting = True
        first = st.render_to_array("dof_seed_a")
        self.assertFalse(final.last_render["camera_ray_splatting"])
        self.assertEqual(final.last_render["notice"], "Camera Rays as Splats needs a camera without depth of "
                                                      "field: this render's camera rays were ray traced")
        np.testing.assert_array_equal(st.render_to_array("dof_seed_b"), first)
        scene.raysplats.seed = 2
        self.assertFalse(np.array_equal(st.render_to_array("dof_seed_c"), first))
        scene.camera.data.dof.use_dof = False
        st.render_to_array("dof_seed_pinhole")
        self.assertTrue(final.last_render["camera_ray_splatting"])
        self.assertEqual(final.last_render["notice"], "")

    def test_every_kind_of_splat_object_renders_the_same_defocused_frame(self):
        kinds = {"POLYGONS": {"representation": "POLYGONS"}, "POINTS": {"representation": "POINTS"},
                 "PIECES": {"objects": "PIECES"}}
        if compat.HAS_NATIVE_GAUSSIAN_SPLATS:
            kinds["BLENDER_SPLATS"] = {"representation": "POLYGONS"}
        images = {}
        for kind, options in kinds.items():
            scene = st.reset_render_scene(96, 72, 8)
            obj = st.import_file("small_sh3_inria.ply", **options)
            if kind == "BLENDER_SPLATS":
                for other in bpy.context.view_layer.objects:
                    other.select_set(other is obj)
                bpy.context.view_layer.objects.active = obj
                self.assertEqual(bpy.ops.object.raysplats_to_native_splats(), {"FINISHED"})
            camera = add_camera((0.0, -6.0, 1.0), (0.0, 1.0, -0.12), lens=50.0)
            dof = camera.data.dof
            dof.use_dof, dof.focus_distance, dof.aperture_fstop = True, 3.0, 0.25
            images[kind] = st.render_to_array(f"dof_kind_{kind.lower()}")[..., :3]
            if kind == "POLYGONS":
                dof.use_dof = False
                images["pinhole"] = st.render_to_array("dof_kind_pinhole")[..., :3]
        polygons = images["POLYGONS"]
        self.assertGreater(float(polygons.max()), 0.1, "the scene is in view")

        def psnr(image):
            mse = float(np.mean((image - polygons) ** 2))
            return 10 * np.log10(float(polygons.max()) ** 2 / max(mse, 1e-20))

        for kind in kinds:
            self.assertGreater(psnr(images[kind]), 40.0, kind)
        self.assertLess(psnr(images["pinhole"]), 35.0, "the blur is real")


class CameraPanels(unittest.TestCase):
    def test_camera_properties_show_every_depth_of_field_setting(self):
        # Camera Properties > Depth of Field (its header's check box and the focus) and its Aperture subpanel are
        # Blender's own, shown for this engine; together they draw every Camera.dof setting the engine reads.
        scene = st.reset_render_scene(32, 24, 1)
        camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
        scene.collection.objects.link(camera)
        context = SimpleNamespace(engine=scene.render.engine, camera=camera.data, scene=scene, object=camera,
                                  space_data=None)
        drawn = []
        for panel in (bpy.types.DATA_PT_camera_dof, bpy.types.DATA_PT_camera_dof_aperture):
            self.assertIn("RAYSPLATS", panel.COMPAT_ENGINES, panel.__name__)
            stand_in = SimpleNamespace(layout=st.RecordingLayout(drawn))
            for method in ("draw_header", "draw"):
                if hasattr(panel, method):
                    getattr(panel, method)(stand_in, context)
        settings = {name for owner, name in drawn if owner == "CameraDOFSettings"}
        self.assertLessEqual({"use_dof", "focus_object", "focus_distance", "aperture_fstop", "aperture_blades",
                              "aperture_rotation", "aperture_ratio"}, settings)


class ViewportThroughTheCamera(unittest.TestCase):
    def context(self, scene, camera, zoom=1.0, view_perspective="CAMERA"):
        depsgraph = bpy.context.evaluated_depsgraph_get()
        window = camera.calc_matrix_camera(depsgraph, x=96, y=72)
        window[0][0] *= zoom
        window[1][1] *= zoom
        return SimpleNamespace(
            scene=scene,
            region_data=SimpleNamespace(view_matrix=camera.matrix_world.inverted(), window_matrix=window,
                                        is_perspective=True, view_perspective=view_perspective),
            space_data=SimpleNamespace(clip_start=camera.data.clip_start, clip_end=camera.data.clip_end,
                                       camera=None, use_local_camera=False))

    def test_rendered_shading_through_the_camera_has_its_depth_of_field(self):
        scene = donut_scene(16)
        camera = scene.camera
        f12 = sync.camera_settings(scene, camera, 96, 72)
        view = viewport.view_camera(self.context(scene, camera), 96, 72)
        for name in ("use_dof", "focus_distance", "aperture_fstop", "aperture_blades", "aperture_rotation",
                     "aperture_ratio"):
            self.assertAlmostEqual(view[name], f12[name], places=4, msg=name)
        # Zoomed in the camera view, the lens the view gives is longer; the aperture keeps its size (Cycles' viewport
        # takes it from the camera's own lens): lens / (2 f-stop) is unchanged.
        zoomed = viewport.view_camera(self.context(scene, camera, zoom=2.0), 96, 72)
        self.assertAlmostEqual(zoomed["lens"] / zoomed["aperture_fstop"], f12["lens"] / f12["aperture_fstop"], 3)
        # A view not looking through the camera has none, as in Cycles.
        self.assertNotIn("use_dof", viewport.view_camera(self.context(scene, camera, view_perspective="PERSP"), 96,
                                                         72))
        render_scene, _ = sync.build_render_scene(bpy.context.evaluated_depsgraph_get())
        settings = sync.render_settings(scene, 96, 72, 4)
        images = [st.native().RenderJob(render_scene, cam, settings).result()["rgba"] for cam in (f12, view)]
        self.assertGreater(float(images[0].max()), 0.1, "the donut is in view")
        np.testing.assert_allclose(images[1], images[0], atol=2e-3)


if __name__ == "__main__":
    unittest.main()
