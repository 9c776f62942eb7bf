# Frames that agree across workers: a frame's pixels depend on the scene and the frame only, not on the worker's
# thread count; Animate Seed varies the sampling seed per frame exactly as Cycles does (its hash of frame and seed),
# so a frame rendered alone on one worker equals the same frame of a whole-animation render on another.
import os
import unittest

import bpy
import numpy as np

import farm_testing as ft
from farm_testing import st
from raysplats.engine import sync

# Cycles' hash_uint2 (intern/cycles/util/hash.h, Bob Jenkins' lookup3 final mix) of (frame, seed), computed by that
# C function itself: the values Cycles' sync_integrator gives the integrator with Animate Seed on.
CYCLES_SEEDS = {(1, 0): 1267069554, (2, 0): 1001505576, (250, 0): 773244858, (1, 7): 4009661705,
                (-3, 7): 3205193008, (0, 2147483647): 1513101184}


class FrameSeeds(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.blend = st.tmp_file("frame_seeds/shot.blend")
        ft.build_shot(cls.blend, frames=(1, 3), width=48, height=32, samples=2)

    def setUp(self):
        bpy.ops.wm.open_mainfile(filepath=self.blend, load_ui=False)
        self.scene = bpy.context.scene

    def render(self, name, frame=1, threads=0):
        scene = self.scene
        scene.frame_set(frame)
        scene.render.threads_mode = "FIXED" if threads else "AUTO"
        if threads:
            scene.render.threads = threads
        scene.render.filepath = st.tmp_file(f"frame_seeds/{name}.png")
        scene.render.use_file_extension = False
        self.assertEqual(bpy.ops.render.render(write_still=True), {"FINISHED"})
        return ft.load_pixels(scene.render.filepath)

    def test_seed_is_cycles_hash_of_frame_and_seed(self):
        for (frame, seed), expected in CYCLES_SEEDS.items():
            self.assertEqual(sync._hash_uint2(frame, seed), expected, (frame, seed))
        settings = self.scene.raysplats
        settings.seed = 7
        settings.use_animated_seed = False
        self.scene.frame_set(1)
        self.assertEqual(sync.frame_seed(self.scene), 7)
        self.assertEqual(sync.render_settings(self.scene, 8, 8, 1)["seed"], 7)
        settings.use_animated_seed = True
        self.assertEqual(sync.frame_seed(self.scene), CYCLES_SEEDS[(1, 7)])
        self.assertEqual(sync.render_settings(self.scene, 8, 8, 1)["seed"], CYCLES_SEEDS[(1, 7)])
        # A subframe (motion blur steps) adds Cycles' second hash.
        self.scene.frame_set(1, subframe=0.5)
        expected = (CYCLES_SEEDS[(1, 7)] + sync._hash_uint2(int(0.5 * 2147483647.0), 7)) & 0xFFFFFFFF
        self.assertEqual(sync.frame_seed(self.scene), expected)

    def test_animated_seed_reaches_the_render(self):
        # Frame 1 with Animate Seed and seed 0 renders with seed hash(1, 0): the same image as a still with that seed.
        self.scene.raysplats.seed = 0
        animated = self.render("animated_frame1", frame=1)
        self.scene.raysplats.use_animated_seed = False
        self.scene.raysplats.seed = CYCLES_SEEDS[(1, 0)]
        still = self.render("still_seed", frame=1)
        self.assertEqual(np.abs(animated - still).max(), 0.0)
        # With the scene's seed 0 instead, the noise differs (2 samples: the seed shows).
        self.scene.raysplats.seed = 0
        self.assertGreater(np.abs(self.render("still_seed0", frame=1) - animated).max(), 0.01)

    def test_animated_seed_varies_noise_per_frame(self):
        # The camera stands still over frames 1..2 here, so only the seed can change the image.
        self.scene.animation_data_clear()
        for obj in self.scene.objects:
            obj.animation_data_clear()
        self.scene.raysplats.use_animated_seed = False
        self.assertEqual(np.abs(self.render("fixed_1", 1) - self.render("fixed_2", 2)).max(), 0.0)
        self.scene.raysplats.use_animated_seed = True
        self.assertGreater(np.abs(self.render("animated_1", 1) - self.render("animated_2", 2)).max(), 0.01)

    def test_thread_count_does_not_change_pixels(self):
        # Workers with 1, 2 and all threads (Blender's Auto), each its own process as on a farm (`blender -t N`).
        out = st.tmp_file("frame_seeds/threads")
        images = []
        for threads in (1, 2, 0):
            pattern = os.path.join(out, f"t{threads}_####")
            ft.run(ft.worker_command(self.blend, pattern, (2, 2), threads=threads))
            images.append(ft.load_pixels(ft.frame_path(pattern, 2)))
        self.assertGreater(np.count_nonzero(images[0][..., 3] > 0.05), images[0].shape[0] * images[0].shape[1] // 10)
        self.assertEqual(np.abs(images[0] - images[1]).max(), 0.0)
        self.assertEqual(np.abs(images[0] - images[2]).max(), 0.0)

    def test_frame_alone_equals_frame_of_the_animation(self):
        # Worker A renders frames 1..3 in one process, worker B frame 2 alone, in another: frame 2 agrees.
        out = st.tmp_file("frame_seeds/workers")
        ft.run(ft.worker_command(self.blend, os.path.join(out, "a_####"), (1, 3)))
        ft.run(ft.worker_command(self.blend, os.path.join(out, "b_####"), (2, 2), threads=1))
        a, b = (ft.load_pixels(ft.frame_path(os.path.join(out, f"{w}_####"), 2)) for w in "ab")
        self.assertEqual(np.abs(a - b).max(), 0.0)
        # And the frames of the animation differ (the camera moves): the comparison can fail.
        first = ft.load_pixels(ft.frame_path(os.path.join(out, "a_####"), 1))
        self.assertGreater(np.abs(first - a).max(), 0.05)
