# The add-on reads the core's vocabularies rather than restating them: splat formats (file browser filter,
# menu text, import up axis), camera models (panoramic cameras of both Blender versions) and render settings (the
# scene's properties named as the core's settings table, copied by sync.render_settings).
import unittest
from unittest import mock

import bpy

from raysplats.io import format_table
from raysplats.objects import axes
from raysplats import errors, native
from raysplats.engine import sync


class _CoreWithSettings:
    """The core with another settings table."""

    def __init__(self, core, rows):
        self._core, self._rows = core, rows

    def render_settings(self):
        return self._rows

    def __getattr__(self, name):
        return getattr(self._core, name)


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

    def test_every_render_setting_of_the_core_comes_from_the_scene(self):
        settings = bpy.context.scene.raysplats
        properties = settings.bl_rna.properties
        core_settings = native.core().render_settings()
        names = {s["name"] for s in core_settings}
        # The settings sync makes itself or leaves to the core are settings of the core (no stale names).
        self.assertLessEqual(sync.DERIVED_SETTINGS | sync.CORE_ONLY_SETTINGS, names)
        blender_type = {"int": "INT", "float": "FLOAT", "bool": "BOOLEAN", "str": "ENUM"}
        copied = sync.copied_settings(native.core())
        # Every scene property named as a core setting is copied, unless sync makes that setting itself.
        self.assertEqual({name for name in properties.keys() if name in names} - sync.DERIVED_SETTINGS, set(copied))
        for setting in core_settings:
            name = setting["name"]
            if name not in copied:
                continue
            with self.subTest(setting=name):
                self.assertIn(name, properties)
                self.assertEqual(properties[name].type, blender_type[setting["type"]])
                if setting["choices"]:
                    self.assertEqual(sorted(item.identifier for item in properties[name].enum_items),
                                     sorted(setting["choices"]))
                # A value other than the default reaches the core's settings.
                default = getattr(settings, name)
                if setting["type"] == "bool":
                    value = not default
                elif setting["type"] == "str":
                    value = next(choice for choice in setting["choices"] if choice != default)
                elif setting["type"] == "int":
                    value = default + 1
                else:
                    value = (default + properties[name].hard_max) / 2 if default < properties[name].hard_max else 0.0
                setattr(settings, name, value)
                try:
                    self.assertEqual(sync.render_settings(bpy.context.scene, 16, 12, 1)[name], getattr(settings, name))
                    self.assertNotEqual(getattr(settings, name), default)
                finally:
                    setattr(settings, name, default)

    def test_a_core_setting_without_a_scene_property_is_named(self):
        core = native.core()
        rows = core.render_settings() + [{"name": "new_setting", "type": "bool", "description": "", "choices": []}]
        with mock.patch.object(native, "core", return_value=_CoreWithSettings(core, rows)):
            with self.assertRaisesRegex(errors.InternalError, "new_setting"):
                sync.render_settings(bpy.context.scene, 16, 12, 1)

    def test_misspelt_render_setting_is_reported(self):
        scene = native.core().RenderScene()
        camera = {"type": "PERSP"}
        settings = dict(sync.render_settings(bpy.context.scene, 16, 12, 1))
        settings["sample"] = settings.pop("samples")
        with self.assertRaises(ValueError) as raised:
            native.core().RenderJob(scene, camera, settings)
        self.assertIn("unknown render setting 'sample' (known: width, height, samples,", str(raised.exception))
