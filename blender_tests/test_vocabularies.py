# The add-on reads the core's vocabularies rather than restating them: splat formats (file browser filter,
# menu text, import up axis) and camera models (panoramic cameras of both Blender versions).
import unittest

import bpy

from raysplats import axes, io_import, native
from raysplats.engine import sync


class Vocabularies(unittest.TestCase):
    def test_splat_formats_come_from_the_core(self):
        extensions = [e for f in native.core().splat_formats() for e in f["extensions"]]
        self.assertEqual(extensions[:3], [".ply", ".splat", ".spz"])
        self.assertIn(".glb", extensions)
        self.assertIn(".gltf", extensions)
        self.assertIn(".compressed.ply", extensions)
        self.assertEqual(io_import.splat_file_browser_filter(), ";".join("*" + e for e in extensions))
        self.assertEqual(io_import.splat_menu_text(), f"Gaussian Splats ({'/'.join(extensions)})")
        # The automatic import up axis is the same for every format: the readers return COLMAP's -Y up (SPZ's RUB is
        # converted on reading), so the up axis is the scene's, not the format's.
        self.assertEqual(axes.resolve_import_up_axis("AUTO", io_import.splat_format_of("/scans/A.SPZ")), "-Y")
        self.assertEqual(axes.resolve_import_up_axis("AUTO", io_import.splat_format_of("/scans/a.splat")), "-Y")
        self.assertEqual(axes.resolve_import_up_axis("Z", io_import.splat_format_of("/scans/a.spz")), "Z")
        self.assertIsNone(io_import.splat_format_of("/scans/a.xyz"))
        # Detection: a decided estimate wins over the convention, except where the format's specification fixes up.
        found_z, unsure_z = {"axis": "Z", "decided": True}, {"axis": "Z", "decided": False}
        ply, glb = io_import.splat_format_of("/scans/a.ply"), io_import.splat_format_of("/scans/a.glb")
        self.assertEqual(axes.resolve_import_up_axis("DETECT", ply, found_z), "Z")
        self.assertEqual(axes.resolve_import_up_axis("DETECT", ply, unsure_z), "-Y")
        self.assertEqual(axes.resolve_import_up_axis("DETECT", glb, found_z), "-Y")
        self.assertEqual(axes.resolve_import_up_axis("AUTO", ply, found_z), "-Y")
        self.assertFalse(axes.detection_wanted("DETECT", glb))
        self.assertEqual(io_import.splat_format_of("/scans/a.compressed.ply")["name"], "compressed_ply")

    def test_every_camera_type_renders_by_the_cores_name(self):
        camera = bpy.data.cameras.new("Vocabulary camera")
        obj = bpy.data.objects.new("Vocabulary camera", camera)
        bpy.context.scene.collection.objects.link(obj)
        panoramic = camera if hasattr(camera, "panorama_type") else camera.raysplats  # Blender 4 / 3
        core = native.core()
        scene = core.RenderScene()
        scene.add_material()
        settings = sync.render_settings(bpy.context.scene, 16, 12, 1)
        for camera_type, panorama in (("PERSP", None), ("ORTHO", None), ("PANO", "EQUIRECTANGULAR"),
                                      ("PANO", "FISHEYE_EQUIDISTANT"), ("PANO", "FISHEYE_EQUISOLID")):
            camera.type = camera_type
            if panorama:
                panoramic.panorama_type = panorama
            description = sync.camera_settings(bpy.context.scene, obj, 16, 12)
            self.assertEqual(description["type"], panorama or camera_type)
            film = core.RenderJob(scene, description, settings).result()
            self.assertEqual(film["rgba"].shape, (12, 16, 4))

    def test_misspelt_render_setting_is_reported(self):
        scene = native.core().RenderScene()
        camera = {"type": "PERSP"}
        settings = dict(sync.render_settings(bpy.context.scene, 16, 12, 1))
        settings["sample"] = settings.pop("samples")
        with self.assertRaises(ValueError) as raised:
            native.core().RenderJob(scene, camera, settings)
        self.assertIn("unknown render setting 'sample' (known: width, height, samples,", str(raised.exception))
