# Persistent Data (Render Properties > Performance > Final Render, render.use_persistent_data) with the RaySplats
# engine: the frames of an animation keep the last frame's native scene and apply only what changed, and each such
# frame is bit for bit the frame a fresh render gives; the kept scene goes when the option is off or the file goes.
import gc
import unittest

import bpy
import mathutils
import numpy as np

import splat_testing as st
from raysplats.engine import final, sync

DONUT = "donut_sh0.ply"


def build_scene():
    """Two donuts (the second under an empty), a ground plane, a sun, and a camera that moves between frames 1
    and 2."""
    scene = st.reset_render_scene(96, 64, 2)
    scene.view_settings.view_transform = "Standard"
    world = bpy.data.worlds.new("World")
    st.set_world_color(world, (0.05, 0.05, 0.05))
    scene.world = world
    donuts = []
    for x in (-0.15, 0.15):
        obj = st.import_file(DONUT)
        obj.location = (x, 0.0, 0.0)
        donuts.append(obj)
    # The second donut hangs from an empty (as a split import's pieces do): moving the empty moves it.
    rig = bpy.data.objects.new("Rig", None)
    scene.collection.objects.link(rig)
    donuts[1].parent = rig
    bpy.ops.mesh.primitive_plane_add(size=2.0, location=(0.0, 0.0, -0.1))
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
    scene.collection.objects.link(sun)
    sun.rotation_euler = (0.4, 0.3, 0.0)
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    scene.collection.objects.link(camera)
    scene.camera = camera
    for frame, x in ((1, 0.0), (2, 0.05)):
        camera.location = (x, -0.9, 0.6)
        camera.rotation_euler = mathutils.Vector((-x, 0.9, -0.7)).to_track_quat("-Z", "Y").to_euler()
        camera.keyframe_insert("location", frame=frame)
        camera.keyframe_insert("rotation_euler", frame=frame)
    scene.frame_set(1)
    return scene, donuts


def edit_splats(obj):
    """Moves the first 10 splats' vertices a little (an edit of a few splats)."""
    co = np.empty(len(obj.data.vertices) * 3, dtype=np.float32)
    obj.data.vertices.foreach_get("co", co)
    co[:3 * 10 * 4] += 0.01
    obj.data.vertices.foreach_set("co", co)
    obj.data.update()


def render_sequence(persistent):
    """Frame 1, frame 2 (only the camera moved), then a donut moved by its parent empty, then a few splats of the
    other edited, then a light added: each frame's pixels and how its native scene was had."""
    scene, donuts = build_scene()
    scene.render.use_persistent_data = persistent
    images, hows = [], []

    def frame(name):
        images.append(st.render_to_array(f"persistent_{persistent}_{name}"))
        hows.append(final.last_render["scene"])

    frame("1")
    scene.frame_set(2)
    frame("2")
    donuts[1].parent.location.x += 0.03
    frame("moved")
    edit_splats(donuts[0])
    frame("edited")
    light = bpy.data.objects.new("Point", bpy.data.lights.new("Point", "POINT"))
    scene.collection.objects.link(light)
    light.location = (0.0, 0.0, 0.5)
    frame("light")
    return images, hows


def kept_scenes():
    gc.collect()
    # (type(), not isinstance(): the collected objects include Python wrappers of Blender data already freed,
    # which raise on any attribute access.)
    return sum(type(o) is sync.SceneSync for o in gc.get_objects())


def kept_frame_buffer_bytes():
    """Bytes of camera-ray splatting storage the kept scenes hold for their next frame."""
    gc.collect()
    return sum(o.render_scene.kept_frame_buffer_bytes for o in gc.get_objects() if type(o) is sync.SceneSync)


class PersistentData(unittest.TestCase):
    def test_frames_keep_what_did_not_change_and_equal_fresh_renders(self):
        kept_images, kept_hows = render_sequence(True)
        fresh_images, fresh_hows = render_sequence(False)
        self.assertEqual(fresh_hows, ["new"] * 5)
        # The camera-only frame keeps the scene as it is; a move and an edit are applied to it; a new light (which
        # it cannot apply in place) builds the scene anew.
        self.assertEqual(kept_hows, ["new", "kept", "updated", "updated", "new"])
        for name, kept, fresh in zip(("1", "2", "moved", "edited", "light"), kept_images, fresh_images):
            self.assertTrue(np.array_equal(kept, fresh), f"frame '{name}' with Persistent Data differs from a fresh "
                            f"render by up to {np.abs(kept - fresh).max()}")
        # Each change is visible, so that equality above means the change was applied.
        for before, after in zip(fresh_images, fresh_images[1:]):
            self.assertGreater(float(np.abs(after - before).max()), 1e-3)

    def test_the_kept_scene_is_released_when_the_option_is_off_or_the_file_goes(self):
        scene, _ = build_scene()
        scene.render.use_persistent_data = True
        st.render_to_array("persistent_release_1")
        self.assertEqual(kept_scenes(), 1, "Persistent Data keeps the frame's scene")
        # ... and its camera-ray splatting storage, which the next frame writes into instead of fresh memory.
        self.assertGreater(kept_frame_buffer_bytes(), 0)
        scene.render.use_persistent_data = False
        st.render_to_array("persistent_release_2")
        self.assertEqual(kept_scenes(), 0, "without Persistent Data nothing is kept after the frame")
        scene.render.use_persistent_data = True
        st.render_to_array("persistent_release_3")
        self.assertEqual(kept_scenes(), 1)
        st.reset_scene()
        self.assertEqual(kept_scenes(), 0, "loading a file releases the kept scene")

    def test_the_stages_of_a_frame_account_for_its_time(self):
        scene, _ = build_scene()
        scene.render.use_persistent_data = False
        st.render_to_array("stages")
        stages = final.last_render["stages"]
        for name in ("read", "convert", "scene", "bvh", "samples", "film", "write"):
            self.assertIn(name, stages)
            self.assertGreaterEqual(stages[name][0], 0.0)
            self.assertGreaterEqual(stages[name][1], 0.0)
        entered, left = final.last_render["entered"], final.last_render["left"]
        # The stages are parts of the engine's call: their wall seconds sum to no more than it took.
        self.assertLessEqual(sum(wall for _, wall in stages.values()), left[1] - entered[1] + 1e-3)
        self.assertGreater(stages["samples"][1], 0.0)


if __name__ == "__main__":
    unittest.main()
