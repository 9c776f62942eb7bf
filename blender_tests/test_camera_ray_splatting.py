# Render Properties > Gaussians > Camera Rays as Splats (scene.raysplats.camera_ray_splatting) reaches the core
# through F12 (engine/final.py, engine/sync.py): with it on, the render's camera rays are splatted (the core says
# so) and the image is the native render with the setting, not the traced one; off (the default), it is the traced
# render. A relit object keeps camera rays traced, with a warning.
import unittest
from unittest import mock

import bpy
import numpy as np

import splat_testing as st
from raysplats import native
from raysplats.engine import final, sync, ui, viewport

DONUT = "donut_sh0.ply"
WIDTH, HEIGHT = 96, 72


def donut_scene():
    scene = st.reset_render_scene(WIDTH, HEIGHT, 2)
    st.import_file(DONUT)
    data = bpy.data.cameras.new("Camera")
    camera = bpy.data.objects.new("Camera", data)
    scene.collection.objects.link(camera)
    camera.location = (0.0, -0.6, 0.0)
    camera.rotation_euler = (1.5708, 0.0, 0.0)  # looking along +Y (as test_render_region.py)
    scene.camera = camera
    scene.raysplats.gaussian_mode = "VOLUMETRIC"
    return scene


class _RecordingLayout:
    def __init__(self, log=None):
        self.log = [] if log is None else log
        self.use_property_split = self.use_property_decorate = False
        self.active = True

    def prop(self, owner, name, **kwargs):
        self.log.append(name)

    def column(self, **kwargs):
        return _RecordingLayout(self.log)

    row = box = column


class CameraRaySplatting(unittest.TestCase):
    def setUp(self):
        self.scene = donut_scene()

    def test_on_by_default_and_in_the_gaussians_panel(self):
        self.assertTrue(self.scene.raysplats.camera_ray_splatting)
        self.assertTrue(sync.render_settings(self.scene, 8, 8, 1)["camera_ray_splatting"])
        self.scene.raysplats.camera_ray_splatting = False
        self.assertFalse(sync.render_settings(self.scene, 8, 8, 1)["camera_ray_splatting"])
        self.assertIn("camera_ray_splatting", {s["name"] for s in st.native().render_settings()})
        self.assertIn("camera_ray_splatting", {s["name"] for s in st.native().render_settings()})
        panel = type("Panel", (), {"layout": _RecordingLayout()})()
        ui.RAYSPLATS_RENDER_PT_gaussians.draw(panel, bpy.context)
        self.assertIn("camera_ray_splatting", panel.layout.log)

    def test_f12_splats_camera_rays_when_on(self):
        self.scene.raysplats.camera_ray_splatting = False
        traced = st.render_to_array("splatting_off")
        self.assertFalse(final.last_render["camera_ray_splatting"])
        self.scene.raysplats.camera_ray_splatting = True
        splatted = st.render_to_array("splatting_on")
        self.assertTrue(final.last_render["camera_ray_splatting"])
        self.assertGreater(final.last_render["splat_prepass_seconds"], 0.0)
        self.assertGreater(np.sum(splatted[..., 3] > 0.5), 200)  # the donut is in the frame
        # The two models differ on the donut's soft edges, by a little: not the same image, nor another scene.
        difference = np.abs(splatted[..., :3] - traced[..., :3])
        self.assertGreater(difference.max(), 1e-3)
        self.assertLess(difference.mean(), 0.02)

    def test_the_viewport_preview_is_traced_and_its_passes_splatted(self):
        # The quarter-resolution first image of a view or an edit comes quickly (no pre-pass over every Gaussian);
        # the passes that replace it follow the setting.
        started = []
        real_job = st.native().RenderJob

        def recording_job(render_scene, camera, settings, **options):
            started.append(settings["camera_ray_splatting"])
            return real_job(render_scene, camera, settings, **options)

        state = viewport.ViewportState()
        state.sync = sync.SceneSync(bpy.context.evaluated_depsgraph_get(), interactive=True)
        camera = {"matrix": np.array(self.scene.camera.matrix_world, dtype=np.float32), "type": "PERSP",
                  "lens": 50.0, "sensor_width": 36.0}
        engine = type("Engine", (), {})()
        self.scene.raysplats.camera_ray_splatting = False
        with mock.patch.object(native.core(), "RenderJob", recording_job), \
                mock.patch.object(viewport, "_start_polling", lambda engine, state: None):
            viewport._start_preview(engine, state, self.scene, "key", camera, 16, 12)
            state.job.wait(60.0)
            self.scene.raysplats.camera_ray_splatting = True
            viewport._start_job(engine, state, self.scene, camera, 64, 48, 1, seed_offset=1)
            state.job.wait(60.0)
        self.assertEqual(started, [False, True])
        # The viewport's scene keeps the splatted render's storage for its next render.
        self.assertGreater(state.sync.render_scene.kept_frame_buffer_bytes, 0)

    def test_a_relit_object_keeps_camera_rays_traced(self):
        self.scene.raysplats.camera_ray_splatting = True
        self.scene.raysplats.gaussian_shading = "LIT"
        st.render_to_array("splatting_lit")
        self.assertFalse(final.last_render["camera_ray_splatting"])


if __name__ == "__main__":
    unittest.main()
