# The add-on reads the core's vocabularies rather than restating them: splat formats (file browser filter,
# menu text, import up axis) and camera models (panoramic cameras of both Blender versions).
import unittest

import bpy

from raysplats.io import format_table
from raysplats.objects import axes
from raysplats import native
from raysplats.engine import sync


class Vocabularies(unittest.TestCase):
    def test_splat_formats_come_from_the_core(self):
        extensions = [e for f in native.core().splat_formats() for e in f["extensions"]]
        self.assertEqual(extensions[:3], [".ply", ".splat", ".spz"])
        for extension in (".glb", ".gltf", ".compressed.ply", ".sog", "meta.json"):
            self.assertIn(extension, extensions)
        self.assertEqual(format_table.splat_file_browser_filter(), ";".join("*" + e for e in extensions))
        self.assertEqual(format_table.splat_menu_text(), f"Gaussian Splats ({'/'.join(extensions)})")
        # Export offers what the core writes: SOG and glTF (the mesh export writes glTF splats) are read only here.
        writable = format_table.splat_extensions(writable_only=True)
        self.assertNotIn(".sog", writable)
        self.assertNotIn(".glb", writable)
        self.assertIn(".compressed.ply", writable)
        self.assertEqual(format_table.splat_format_of("/scans/unicorn/META.JSON")["name"], "sog")
        self.assertIsNone(format_table.splat_format_of("/scans/unicorn/meta.json", writable_only=True))
        self.assertIsNone(format_table.splat_format_of("/scans/settings.json"))
        # The automatic import up axis is the same for every format: the readers return COLMAP's -Y up (SPZ's RUB is
        # converted on reading), so the up axis is the scene's, not the format's.
        self.assertEqual(axes.resolve_import_up_axis("AUTO", format_table.splat_format_of("/scans/A.SPZ")), "-Y")
        self.assertEqual(axes.resolve_import_up_axis("AUTO", format_table.splat_format_of("/scans/a.splat")), "-Y")
        self.assertEqual(axes.resolve_import_up_axis("Z", format_table.splat_format_of("/scans/a.spz")), "Z")
        self.assertIsNone(format_table.splat_format_of("/scans/a.xyz"))
        # Detection: a decided estimate wins over the convention, except where the format's specification fixes up.
        found_z, unsure_z = {"axis": "Z", "decided": True}, {"axis": "Z", "decided": False}
        ply, glb = format_table.splat_format_of("/scans/a.ply"), format_table.splat_format_of("/scans/a.glb")
        self.assertEqual(axes.resolve_import_up_axis("DETECT", ply, found_z), "Z")
        self.assertEqual(axes.resolve_import_up_axis("DETECT", ply, unsure_z), "-Y")
        self.assertEqual(axes.resolve_import_up_axis("DETECT", glb, found_z), "-Y")
        self.assertEqual(axes.resolve_import_up_axis("AUTO", ply, found_z), "-Y")
        self.assertFalse(axes.detection_wanted("DETECT", glb))
        self.assertEqual(format_table.splat_format_of("/scans/a.compressed.ply")["name"], "compressed_ply")

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
