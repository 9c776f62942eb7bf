# F12 shows progress and keeps it (engine/final.py): the render window gets the film of the sample passes done as
# they complete (RenderEngine.update_result), and Esc ends the render keeping them (end_result with the image), as
# Cycles does. final.render_final is driven with a stand-in for Blender's RenderEngine that records what the render
# window would be given and presses Esc (test_break) when told to.
import time
import unittest
from unittest import mock

import bpy
import numpy as np

import splat_testing as st
from raysplats.blender import compat
from raysplats.engine import final, sync

DONUT = "donut_sh0.ply"


class _Rect(np.ndarray):
    """A pass's pixels, written as Blender's RenderPass.rect is: in bulk by foreach_set, which checks the buffer's
    length against the pass's values from 4.2 on and against its pixels before (compat.RENDER_PASS_BUFFER_IS_FLAT)."""

    def foreach_set(self, values):
        expected = self.size if compat.RENDER_PASS_BUFFER_IS_FLAT else self.shape[0]
        if len(values) != expected:
            raise TypeError(f"expected sequence size {expected}, got {len(values)}")
        self.reshape(-1)[:] = np.asarray(values).reshape(-1)


class _Pass:
    def __init__(self, name, channels, pixels):
        self.name, self.channels = name, channels
        self.rect = np.zeros((pixels, channels), dtype=np.float32).view(_Rect)


class _Passes(dict):
    def get(self, name, default=None):
        return super().get(name, default)


class _Layer:
    def __init__(self, width, height):
        self.passes = _Passes(Combined=_Pass("Combined", 4, width * height))


class _Result:
    def __init__(self, width, height):
        self.resolution_x, self.resolution_y = width, height
        self.layers = [_Layer(width, height)]


class RecordingEngine:
    """What final.render_final calls on a RenderEngine; records the images given to the render window (copies of
    Combined at each update_result and at end_result) and answers test_break with True once `esc_after_updates`
    partial results were shown, or after `esc_after_seconds` in any case (a hang guard of minutes, so that a render
    that shows none fails the test instead of running for hours; never reached by a slow machine's render)."""

    def __init__(self, esc_after_updates=None, esc_after_seconds=300.0):
        self.esc_after_updates = esc_after_updates
        self.esc_at = time.perf_counter() + esc_after_seconds
        self.partial_images, self.final_image, self.ended_cancelled = [], None, None
        self.result = None

    def begin_result(self, x, y, w, h):
        self.result = _Result(w, h)
        return self.result

    def update_result(self, result):
        self.partial_images.append(result.layers[0].passes["Combined"].rect.copy())

    def end_result(self, result, cancel=False):
        self.final_image = result.layers[0].passes["Combined"].rect.copy()
        self.ended_cancelled = cancel

    def test_break(self):
        if self.esc_after_updates is None:
            return False
        return len(self.partial_images) >= self.esc_after_updates or time.perf_counter() > self.esc_at

    def update_progress(self, value):
        pass

    def update_stats(self, stats, info):
        pass

    def report(self, kind, message):
        pass


def donut_scene(samples):
    scene = st.reset_render_scene(64, 48, samples)
    st.import_file(DONUT)
    data = bpy.data.cameras.new("Camera")
    camera = bpy.data.objects.new("Camera", data)
    scene.collection.objects.link(camera)
    camera.location = (0.0, -0.6, 0.0)
    camera.rotation_euler = (1.5708, 0.0, 0.0)  # looking along +Y
    scene.camera = camera
    return scene


def coverage(image):
    return float(np.sum(image[:, 3] > 0.0)) if image is not None else 0.0


class FinalRenderProgress(unittest.TestCase):
    def render(self, engine):
        with mock.patch.object(final, "UPDATE_SECONDS", 0.0):  # every pass shown (the default: at most 1/s)
            final.render_final(engine, bpy.context.evaluated_depsgraph_get())

    def test_esc_keeps_the_passes_done_after_partial_results(self):
        donut_scene(samples=1 << 16)  # hours of passes unless Esc ends them
        engine = RecordingEngine(esc_after_updates=2)
        self.render(engine)
        self.assertGreaterEqual(len(engine.partial_images), 2)
        for image in engine.partial_images:
            self.assertGreater(coverage(image), 100)  # each partial result is a whole image of the donut
        self.assertIsNotNone(engine.final_image, "Esc threw the render away (no end_result)")
        self.assertFalse(engine.ended_cancelled, "end_result(cancel=True) discards the image in Blender")
        self.assertGreater(coverage(engine.final_image), 100)
        self.assertTrue(final.last_render["cancelled"])
        self.assertGreaterEqual(final.last_render["samples"], 2)
        self.assertLess(final.last_render["samples"], 1 << 16)

    def test_partial_results_refine_to_the_render_of_all_samples(self):
        scene = donut_scene(samples=12)
        engine = RecordingEngine()
        self.render(engine)
        self.assertFalse(final.last_render["cancelled"])
        self.assertEqual(final.last_render["samples"], 12)
        shown = [samples for _, samples in final.last_render["partial_results"]]
        self.assertEqual(shown, sorted(set(shown)))  # newer passes each time
        self.assertTrue(all(1 <= samples < 12 for samples in shown))
        self.assertEqual(len(engine.partial_images), len(shown))
        # The image kept is the full render's, bit for bit (rows bottom to top in Blender).
        depsgraph = bpy.context.evaluated_depsgraph_get()
        render_scene, _ = sync.build_render_scene(depsgraph)
        camera = sync.camera_settings(scene, scene.camera.evaluated_get(depsgraph), 64, 48)
        film = st.native().RenderJob(render_scene, camera, sync.render_settings(scene, 64, 48, 12)).result()
        np.testing.assert_array_equal(engine.final_image, film["rgba"][::-1].reshape(-1, 4))


class FinalRenderFailure(unittest.TestCase):
    """A failure inside the render (here injected: writing a pass into Blender's result raises) ends Blender's result
    cancelled (no half-written result left open) and stops the render thread at once."""

    def render_failing(self, engine, update_seconds):
        jobs, make_job = [], st.native().RenderJob

        def recording_job(*args, **kwargs):
            jobs.append(make_job(*args, **kwargs))
            return jobs[-1]

        with mock.patch.object(final, "UPDATE_SECONDS", update_seconds), \
                mock.patch.object(st.native(), "RenderJob", recording_job), \
                mock.patch.object(final.passes, "write_passes", side_effect=RuntimeError("pass 'Depth' not found")), \
                self.assertRaisesRegex(RuntimeError, "pass 'Depth' not found"):
            final.render_final(engine, bpy.context.evaluated_depsgraph_get())
        self.assertEqual(len(jobs), 1)
        return jobs[0]

    def test_failure_while_showing_a_partial_result(self):
        donut_scene(samples=1 << 16)  # hours of passes unless the failure stops them
        engine = RecordingEngine()
        job = self.render_failing(engine, update_seconds=0.0)
        self.assertTrue(engine.ended_cancelled)
        self.assertTrue(job.wait(60.0), "the render thread went on after the failure")
        self.assertTrue(job.result()["cancelled"])

    def test_failure_while_writing_the_final_image(self):
        donut_scene(samples=2)
        engine = RecordingEngine()
        self.render_failing(engine, update_seconds=1e9)
        self.assertTrue(engine.ended_cancelled)
        self.assertEqual(engine.partial_images, [])


if __name__ == "__main__":
    unittest.main()
