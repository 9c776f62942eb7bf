# The RaySplats engine inside Blender: F12 on splats with meshes, shadows through splats, mirrors, headless
# command-line rendering, animation of deformed splats, cancellation, empty scenes and missing cameras.
import math
import os
import subprocess
import sys
import time
import unittest

import bpy
import mathutils
import numpy as np

import splat_testing as st
from raysplats.blender import compat, mesh_read
from raysplats.objects import polygon_mesh

DONUT = "donut_sh0.ply"


# How long a wait may last before a test calls it a hang: minutes, far beyond what any load makes of seconds of work.
HANG_GUARD_SECONDS = 300.0


def new_scene(width=160, height=120, samples=4):
    st.reset_scene()
    scene = bpy.context.scene
    scene.render.engine = "RAYSPLATS"
    scene.render.resolution_x, scene.render.resolution_y = width, height
    scene.render.resolution_percentage = 100
    scene.raysplats.samples = samples
    scene.view_settings.view_transform = "Standard"
    world = bpy.data.worlds.new("World")
    world.use_nodes = False
    st.set_world_color(world, (0.0, 0.0, 0.0))
    scene.world = world
    return scene


def add_donut(location, up_axis="Z"):
    obj = st.import_file(DONUT, up_axis=up_axis)
    # Centre the donut's splats on `location` (object origin = centroid of the Gaussian centres).
    centres = st.native().read_splats(st.data_file(DONUT))["positions"].astype(np.float64)
    obj.location = mathutils.Vector(location) - mathutils.Vector(centres.mean(axis=0))
    return obj


def add_camera(location, direction, ortho_scale=None, lens=50.0):
    data = bpy.data.cameras.new("Camera")
    if ortho_scale is not None:
        data.type, data.ortho_scale = "ORTHO", ortho_scale
    data.lens = lens
    data.clip_start, data.clip_end = 0.01, 100.0
    camera = bpy.data.objects.new("Camera", data)
    bpy.context.scene.collection.objects.link(camera)
    camera.location = location
    camera.rotation_euler = mathutils.Vector(direction).to_track_quat("-Z", "Y").to_euler()
    bpy.context.scene.camera = camera
    return camera


def diffuse_material(color, specular=0.0):
    material = bpy.data.materials.new("Diffuse")
    material.use_nodes = True
    principled = material.node_tree.nodes["Principled BSDF"]
    principled.inputs["Base Color"].default_value = (*color, 1.0)
    principled.inputs["Roughness"].default_value = 1.0
    specular_input = principled.inputs.get("Specular") or principled.inputs.get("Specular IOR Level")
    specular_input.default_value = specular
    return material


def principled_material(name, **values):
    material = bpy.data.materials.new(name)
    material.use_nodes = True
    principled = material.node_tree.nodes["Principled BSDF"]
    for key, value in values.items():
        principled.inputs[key].default_value = value
    return material


class RenderEngine(unittest.TestCase):
    def test_engine_and_settings_are_registered(self):
        scene = new_scene()
        self.assertEqual(scene.render.engine, "RAYSPLATS")
        for name in ("samples", "max_bounces", "compositing", "transmittance_threshold", "gaussian_mode",
                     "meshes_shadow_gaussians", "seed"):
            self.assertTrue(hasattr(scene.raysplats, name), name)

    def test_splat_shadow_falls_along_the_sun_and_transmits_what_the_splats_let_through(self):
        """A real splat object 0.3 above a white Lambertian plane, lit by a sun at 45°. The shadow's deficit
        (1 - L/L0, integrated over the ground) must equal the splats' opacity integrated over a view along the
        sun direction, divided by cos 45° (the shadow is stretched on the ground), and be centred where the
        sun direction through the splats meets the ground. L0 must be the analytic rho·E·cos θ / π."""
        scene = new_scene(width=320, height=320, samples=4)
        # Direct light only: the splats' baked radiance would otherwise light the ground too (indirect).
        scene.raysplats.max_bounces = 0
        height, theta, irradiance, albedo = 0.3, math.radians(45), 2.0, 0.8
        donut = add_donut((0.0, 0.0, height))
        bpy.ops.mesh.primitive_plane_add(size=6.0, location=(0, 0, 0))
        plane = bpy.context.object
        plane.data.materials.append(diffuse_material((albedo, albedo, albedo)))
        sun_direction = mathutils.Vector((-math.sin(theta), 0.0, -math.cos(theta)))
        bpy.ops.object.light_add(type="SUN")
        sun = bpy.context.object
        sun.data.energy = irradiance
        sun.data.angle = 0.0
        sun.rotation_euler = sun_direction.to_track_quat("-Z", "Y").to_euler()

        # View A: orthographic along the sun direction, splats only, transparent film: alpha = 1 - T.
        plane.hide_render = True
        scene.render.film_transparent = True
        ortho_a = 0.5
        add_camera(mathutils.Vector((0, 0, height)) - 5 * sun_direction, sun_direction, ortho_scale=ortho_a)
        view_a = st.render_to_array("shadow_view_a")
        opacity_integral = view_a[..., 3].sum() * (ortho_a / 320) ** 2
        self.assertGreater(opacity_integral, 1e-3, "the splats must be visible along the sun")

        # View B: straight down onto the ground, first the splats alone (to mask them), then with the plane.
        ortho_b = 1.2
        centre_b = mathutils.Vector((-0.2, 0.0, 5.0))
        add_camera(centre_b, (0, 0, -1), ortho_scale=ortho_b)
        splat_mask = st.render_to_array("shadow_view_b_mask")[..., 3] > 1e-3
        plane.hide_render = False
        scene.render.film_transparent = False
        ground = st.render_to_array("shadow_view_b")
        self.assertFalse(np.isnan(ground).any())

        l0_expected = albedo * irradiance * math.cos(theta) / math.pi
        if compat.PRINCIPLED_VERSION == "V1":
            # Principled v1's diffuse (Cycles' principled diffuse, roughness 1, seen along the normal):
            # (1 - FL / 2) + RR FL, FL = (1 - cos theta)^5, RR = roughness (1 + cos theta).
            fl = (1.0 - math.cos(theta)) ** 5
            l0_expected *= (1.0 - 0.5 * fl) + 1.0 * (1.0 + math.cos(theta)) * fl
        luminance = ground[..., :3].mean(axis=2)
        lit = luminance[:, :40][~splat_mask[:, :40]]  # the image's left edge, far from the shadow
        self.assertAlmostEqual(float(np.median(lit)) / l0_expected, 1.0, delta=0.02)
        deficit = np.where(splat_mask, 0.0, 1.0 - luminance / l0_expected)
        pixel_area = (ortho_b / 320) ** 2
        shadow_integral = deficit.sum() * pixel_area
        self.assertAlmostEqual(shadow_integral * math.cos(theta) / opacity_integral, 1.0, delta=0.05)

        # Where the shadow is: centroid of the deficit in world x, y.
        rows, cols = np.indices(deficit.shape)
        xs = centre_b.x + (cols + 0.5 - 160) * ortho_b / 320
        ys = centre_b.y + (rows + 0.5 - 160) * ortho_b / 320  # rows run bottom to top
        weights = np.clip(deficit, 0, None)
        shadow_centre = np.array([(xs * weights).sum(), (ys * weights).sum()]) / weights.sum()
        expected = np.array([-height * math.tan(theta), 0.0])
        np.testing.assert_allclose(shadow_centre, expected, atol=0.03)
        self.assertTrue(donut.raysplats.is_gaussian)

    def test_mirror_shows_splat_colours_and_glass_renders_without_nan(self):
        scene = new_scene(width=240, height=160, samples=8)
        st.set_world_color(scene.world, (0.02, 0.02, 0.02))
        add_donut((0.3, -0.3, 0.0))
        bpy.ops.mesh.primitive_plane_add(size=3.0, location=(0.0, 0.6, 0.0), rotation=(math.pi / 2, 0, 0))
        mirror = bpy.context.object
        mirror_material = principled_material("Mirror", Metallic=1.0, Roughness=0.0)
        mirror_material.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (1, 1, 1, 1)
        mirror.data.materials.append(mirror_material)
        bpy.ops.mesh.primitive_uv_sphere_add(radius=0.15, location=(-0.5, 0.0, 0.0))
        glass = principled_material("Glass", Roughness=0.0, IOR=1.5)
        glass_node = glass.node_tree.nodes["Principled BSDF"]
        (glass_node.inputs.get("Transmission Weight") or glass_node.inputs["Transmission"]).default_value = 1.0
        bpy.context.object.data.materials.append(glass)
        bpy.ops.object.light_add(type="SUN", rotation=(0.3, 0.2, 0.0))
        camera = add_camera((0.0, -2.0, 0.0), (0, 1, 0), lens=35.0)

        image = st.render_to_array("mirror")
        self.assertFalse(np.isnan(image).any())
        self.assertTrue(np.isfinite(image).all())

        def pixel_of(point):
            co = bpy_extras_world_to_camera(scene, camera, mathutils.Vector(point))
            return int(co.y * image.shape[0]), int(co.x * image.shape[1])

        donut_centre = (0.3, -0.3, 0.0)
        reflected_centre = (0.3, 0.6 + (0.6 + 0.3), 0.0)  # mirrored across the plane y = 0.6
        r_direct, c_direct = pixel_of(donut_centre)
        r_mirror, c_mirror = pixel_of(reflected_centre)
        direct = image[r_direct - 2:r_direct + 3, c_direct - 2:c_direct + 3, :3].reshape(-1, 3)
        reflected = image[r_mirror - 2:r_mirror + 3, c_mirror - 2:c_mirror + 3, :3].reshape(-1, 3)
        self.assertGreater(reflected.mean(), 5 * 0.02, "the mirror must show the splats, not the dark world")
        # Splat colours in the mirror: the same hue as the splats seen directly.
        chroma_direct = direct.mean(axis=0) / direct.mean()
        chroma_reflected = reflected.mean(axis=0) / reflected.mean()
        np.testing.assert_allclose(chroma_reflected, chroma_direct, atol=0.15)

        # Without the mirror (black diffuse) the same pixels are dark: the colour came from the reflection.
        mirror.data.materials[0] = diffuse_material((0.0, 0.0, 0.0))
        image_black = st.render_to_array("mirror_black")
        dark = image_black[r_mirror - 2:r_mirror + 3, c_mirror - 2:c_mirror + 3, :3]
        self.assertLess(dark.mean(), 0.2 * reflected.mean())

    def test_animation_of_a_deformed_splat_object_changes_only_where_it_deforms(self):
        scene = new_scene(width=200, height=100, samples=2)
        st.set_world_color(scene.world, (0.05, 0.05, 0.05))
        moving = add_donut((-0.15, 0.0, 0.0))
        add_donut((0.15, 0.0, 0.0))
        lattice_data = bpy.data.lattices.new("Lattice")
        lattice = bpy.data.objects.new("Lattice", lattice_data)
        scene.collection.objects.link(lattice)
        lattice.location = (-0.15, 0.0, 0.0)
        lattice.scale = (0.4, 0.4, 0.4)
        modifier = moving.modifiers.new("Lattice", "LATTICE")
        modifier.object = lattice
        # Keyframe the lattice points: frame 1 at rest, frame 2 squashed in x.
        lattice.shape_key_add(name="Basis")
        squash = lattice.shape_key_add(name="Squash")
        for point in squash.data:
            point.co.x *= 0.6
        squash.value = 0.0
        squash.keyframe_insert("value", frame=1)
        squash.value = 1.0
        squash.keyframe_insert("value", frame=2)
        add_camera((0.0, 0.0, 3.0), (0, 0, -1), ortho_scale=0.6)
        scene.frame_start, scene.frame_end = 1, 2
        scene.render.image_settings.file_format = "OPEN_EXR"
        scene.render.filepath = st.tmp_file("anim_####")
        bpy.ops.render.render(animation=True)
        frames = [st.load_image(st.tmp_file(f"anim_{frame:04d}.exr")) for frame in (1, 2)]
        difference = np.abs(frames[1] - frames[0])[..., :3].sum(axis=2)
        left, right = difference[:, :100], difference[:, 100:]
        self.assertGreater(left.sum(), 1.0, "the lattice-deformed splats must change between frames")
        self.assertEqual(float(right.sum()), 0.0, "the untouched splats must render identically")

    @unittest.skipIf(not bpy.app.binary_path, "expected: Blender as a Python module has no command line")
    def test_headless_command_line_render(self):
        scene = new_scene(width=64, height=48, samples=2)
        st.set_world_color(scene.world, (0.1, 0.2, 0.3))
        add_donut((0.0, 0.0, 0.0))
        add_camera((0.0, -0.6, 0.0), (0, 1, 0))
        blend = st.tmp_file("headless.blend")
        bpy.ops.wm.save_as_mainfile(filepath=blend)
        output = st.tmp_file("headless_")
        for old in (output + "0001.png",):
            if os.path.exists(old):
                os.remove(old)
        addon_dir = os.path.dirname(os.path.dirname(os.path.abspath(sys.modules["raysplats"].__file__)))
        register = f"import sys; sys.path.insert(0, {addon_dir!r}); import raysplats; raysplats.register()"
        process = subprocess.run(
            [bpy.app.binary_path, "-b", "--factory-startup", blend, "--python-expr", register,
             "-E", "RAYSPLATS", "-o", output + "####", "-F", "PNG", "-f", "1"],
            capture_output=True, text=True, timeout=300)
        self.assertEqual(process.returncode, 0, process.stdout[-2000:] + process.stderr[-2000:])
        self.assertTrue(os.path.exists(output + "0001.png"), process.stdout[-2000:])
        pixels = st.load_image(output + "0001.png")
        self.assertEqual(pixels.shape, (48, 64, 4))
        # The splats cover the centre; the corners show the world colour.
        rgb = pixels[..., :3]
        self.assertGreater(np.abs(rgb[20:28, 28:36] - rgb[0, 0]).mean(), 0.05)

    def test_empty_scene_renders_the_world(self):
        scene = new_scene(width=32, height=24, samples=1)
        st.set_world_color(scene.world, (0.2, 0.3, 0.4))
        add_camera((0, 0, 0), (0, 1, 0))
        image = st.render_to_array("empty")
        np.testing.assert_allclose(image[..., :3].reshape(-1, 3).mean(axis=0), (0.2, 0.3, 0.4), atol=1e-4)

    def test_scene_without_camera_is_a_clear_error(self):
        new_scene()
        add_donut((0, 0, 0))
        with self.assertRaises(RuntimeError) as raised:
            bpy.ops.render.render()
        self.assertIn("camera", str(raised.exception).lower())

    def test_viewport_camera_from_view_matrices_matches_the_scene_camera(self):
        """In camera view the 3D view's matrices are the camera's; the viewport must then trace the same rays
        (perspective with lens shift, and orthographic)."""
        from types import SimpleNamespace

        from raysplats.engine import sync, viewport
        core = st.native()
        for ortho in (False, True):
            scene = new_scene(width=80, height=60, samples=1)
            st.set_world_color(scene.world, (0.1, 0.1, 0.1))
            add_donut((0, 0, 0))
            camera = add_camera((0.05, -0.6, 0.1), (0, 1, -0.1), ortho_scale=0.4 if ortho else None, lens=40.0)
            camera.data.shift_x, camera.data.shift_y = 0.1, -0.05
            depsgraph = bpy.context.evaluated_depsgraph_get()
            window = camera.calc_matrix_camera(depsgraph, x=80, y=60)
            context = SimpleNamespace(
                scene=scene,
                region_data=SimpleNamespace(view_matrix=camera.matrix_world.inverted(), window_matrix=window,
                                            is_perspective=not ortho, view_perspective="CAMERA"),
                space_data=SimpleNamespace(clip_start=camera.data.clip_start, clip_end=camera.data.clip_end,
                                           camera=None, use_local_camera=False))
            render_scene, _ = sync.build_render_scene(depsgraph)
            settings = sync.render_settings(scene, 80, 60, 1)
            settings["compositing"] = "STOCHASTIC"
            images = [core.RenderJob(render_scene, cam, settings).result()["rgba"]
                      for cam in (sync.camera_settings(scene, camera, 80, 60), viewport.view_camera(context, 80, 60))]
            self.assertGreater(np.abs(images[0] - images[0][0, 0]).max(), 0.1, "the splats must be in view")
            np.testing.assert_allclose(images[1], images[0], atol=2e-3, err_msg="ortho" if ortho else "perspective")

    def test_instances_and_modifiers_reach_the_renderer(self):
        from raysplats.engine import sync
        new_scene()
        bpy.ops.mesh.primitive_cube_add(size=0.2)
        cube = bpy.context.object
        cube.modifiers.new("Subdivision", "SUBSURF").levels = 1  # 6 faces -> 24 quads -> 48 triangles
        collection = bpy.data.collections.new("Instanced")
        collection.objects.link(cube)
        bpy.context.scene.collection.children.link(collection)
        for x in (1.0, 2.0):
            empty = bpy.data.objects.new(f"Instance {x}", None)
            empty.instance_type, empty.instance_collection = "COLLECTION", collection
            empty.location = (x, 0.0, 0.0)
            bpy.context.scene.collection.objects.link(empty)
        splats = add_donut((0, 0, 0))
        splats.modifiers.new("Mirror", "MIRROR").use_mirror_merge = False
        _, stats = sync.build_render_scene(bpy.context.evaluated_depsgraph_get())
        self.assertEqual(stats.triangles, 3 * 48)
        self.assertEqual(stats.splats, 2 * len(splats.data.polygons))

    def test_viewport_edit_of_a_shape_keyed_object_shows_its_evaluated_geometry(self):
        """A shape key's value changed: the viewport's update reads the geometry with the key applied (the object's
        evaluated mesh, not its Mesh datablock, which keeps the basis), as a scene built from scratch does."""
        from raysplats.engine import sync
        scene = new_scene()
        splats = add_donut((0, 0, 0))
        add_camera((0.0, -0.6, 0.0), (0, 1, 0))
        co = np.empty(len(splats.data.vertices) * 3, dtype=np.float32)
        splats.data.vertices.foreach_get("co", co)
        splats.shape_key_add(name="Basis")
        lift = splats.shape_key_add(name="Lift")
        lift.value = 0.0  # (a new key's value is 0 up to Blender 4.5 and 1 from 5.0)
        lift.data.foreach_set("co", (co.reshape(-1, 3) + (0.0, 0.0, 0.03)).ravel())
        bpy.context.view_layer.update()
        live = sync.SceneSync(bpy.context.evaluated_depsgraph_get(), interactive=True)
        live.render_scene.build("FLAT")
        changes = []

        def handler(scene_, depsgraph_):
            changes.append(live.update(depsgraph_))

        def image(scene_sync):
            return sorted_image(scene, scene_sync)

        before = image(live)
        bpy.app.handlers.depsgraph_update_post.append(handler)
        try:
            lift.value = 1.0
            bpy.context.view_layer.update()
        finally:
            bpy.app.handlers.depsgraph_update_post.remove(handler)
        self.assertEqual(changes, ["updated"])
        after = image(live)
        self.assertLessEqual(float(np.abs(after - image(fresh_sync())).max()), 1e-6)
        self.assertGreater(float(np.abs(after - before).max()), 1e-3)

    def test_viewport_edits_recover_only_the_edited_splats_and_render_like_a_fresh_scene(self):
        from raysplats.engine import sync
        scene = new_scene()
        splats = add_donut((0, 0, 0))
        add_camera((0.0, -0.6, 0.0), (0, 1, 0))
        depsgraph = bpy.context.evaluated_depsgraph_get()
        # `live` recovers what changed; `whole` always recovers whole objects (and keeps the primitive order too, so
        # that the images must agree bit for bit: a scene built from scratch orders the edited Gaussians anew, and
        # hits at equal depth may then composite in another order).
        live, whole = sync.SceneSync(depsgraph, interactive=True), sync.SceneSync(depsgraph, interactive=True)
        live.render_scene.build("FLAT")
        whole.render_scene.build("FLAT")
        changes = []

        handler = updating_live_and_whole(live, whole, changes)

        bpy.app.handlers.depsgraph_update_post.append(handler)

        def images(reference=None):
            """Sorted and stochastic renders of `live` and of the reference (by default a scene built from scratch
            from the same data, read from the evaluated meshes: see fresh_sync)."""
            reference = reference or fresh_sync()
            out = []
            for compositing in ("SORTED", "STOCHASTIC"):
                out.append([sorted_image(scene, s, compositing) for s in (live, reference)])
            return out

        try:
            before = images()[0][0]
            faces = len(splats.data.polygons)
            # Object Mode edit: the vertices of faces 10..12 move, and face 500's opacity attribute changes.
            co = np.empty(len(splats.data.vertices) * 3, dtype=np.float32)
            splats.data.vertices.foreach_get("co", co)
            corners = np.empty(len(splats.data.loops), dtype=np.int64)
            splats.data.loops.foreach_get("vertex_index", corners)
            moved = np.unique(corners[splats.data.polygons[10].loop_start:splats.data.polygons[12].loop_start + 8])
            co.reshape(-1, 3)[moved] += (0.0, 0.0, 0.03)
            splats.data.vertices.foreach_set("co", co)
            splats.data.attributes["gs_opacity"].data[500].value = 0.02
            splats.data.update()
            bpy.context.view_layer.update()
            self.assertEqual(changes[-1], "updated")
            self.assertEqual(live.faces_recovered, 4)
            live.render_scene.build("FLAT")
            report = live.render_scene.last_build()
            self.assertFalse(report["full"])
            self.assertGreaterEqual(report["gaussian_chunks"], 1)
            self.assertEqual(whole.faces_recovered, faces)
            for live_image, whole_image in images(whole):
                self.assertLessEqual(float(np.abs(live_image - whole_image).max()), 1e-6)
            after = images(whole)[0][0]
            self.assertGreater(float(np.abs(after - before).max()), 1e-3)  # the edit shows

            # Topology change (a face deleted): the whole object is recovered; a NaN vertex drops its face.
            import bmesh
            mesh = bmesh.new()
            mesh.from_mesh(splats.data)
            mesh.faces.ensure_lookup_table()
            bmesh.ops.delete(mesh, geom=[mesh.faces[3]], context="FACES")
            mesh.to_mesh(splats.data)
            mesh.free()
            splats.data.update()
            bpy.context.view_layer.update()
            self.assertEqual(changes[-1], "updated")
            self.assertEqual(live.faces_recovered, faces - 1)
            self.assertEqual(live.stats.splats, faces - 1)
            splats.data.vertices[0].co = (float("nan"), 0.0, 0.0)
            splats.data.update()
            bpy.context.view_layer.update()
            self.assertEqual(changes[-1], "updated")
            self.assertEqual(live.stats.splats, faces - 2)
            for live_image, fresh_image in images():
                self.assertLessEqual(float(np.abs(live_image - fresh_image).max()), 1e-6)
        finally:
            bpy.app.handlers.depsgraph_update_post.remove(handler)

    def test_viewport_edit_mode_moves_are_read_from_the_bmesh_and_recover_only_the_moved_splats(self):
        """In Edit Mode the viewport reads the moved vertices in place from the BMesh (no conversion of the whole edit
        mesh): exactly the positions Blender's conversion gives, only the moved splats recovered, the image that of a
        whole recovery; a change of topology in Edit Mode (a face deleted) reads the mesh in full."""
        from unittest import mock
        from raysplats.engine import sync
        scene = new_scene()
        splats = add_donut((0, 0, 0))
        add_camera((0.0, -0.6, 0.0), (0, 1, 0))
        bpy.context.view_layer.objects.active = splats
        depsgraph = bpy.context.evaluated_depsgraph_get()
        # `whole` recovers whole objects (same primitive order, so the images must agree bit for bit).
        live, whole = sync.SceneSync(depsgraph, interactive=True), sync.SceneSync(depsgraph, interactive=True)
        live.render_scene.build("FLAT")
        whole.render_scene.build("FLAT")
        faces = len(splats.data.polygons)
        uid = splats.as_pointer()
        changes, reads = [], []
        reader = mesh_read.read_edit_mode_positions

        def counted_reader(*args):
            reads.append(reader(*args))
            return reads[-1]

        handler = updating_live_and_whole(live, whole, changes)

        def image(scene_sync):
            return sorted_image(scene, scene_sync)

        def converted_positions():
            evaluated = splats.evaluated_get(bpy.context.evaluated_depsgraph_get())
            try:
                return polygon_mesh.mesh_arrays(evaluated.to_mesh())[0].copy()
            finally:
                evaluated.to_mesh_clear()

        def move(faces_moved, offset):
            import bmesh
            st.select_faces(splats, faces_moved)
            bmesh.update_edit_mesh(splats.data)
            bpy.context.view_layer.update()
            bpy.ops.transform.translate(value=offset)
            bpy.context.view_layer.update()

        before = image(live)
        bpy.app.handlers.depsgraph_update_post.append(handler)
        try:
            with mock.patch.object(mesh_read, "read_edit_mode_positions", side_effect=counted_reader):
                bpy.ops.object.mode_set(mode="EDIT")
                bpy.context.tool_settings.mesh_select_mode = (False, False, True)
                move((10, 11, 12, 400), (0.0, 0.0, 0.03))
                self.assertEqual(changes[-1], "updated")
                self.assertEqual(set(reads), {"read"})
                self.assertEqual(live.faces_recovered, 4)
                self.assertTrue(np.array_equal(live.sources[uid].arrays[0], converted_positions()))
                after = image(live)
                self.assertLessEqual(float(np.abs(after - image(whole)).max()), 1e-6)
                self.assertGreater(float(np.abs(after - before).max()), 1e-3)  # the edit shows
                # A second move reads into the spare arrays (the first move's source keeps its own).
                move((20,), (0.02, 0.0, 0.0))
                self.assertEqual(reads[-1], "read")
                self.assertEqual(live.faces_recovered, 1)
                self.assertTrue(np.array_equal(live.sources[uid].arrays[0], converted_positions()))
                self.assertLessEqual(float(np.abs(image(live) - image(whole)).max()), 1e-6)
                # Topology changed in Edit Mode: the mesh is read in full, and later moves read in place again.
                bpy.ops.mesh.delete(type="FACE")
                bpy.context.view_layer.update()
                self.assertEqual(reads[-1], "topology")
                self.assertEqual(live.stats.splats, faces - 1)
                move((30,), (0.0, 0.0, -0.02))
                self.assertEqual(reads[-1], "read")
                self.assertEqual(live.faces_recovered, 1)
                self.assertTrue(np.array_equal(live.sources[uid].arrays[0], converted_positions()))
                self.assertLessEqual(float(np.abs(image(live) - image(whole)).max()), 1e-6)
        finally:
            bpy.app.handlers.depsgraph_update_post.remove(handler)
            bpy.ops.object.mode_set(mode="OBJECT")

    def test_native_render_job_cancels_promptly(self):
        scene = new_scene(width=400, height=300, samples=4096)
        add_donut((0, 0, 0))
        add_camera((0.0, -0.6, 0.0), (0, 1, 0))
        from raysplats.engine import sync
        core = st.native()
        render_scene, _ = sync.build_render_scene(bpy.context.evaluated_depsgraph_get())
        camera = sync.camera_settings(scene, scene.camera, 400, 300)
        job = core.RenderJob(render_scene, camera, sync.render_settings(scene, 400, 300, 4096))
        # The reference, measured in this run under whatever load the machine has: the time to the first whole pass
        # (the scene's BVH build included). The job polls its cancel flag per tile, so a cancel must end it within
        # one pass; 3 passes leaves room for the load to change between the two measurements, and 1 s more for the
        # threads' wake-ups, which do not scale with the pass. The waits themselves are only hang guards (minutes).
        # 4096 samples would take minutes.
        start = time.perf_counter()
        while job.snapshot_samples < 1 and not job.wait(0.01) and time.perf_counter() - start < HANG_GUARD_SECONDS:
            pass
        first_pass = time.perf_counter() - start
        self.assertGreaterEqual(job.snapshot_samples, 1, f"no pass done in {first_pass:.0f} s")
        self.assertFalse(job.wait(0.0), "4096 samples done already")
        start = time.perf_counter()
        job.cancel()
        self.assertTrue(job.wait(HANG_GUARD_SECONDS))
        self.assertLess(time.perf_counter() - start, 3 * first_pass + 1.0,
                        f"the cancel took longer than 3 passes ({first_pass:.2f} s each in this run)")
        self.assertTrue(job.result()["cancelled"])


def sorted_image(scene, scene_sync, compositing="SORTED"):
    """The 96 x 72, 2-sample render (sorted compositing unless said otherwise) of `scene_sync`'s native scene through the scene's camera."""
    from raysplats.engine import sync
    settings = sync.render_settings(scene, 96, 72, 2)
    settings["compositing"] = compositing
    camera = sync.camera_settings(scene, scene.camera, 96, 72)
    return st.native().RenderJob(scene_sync.render_scene, camera, settings).result()["rgba"]


def updating_live_and_whole(live, whole, changes):
    """A depsgraph_update_post handler: `live` (an interactive SceneSync) applies each update as the viewport does,
    appending its result to `changes`; `whole` applies it recovering whole objects (and keeping the primitive order, so
    that the two render bit for bit alike)."""
    from raysplats.engine import sync

    def handler(scene_, depsgraph_):
        changes.append(live.update(depsgraph_))
        limit, sync.PARTIAL_RECOVERY_LIMIT = sync.PARTIAL_RECOVERY_LIMIT, -1
        try:
            whole.update(depsgraph_)
        finally:
            sync.PARTIAL_RECOVERY_LIMIT = limit
    return handler


def fresh_sync():
    """An interactive SceneSync built from scratch from the current depsgraph, reading every Gaussian object from its
    evaluated mesh (not through mesh_read.evaluated_mesh's datablock shortcut, whose reads it checks)."""
    from unittest import mock
    from raysplats.engine import sync
    with mock.patch.object(compat, "EVALUATED_MESH_COPIES_ON_READ", False):
        return sync.SceneSync(bpy.context.evaluated_depsgraph_get(), interactive=True)


def bpy_extras_world_to_camera(scene, camera, point):
    from bpy_extras.object_utils import world_to_camera_view
    return world_to_camera_view(scene, camera, point)
