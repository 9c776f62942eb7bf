# Deformation blur (Object Properties > Motion Blur > Deformation, Object.cycles.use_deform_motion), in F12:
# - analytic: an emissive bar whose vertices (not its object) move at v pixels per frame, by an animated shape key or
#   by an armature's bone, smears as a moving object does: the image's variance along the motion grows by
#   (v shutter)^2 / 12 (within 3 %) and its total stays (within 1.5 %); with Deformation off it renders as with
#   motion blur off, bit for bit; the same for a polygon splat object whose Gaussians a shape key moves (the
#   Gaussians recovered from the polygons at each step);
# - against Cycles: a mesh scene with a cube sheared by an animated shape key during the shutter (512 samples): mean
#   absolute difference of the images within the tolerance below; with Deformation off RaySplats differs from
#   Cycles' blurred image by far more;
# - what is read: the vertices of a deforming mesh at each step (the frame put back afterwards), nothing for a still
#   mesh or with Deformation off, a textured mesh's steps mapped to its corner vertices as its frame's are, and a
#   mesh whose vertex count changes during the shutter is left sharp with a warning, as Cycles does;
# - with Persistent Data a kept scene renders each frame as a fresh one;
# - the Vector pass (motion blur off): a plane whose vertices a shape key moves reads its vertices' motion on the
#   image (within 1e-3 px), and only its object's with Deformation off.
import unittest
from types import SimpleNamespace

import bpy
import numpy as np

import splat_testing as st
from raysplats.engine import final, motion_blur, sync, ui
from test_motion_blur import (PIXELS_PER_UNIT, SPEED, assert_blur_agrees_with_cycles, assert_smear, emissive_cubes_scene,
                               ortho_scene, spread_x)
from test_vector_pass import base_scene, vector_and_position

SHUTTER = 0.5


def flat_bar(name="Bar"):
    """A thin emissive bar (2 x 30 pixels) at the origin, its size in its vertices (the object unscaled)."""
    mesh = bpy.data.meshes.new(name)
    half_w, half_h = 1.0 / PIXELS_PER_UNIT, 15.0 / PIXELS_PER_UNIT
    mesh.from_pydata([(-half_w, -half_h, 0.0), (half_w, -half_h, 0.0), (half_w, half_h, 0.0), (-half_w, half_h, 0.0)],
                     [], [(0, 1, 2, 3)])
    mesh.materials.append(st.emission_material(name))
    bar = bpy.data.objects.new(name, mesh)
    bpy.context.scene.collection.objects.link(bar)
    return bar


def shape_key_bar():
    """The bar moved along +X at SPEED by a shape key whose vertices are 1 unit to the right of the basis, its value
    driven by the frame (x = 0 at frame 5)."""
    bar = flat_bar()
    bar.shape_key_add(name="Basis")
    key = bar.shape_key_add(name="Right")
    for point in key.data:
        point.co.x += 1.0
    key.slider_min, key.slider_max = -10.0, 10.0
    st.drive(bar.data.shape_keys, 'key_blocks["Right"].value', -1, f"(frame - 5) * {SPEED}")
    bpy.context.scene.frame_set(5)
    return bar


def armature_bar():
    """The bar moved along +X at SPEED by an armature's bone (an Armature modifier, every vertex weighted 1), the
    bone's location driven by the frame (x = 0 at frame 5)."""
    bar = flat_bar()
    armature = bpy.data.objects.new("Rig", bpy.data.armatures.new("Rig"))
    bpy.context.scene.collection.objects.link(armature)
    bpy.context.view_layer.objects.active = armature
    bpy.ops.object.mode_set(mode="EDIT")
    bone = armature.data.edit_bones.new("Bone")
    bone.head, bone.tail = (0.0, 0.0, 0.0), (0.0, 1.0, 0.0)  # along +Y: the bone's X is the world's X
    bpy.ops.object.mode_set(mode="OBJECT")
    group = bar.vertex_groups.new(name="Bone")
    group.add(range(len(bar.data.vertices)), 1.0, "REPLACE")
    bar.modifiers.new("Armature", "ARMATURE").object = armature
    st.drive(armature, 'pose.bones["Bone"].location', 0, f"(frame - 5) * {SPEED}")
    bpy.context.scene.frame_set(5)
    return bar


class DeformedBar(unittest.TestCase):
    def check_smear(self, make_bar, name):
        scene = ortho_scene()
        bar = make_bar()
        scene.render.use_motion_blur = False
        still = spread_x(st.render_to_array(f"deform_{name}_still"))
        scene.render.use_motion_blur = True
        scene.render.motion_blur_shutter = SHUTTER
        moving = spread_x(st.render_to_array(f"deform_{name}_blurred"))
        assert_smear(self, f"Deformed bar ({name})", still, moving, SHUTTER)
        self.assertAlmostEqual(moving[1], still[1], delta=0.3)
        self.assertEqual((scene.frame_current, scene.frame_subframe), (5, 0.0))
        return scene, bar

    def test_shape_key_smears_by_speed_times_shutter(self):
        self.check_smear(shape_key_bar, "shape_key")

    def test_armature_smears_by_speed_times_shutter(self):
        self.check_smear(armature_bar, "armature")

    def test_deformation_switch_and_seed(self):
        scene = ortho_scene(16)
        bar = shape_key_bar()
        scene.render.use_motion_blur = False
        off = st.render_to_array("deform_switch_off")
        scene.render.use_motion_blur = True
        bar.cycles.use_deform_motion = False  # Object Properties > Motion Blur > Deformation
        np.testing.assert_array_equal(st.render_to_array("deform_switch_object_off"), off)
        bar.cycles.use_deform_motion = True
        blurred = st.render_to_array("deform_switch_on")
        self.assertFalse(np.array_equal(blurred, off))
        np.testing.assert_array_equal(st.render_to_array("deform_switch_on_again"), blurred)  # one frame per seed
        bar.cycles.use_motion_blur = False  # the object's motion blur off leaves its deformation sharp too
        np.testing.assert_array_equal(st.render_to_array("deform_switch_motion_off"), off)


def shape_key_splats():
    """donut_sh0.ply as one polygon splat object (about 32 pixels across) whose Gaussians a shape key moves along +X
    at SPEED (every vertex 1 unit to the right in the key, its value driven by the frame: x = 0.5 at frame 5, so that
    at every time of the shutter its faces are off their imported shape and recovered alike, by moments)."""
    obj = st.import_file("donut_sh0.ply", representation="POLYGONS")
    obj.scale = (5.0, 5.0, 5.0)
    obj.shape_key_add(name="Basis")
    key = obj.shape_key_add(name="Right")
    positions = np.empty(len(key.data) * 3, dtype=np.float32)
    key.data.foreach_get("co", positions)
    positions[0::3] += 1.0 / obj.scale.x  # (the key is in the object's frame)
    key.data.foreach_set("co", positions)
    key.slider_min, key.slider_max = -10.0, 10.0
    st.drive(obj.data.shape_keys, 'key_blocks["Right"].value', -1, f"0.5 + (frame - 5) * {SPEED}")
    bpy.context.scene.frame_set(5)
    return obj


class DeformedSplats(unittest.TestCase):
    def test_shape_key_moves_the_gaussians_by_speed_times_shutter(self):
        scene = ortho_scene(128)
        obj = shape_key_splats()
        scene.render.use_motion_blur = False
        still = spread_x(st.render_to_array("deform_splats_still"))
        scene.render.use_motion_blur = True
        scene.render.motion_blur_shutter = SHUTTER
        image = st.render_to_array("deform_splats_blurred")
        edges = image[:, :4, :3].sum() + image[:, -4:, :3].sum()
        self.assertLess(edges, 1e-3 * still[0], "the smear stays inside the frame")
        assert_smear(self, "Deformed splats (shape key)", still, spread_x(image), SHUTTER)
        # One frame per seed; Deformation off: the still image, bit for bit.
        scene.raysplats.samples = 8
        blurred = st.render_to_array("deform_splats_seed")
        np.testing.assert_array_equal(st.render_to_array("deform_splats_seed_again"), blurred)
        obj.cycles.use_deform_motion = False
        sharp = st.render_to_array("deform_splats_off")
        scene.render.use_motion_blur = False
        np.testing.assert_array_equal(sharp, st.render_to_array("deform_splats_blur_off"))
        self.assertFalse(np.array_equal(sharp, blurred))


class PersistentData(unittest.TestCase):
    def test_kept_scene_renders_as_fresh(self):
        # Persistent Data keeps the native scene between renders: frames 5 and 6 with motion blur, then 6 without, of
        # a deforming bar and a deforming polygon splat object, each equal to a render that built its scene anew.
        images = {}
        for persistent in (False, True):
            scene = ortho_scene(8)
            shape_key_bar()
            shape_key_splats()
            scene.render.use_persistent_data = persistent
            for frame, blur in ((5, True), (6, True), (6, False)):
                scene.frame_set(frame)
                scene.render.use_motion_blur = blur
                images[persistent, frame, blur] = st.render_to_array(f"deform_persistent_{persistent}_{frame}_{blur}")
            self.assertEqual(final.last_render["scene"] != "new", persistent)
        for frame, blur in ((5, True), (6, True), (6, False)):
            np.testing.assert_array_equal(images[True, frame, blur], images[False, frame, blur])
        self.assertFalse(np.array_equal(images[False, 6, True], images[False, 6, False]))


class VectorPass(unittest.TestCase):
    def test_deforming_mesh_gives_its_vertices_motion(self):
        # Motion blur off, View Layer > Passes > Vector: a plane whose vertices a shape key moves 30 px a frame along
        # +X, under an orthographic camera moving 15 px a frame along +Y, reads (-30, +15, -30, +15) where it is seen
        # (1e-3 px); with Deformation off, the camera's motion alone (0, +15, 0, +15).
        scene = base_scene("ORTHO")
        bpy.ops.mesh.primitive_plane_add(size=1.0)
        plane = bpy.context.object
        plane.data.materials.append(st.emission_material("Plane"))
        plane.shape_key_add(name="Basis")
        key = plane.shape_key_add(name="Right")
        for point in key.data:
            point.co.x += 1.0
        key.slider_min, key.slider_max = -10.0, 10.0
        st.drive(plane.data.shape_keys, 'key_blocks["Right"].value', -1, "(frame - 5) * 1.0")
        st.drive(scene.camera, "location", 1, "(frame - 5) * 0.5")
        scene.frame_set(5)
        for deform, expected in ((True, (-30.0, 15.0, -30.0, 15.0)), (False, (0.0, 15.0, 0.0, 15.0))):
            plane.cycles.use_deform_motion = deform
            vector, position = vector_and_position(st.render_multilayer_exr(f"deform_vector_{deform}"))
            covered = np.any(position != 0.0, axis=-1)
            self.assertGreater(int(covered.sum()), 200, "the plane is in view")
            error = np.abs(vector[covered] - np.array(expected, dtype=np.float32)).max()
            print(f"\nVector of a deforming plane (Deformation {'on' if deform else 'off'}), Blender "
                  f"{bpy.app.version_string}: {int(covered.sum())} px covered, max |error| {error:.2e} px")
            self.assertLess(error, 1e-3)
        self.assertEqual(scene.frame_current, 5)


class Reading(unittest.TestCase):
    """motion_blur.shutter_motion with Blender's own scene standing in for the engine (RenderEngine.frame_set and
    Scene.frame_set take the same frame and subframe)."""

    def shutter_motion(self, scene):
        stand_in = SimpleNamespace(frame_set=lambda frame, subframe: scene.frame_set(frame, subframe=subframe))
        motion = motion_blur.shutter_motion(stand_in, bpy.context.evaluated_depsgraph_get())
        self.assertEqual((scene.frame_current, scene.frame_subframe), (5, 0.0))
        return motion

    def test_deforming_meshes_only_and_their_steps(self):
        scene = ortho_scene(1)
        scene.render.use_motion_blur = True
        scene.render.motion_blur_shutter = SHUTTER
        bar = shape_key_bar()
        still = flat_bar("Still")
        still.modifiers.new("Subdivision", "SUBSURF")  # may deform (a modifier), but does not
        motion = self.shutter_motion(scene)
        key = motion_blur.instance_key(SimpleNamespace(object=bar, is_instance=False))
        self.assertEqual(set(motion.deformation), {key})
        self.assertEqual(motion.objects, {}, "the objects themselves do not move")
        steps = motion.deformation[key]
        self.assertEqual(steps.shape, (3, 4, 3))
        basis = np.array([v.co for v in bar.data.vertices], dtype=np.float32)
        for k, offset in enumerate((-0.5, 0.0, 0.5)):  # the shutter's times: 5 -+ SHUTTER / 2
            np.testing.assert_allclose(steps[k], basis + [offset * SHUTTER * SPEED, 0.0, 0.0], atol=1e-6)
        bar.cycles.use_deform_motion = False
        self.assertEqual(self.shutter_motion(scene).deformation, {})
        self.assertEqual(motion.warnings, [])

    def test_textured_mesh_steps_follow_its_corner_vertices(self):
        # A textured mesh is given to the core with one vertex per triangle corner (its UVs): its steps are mapped
        # the same way, so that the middle step (the frame) is exactly the frame's vertices.
        scene = ortho_scene(1)
        scene.render.use_motion_blur = True
        bar = shape_key_bar()
        bar.data.uv_layers.new(name="UVMap")
        material = bpy.data.materials.new("Textured")
        material.use_nodes = True
        texture = material.node_tree.nodes.new("ShaderNodeTexImage")
        texture.image = bpy.data.images.new("Texture", 4, 4)
        material.node_tree.links.new(texture.outputs["Color"],
                                     material.node_tree.nodes["Principled BSDF"].inputs["Base Color"])
        bar.data.materials[0] = material
        motion = self.shutter_motion(scene)
        scene_sync = sync.SceneSync(bpy.context.evaluated_depsgraph_get())
        index, arrays = scene_sync.meshes[bar.as_pointer()]
        self.assertIsNotNone(scene_sync.vertex_maps[index][1], "one vertex per corner")
        steps = scene_sync._mesh_steps(index, motion.deformation[motion_blur.instance_key(
            SimpleNamespace(object=bar, is_instance=False))])
        self.assertEqual(steps.shape, (3, 6, 3))
        np.testing.assert_array_equal(steps[1], arrays[0])
        np.testing.assert_allclose(steps[2] - steps[0], np.tile([SHUTTER * SPEED, 0.0, 0.0], (6, 1)), atol=1e-6)

    def test_changed_vertex_count_is_left_sharp_with_a_warning(self):
        scene = ortho_scene(1)
        scene.render.use_motion_blur = True
        bpy.ops.mesh.primitive_uv_sphere_add(segments=32, ring_count=16)
        sphere = bpy.context.object
        decimate = sphere.modifiers.new("Decimate", "DECIMATE")
        st.drive(sphere, 'modifiers["Decimate"].ratio', -1, "0.5 + 0.2 * (frame - 5)")
        scene.frame_set(5)
        motion = self.shutter_motion(scene)
        self.assertEqual(motion.deformation, {})
        self.assertEqual(motion.warnings, [f"Object '{sphere.name}': its vertex count changes during the shutter; "
                                           "its deformation is not blurred"])
        self.assertIsNotNone(decimate)
        # The render's scene reports it (engine.report), once.
        warnings = []
        scene_sync = sync.SceneSync(bpy.context.evaluated_depsgraph_get(), warn=warnings.append)
        scene_sync.apply_motion(motion)
        scene_sync.apply_motion(motion)
        self.assertEqual(warnings, motion.warnings)


class Panel(unittest.TestCase):
    def test_object_panel_draws_the_deformation_switch(self):
        scene = ortho_scene(1)
        bar = flat_bar()
        context = SimpleNamespace(engine=scene.render.engine, scene=scene, object=bar)
        drawn = []
        stand_in = SimpleNamespace(layout=st.RecordingLayout(drawn))
        ui.RAYSPLATS_OBJECT_PT_motion_blur.draw(stand_in, context)
        self.assertIn("use_deform_motion", {name for _, name, _ in drawn})


def sheared_cube_scene():
    """Emissive cubes on a dark world seen from above by a perspective camera: one whose top is sheared along +X by an
    animated shape key (0.6 units per frame at its top face), one still; frame 5, shutter 1."""
    scene, sheared, camera = emissive_cubes_scene((-0.6, 0.0, 0.0))
    sheared.shape_key_add(name="Basis")
    key = sheared.shape_key_add(name="Shear")
    for point in key.data:
        point.co.x += point.co.z + 0.4  # 0 at the bottom face, 0.8 at the top
    key.slider_min, key.slider_max = -10.0, 10.0
    st.drive(sheared.data.shape_keys, 'key_blocks["Shear"].value', -1, "0.5 + (frame - 5) * 0.75")
    camera.location = (0.0, 0.0, 6.0)
    scene.frame_set(5)
    scene.render.use_motion_blur = True
    scene.render.motion_blur_shutter = 1.0
    return scene, sheared


class AgainstCycles(unittest.TestCase):
    def test_shape_key_deformation_agrees_with_cycles(self):
        scene, sheared = sheared_cube_scene()
        assert_blur_agrees_with_cycles(self, scene, "Deformation blur",
                                       lambda: setattr(sheared.cycles, "use_deform_motion", False))


if __name__ == "__main__":
    unittest.main()
