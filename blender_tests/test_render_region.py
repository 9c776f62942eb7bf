# The render region (Output > Format > Render Region, with or without Crop to Render Region) and adaptive sampling
# (Render > Sampling > Noise Threshold) through F12 (engine/final.py): a region traces only its own pixels, which
# equal the whole frame's render there (the same seeds); uncropped, the rest of the frame is transparent, cropped
# the image is the region's size. Adaptive sampling reaches the core from the Sampling panel's settings.
import unittest

import bpy
import numpy as np

import splat_testing as st
from raysplats.engine import final, ui

DONUT = "donut_sh0.ply"
WIDTH, HEIGHT, SAMPLES = 96, 72, 4


def donut_scene(samples=SAMPLES):
    scene = st.reset_render_scene(WIDTH, HEIGHT, samples)
    st.import_file(DONUT)
    data = bpy.data.cameras.new("Camera")
    camera = bpy.data.objects.new("Camera", data)
    scene.collection.objects.link(camera)
    camera.location = (0.0, -0.6, 0.0)
    camera.rotation_euler = (1.5708, 0.0, 0.0)  # looking along +Y
    scene.camera = camera
    scene.render.film_transparent = False  # the world behind the donut: a region's outside must still be empty
    scene.raysplats.seed = 3
    return scene


def set_border(scene, crop):
    scene.render.use_border = True
    scene.render.use_crop_to_border = crop
    # Not on tile or 4 x 4 packet edges.
    scene.render.border_min_x, scene.render.border_max_x = 0.27, 0.71
    scene.render.border_min_y, scene.render.border_max_y = 0.15, 0.62


def border_pixels():
    """The border in image pixels, rows from the bottom as Blender (and its EXR rows as loaded) count them."""
    x0, x1 = int(np.float32(0.27) * np.float32(WIDTH)), int(np.float32(0.71) * np.float32(WIDTH))
    y0, y1 = int(np.float32(0.15) * np.float32(HEIGHT)), int(np.float32(0.62) * np.float32(HEIGHT))
    return x0, x1, y0, y1


class RenderRegion(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        donut_scene()
        cls.full = st.render_to_array("region_full")
        cls.full_rays = final.last_render["camera_rays"]

    def setUp(self):
        self.scene = donut_scene()

    def test_whole_frame_traces_every_pixel(self):
        self.assertEqual(self.full.shape, (HEIGHT, WIDTH, 4))
        self.assertEqual(self.full_rays, WIDTH * HEIGHT * SAMPLES)
        self.assertGreater(np.sum(self.full[..., 0] > 0.05), 200)  # the donut is in the frame

    def test_uncropped_region_renders_only_the_region_and_matches_the_whole_render(self):
        set_border(self.scene, crop=False)
        image = st.render_to_array("region_uncropped")
        x0, x1, y0, y1 = border_pixels()
        self.assertEqual(final.last_render["camera_rays"], (x1 - x0) * (y1 - y0) * SAMPLES)
        self.assertEqual(image.shape, (HEIGHT, WIDTH, 4))
        # Inside: the whole frame's pixels (the same samples, so equal to float precision).
        np.testing.assert_allclose(image[y0:y1, x0:x1], self.full[y0:y1, x0:x1], rtol=0, atol=1e-6)
        # Outside: nothing (Blender leaves the uncropped frame's rest transparent black).
        outside = np.ones((HEIGHT, WIDTH), dtype=bool)
        outside[y0:y1, x0:x1] = False
        self.assertEqual(float(np.abs(image[outside]).max()), 0.0)
        self.assertGreater(float(self.full[outside][:, 3].min()), 0.99)  # where the whole render is opaque

    def test_cropped_region_is_the_regions_pixels(self):
        set_border(self.scene, crop=True)
        image = st.render_to_array("region_cropped")
        x0, x1, y0, y1 = border_pixels()
        self.assertEqual(image.shape, (y1 - y0, x1 - x0, 4))
        self.assertEqual(final.last_render["camera_rays"], (x1 - x0) * (y1 - y0) * SAMPLES)
        np.testing.assert_allclose(image, self.full[y0:y1, x0:x1], rtol=0, atol=1e-6)


class AdaptiveSampling(unittest.TestCase):
    def render(self, use_adaptive, threshold=0.05, min_samples=16, samples=64):
        scene = donut_scene(samples)
        settings = scene.raysplats
        settings.use_adaptive_sampling = use_adaptive
        settings.adaptive_threshold = threshold
        settings.adaptive_min_samples = min_samples
        bpy.context.view_layer.raysplats_passes.use_pass_sample_count = True
        image = st.render_to_array("adaptive")
        return image, dict(final.last_render)

    def test_noise_threshold_stops_converged_pixels(self):
        _, on = self.render(True)
        self.assertGreaterEqual(on["mean_samples"], 16)
        self.assertLess(on["mean_samples"], 0.8 * 64)  # the world behind the donut is noise-free
        self.assertEqual(on["samples"], 64)  # the donut's edges took every sample

    def test_off_takes_every_sample(self):
        _, off = self.render(False)
        self.assertEqual(off["mean_samples"], 64)

    def test_sampling_panel_shows_the_noise_threshold(self):
        log = []

        class Layout:  # records the props a panel draws
            use_property_split = use_property_decorate = active = False

            def prop(self, owner, name, **kwargs):
                log.append((name, kwargs.get("text")))

            def column(self, **kwargs):
                return Layout()

            row = column

        st.reset_render_scene(8, 8, 1)
        ui.RAYSPLATS_RENDER_PT_sampling.draw(type("Panel", (), {"layout": Layout()})(), bpy.context)
        names = [name for name, _ in log]
        for name in ("use_adaptive_sampling", "adaptive_threshold", "samples", "adaptive_min_samples"):
            self.assertIn(name, names)
        self.assertIn(("samples", "Max Samples"), log)  # Cycles' label while the threshold is on

    def test_defaults_are_cycles(self):
        settings = st.reset_render_scene(8, 8, 1).raysplats
        self.assertTrue(settings.use_adaptive_sampling)
        self.assertAlmostEqual(settings.adaptive_threshold, 0.01, places=6)
        self.assertEqual(settings.adaptive_min_samples, 0)


if __name__ == "__main__":
    unittest.main()
