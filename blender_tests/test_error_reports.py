# How failures reach the user (errors.py): a bug inside the add-on (here injected: a function made to raise a
# KeyError or an AssertionError) is reported by every operator and by the render engine as "RaySplats internal error —
# please report: …" with its traceback on stderr; a user's mistake (a missing file, an unknown format, an unwritable
# folder, a setting the renderer rejects) keeps its plain message and prints no traceback.
import contextlib
import io
import sys
import types
import unittest
from unittest import mock

import bpy

import mesh_export_testing as mt
import splat_testing as st
import raysplats
from raysplats.blender import material_reader
from raysplats.io import import_splats
from raysplats.objects import creation, polygon_mesh
from raysplats import errors
from raysplats.engine import final, viewport
from raysplats.engine import RaySplatsRenderEngine

SPLATS = "small.splat"
INTERNAL = "RaySplats internal error — please report: "


class ReportTest(unittest.TestCase):
    def run_reporting(self, operator, **options):
        """(the message Blender raises for an operator that reported an error, what went to stderr)."""
        stderr = io.StringIO()
        with contextlib.redirect_stderr(stderr), self.assertRaises(RuntimeError) as raised:
            operator(**options)
        return str(raised.exception), stderr.getvalue()

    def assert_internal_error(self, message, stderr, error_type, detail):
        self.assertIn(f"{INTERNAL}{error_type}: {detail}", message)
        self.assertIn("Traceback (most recent call last)", stderr)
        self.assertIn(f"{error_type}: {detail}", stderr)

    def assert_user_error(self, message, stderr, prefix):
        self.assertIn(prefix, message)
        self.assertNotIn("internal error", message)
        self.assertNotIn("Traceback", stderr)


class Operators(ReportTest):
    def setUp(self):
        st.reset_scene()

    def test_import_internal_error_and_missing_file(self):
        with mock.patch.object(polygon_mesh, "fill_mesh", side_effect=KeyError("gs_opacity")):
            message, stderr = self.run_reporting(bpy.ops.import_scene.gaussian_splats,
                                                 filepath=st.data_file(SPLATS))
        self.assert_internal_error(message, stderr, "KeyError", "'gs_opacity'")
        self.assertEqual(len(bpy.data.meshes), 0)  # nothing half-imported left behind

        missing = st.tmp_file("no_such_file.ply")
        message, stderr = self.run_reporting(bpy.ops.import_scene.gaussian_splats, filepath=missing)
        self.assert_user_error(message, stderr, "Import failed: ")
        self.assertIn(missing, message)

    def test_import_failure_after_the_mesh_is_filled_leaves_nothing_behind(self):
        # Before: a failure after fill_mesh (the material, the object, linking) left an orphan mesh and object.
        from raysplats.io import import_policy
        for target, name in ((creation.falloff_material, "gaussian_material"),
                             (import_splats.axes, "object_rotation_euler")):
            with self.subTest(failing=name):
                st.reset_scene()
                meshes, objects = len(bpy.data.meshes), len(bpy.data.objects)
                with mock.patch.object(target, name, side_effect=KeyError("injected")):
                    message, stderr = self.run_reporting(bpy.ops.import_scene.gaussian_splats,
                                                         filepath=st.data_file(SPLATS))
                self.assert_internal_error(message, stderr, "KeyError", "'injected'")
                self.assertEqual(len(bpy.data.meshes), meshes)
                self.assertEqual(len(bpy.data.objects), objects)

    def test_import_too_large_for_the_memory_is_refused_before_it_starts(self):
        # The machine's available memory made tiny: the operator says how much the import needs, reads nothing.
        from raysplats.io import import_policy
        from raysplats import native
        real = native.core()

        class SmallMachine:
            def __getattr__(self, name):
                return getattr(real, name)

            @staticmethod
            def available_memory_bytes():
                return 10 ** 6

            @staticmethod
            def read_splats(*args, **kwargs):
                raise AssertionError("read_splats called although the memory check failed")

        for representation, needed in (("POLYGONS", real.import_memory_bytes(22764, 0, 8)),
                                       ("AUTO", real.compact_import_memory_bytes(22764, 0))):  # (the smaller form)
            with mock.patch.object(native, "core", return_value=SmallMachine()):
                message, stderr = self.run_reporting(bpy.ops.import_scene.gaussian_splats,
                                                     filepath=st.data_file(SPLATS), representation=representation)
            self.assert_user_error(message, stderr, "Import failed: ")
            self.assertIn(f"not enough memory to import 22,764 Gaussians (needs about "
                          f"{import_policy.memory_size_text(needed)}, 1 MB available)", message)
            self.assertEqual(len(bpy.data.meshes), 0)
        needed = real.import_memory_bytes(22764, 0, 8)
        # A std::bad_alloc during the import (the estimate too low) is reported the same way, not as a bug.
        with mock.patch.object(polygon_mesh, "fill_mesh", side_effect=MemoryError("std::bad_alloc")):
            message, stderr = self.run_reporting(bpy.ops.import_scene.gaussian_splats, filepath=st.data_file(SPLATS))
        self.assert_user_error(message, stderr, "Import failed: ")
        self.assertIn("not enough memory to import the file's Gaussians (needs about", message)
        self.assertEqual(len(bpy.data.meshes), 0)
        # The estimate is of the right size: 1.5 M degree-0 Gaussians as octagons need gigabytes, not megabytes.
        self.assertGreater(real.import_memory_bytes(1_500_000, 0, 8), 1e9)
        self.assertLess(real.import_memory_bytes(1_500_000, 0, 8), 4e9)
        self.assertEqual(real.probe_splat_file(st.data_file("biker_v4.spz")),
                         {"format": "spz", "count": 152746, "sh_degree": 0})

    def test_splat_export_internal_error_and_user_error(self):
        st.import_file(SPLATS)
        with mock.patch.object(polygon_mesh, "recover_object_gaussians",
                               side_effect=AssertionError("faces and attributes disagree")):
            message, stderr = self.run_reporting(bpy.ops.export_scene.gaussian_splats,
                                                 filepath=st.tmp_file("internal.ply"))
        self.assert_internal_error(message, stderr, "AssertionError", "faces and attributes disagree")

        message, stderr = self.run_reporting(bpy.ops.export_scene.gaussian_splats,
                                             filepath=st.tmp_file("scene.xyz"))
        self.assert_user_error(message, stderr, "Export failed: ")
        self.assertIn("unknown splat format", message)

    def test_mesh_export_internal_error_and_user_error(self):
        mt.add_red_cube()
        with mock.patch.object(material_reader, "read_material", side_effect=KeyError("Surface")):
            message, stderr = self.run_reporting(bpy.ops.export_scene.raysplats_mesh,
                                                 filepath=st.tmp_file("internal.glb"))
        self.assert_internal_error(message, stderr, "KeyError", "'Surface'")

        message, stderr = self.run_reporting(bpy.ops.export_scene.raysplats_mesh,
                                             filepath="/nonexistent-folder/scene.glb")
        self.assert_user_error(message, stderr, "Export failed: ")


class RecordingEngine:
    """The render engine's entry points on a stand-in that records what they report. (Through bpy.ops.render.render,
    Blender 3.4 in background mode exits with code 1 after any error a render engine reports, which would fail the
    test run itself.)"""
    render = RaySplatsRenderEngine.render
    view_draw = RaySplatsRenderEngine.view_draw
    _fail = RaySplatsRenderEngine._fail

    def __init__(self):
        self.reports, self.errors = [], []

    def report(self, kinds, message):
        self.reports.append((kinds, message))

    def error_set(self, message):
        self.errors.append(message)


class RenderEngine(ReportTest):
    def run_entry_point(self, entry_point, error):
        """(the one ERROR the engine reported when `entry_point` met `error`, what went to stderr)."""
        engine = RecordingEngine()
        stderr = io.StringIO()
        with contextlib.redirect_stderr(stderr), \
                mock.patch.object(final, "render_final", side_effect=error), \
                mock.patch.object(viewport, "view_draw", side_effect=error):
            entry_point(engine)
        self.assertEqual(len(engine.reports), 1)
        kinds, message = engine.reports[0]
        self.assertEqual(kinds, {"ERROR"})
        self.assertEqual(engine.errors, [message])  # also shown in the render window
        return message, stderr.getvalue()

    def test_render_and_viewport_internal_errors(self):
        for name, entry_point in (("render", lambda e: e.render(None)),
                                  ("view_draw", lambda e: e.view_draw(None, None))):
            with self.subTest(entry_point=name):
                message, stderr = self.run_entry_point(entry_point, AssertionError("chunk count mismatch"))
                self.assert_internal_error(message, stderr, "AssertionError", "chunk count mismatch")

    def test_render_user_error(self):
        error = ValueError("Camera 'Camera': panorama type MIRRORBALL is not supported")
        message, stderr = self.run_entry_point(lambda e: e.render(None), error)
        self.assertEqual(message, f"RaySplats: {error}")
        self.assertNotIn("Traceback", stderr)


class Classification(unittest.TestCase):
    def test_native_errors_are_the_users_and_internal_error_never_is(self):
        core = st.native()
        self.assertTrue(errors.is_user_error(core.FileFormatError("'x.ply': truncated")))
        self.assertTrue(errors.is_user_error(core.InvalidArgument("K out of range")))
        self.assertTrue(errors.is_user_error(FileNotFoundError("x.ply")))
        self.assertFalse(errors.is_user_error(errors.InternalError("invariant")))
        self.assertFalse(errors.is_user_error(KeyError("x")))
        self.assertFalse(errors.is_user_error(RuntimeError("bpy_struct: item.attr = val")))


class ViewportFailures(unittest.TestCase):
    def test_a_scene_that_cannot_be_built_is_built_again_only_after_a_change(self):
        st.reset_render_scene(64, 48, 4)
        engine = types.SimpleNamespace(viewport_state=viewport.ViewportState())
        context = types.SimpleNamespace(region=types.SimpleNamespace(width=64, height=48))
        depsgraph = bpy.context.evaluated_depsgraph_get()
        with mock.patch.object(viewport.sync, "SceneSync", side_effect=ValueError("NaN vertex in 'Splats'")) as build:
            with self.assertRaisesRegex(ValueError, "NaN vertex"):
                viewport.view_draw(engine, context, depsgraph)
            for _ in range(3):  # redraws: the failure was reported once; no build at every redraw
                viewport.view_draw(engine, context, depsgraph)
            self.assertEqual(build.call_count, 1)
            viewport.view_update(engine, context, depsgraph)  # the user changes the scene: try again
            with self.assertRaisesRegex(ValueError, "NaN vertex"):
                viewport.view_draw(engine, context, depsgraph)
            self.assertEqual(build.call_count, 2)

    def test_drawing_that_fails_restores_blenders_gpu_state(self):
        calls = []
        gpu = types.ModuleType("gpu")
        gpu.state = types.SimpleNamespace(blend_set=lambda mode: calls.append(("blend", mode)))
        presets = types.ModuleType("gpu_extras.presets")

        def draw_texture_2d(*args):
            raise RuntimeError("GPUTexture freed")

        presets.draw_texture_2d = draw_texture_2d
        engine = types.SimpleNamespace(bind_display_space_shader=lambda scene: calls.append(("bind",)),
                                       unbind_display_space_shader=lambda: calls.append(("unbind",)))
        region = types.SimpleNamespace(width=64, height=48)
        with mock.patch.dict(sys.modules, {"gpu": gpu, "gpu_extras": types.ModuleType("gpu_extras"),
                                           "gpu_extras.presets": presets}), \
                self.assertRaisesRegex(RuntimeError, "GPUTexture freed"):
            viewport.draw_image(engine, None, object(), region)
        self.assertEqual(calls, [("blend", "ALPHA_PREMULT"), ("bind",), ("unbind",), ("blend", "NONE")])


class Registration(unittest.TestCase):
    def registered(self):
        """Whether each visible part of the add-on is in Blender: its scene settings, import operator, engine."""
        try:
            bpy.ops.import_scene.gaussian_splats.get_rna_type()
            operator = True
        except KeyError:
            operator = False
        # (Blender 4.5 has an abstract HydraRenderEngine base without a bl_idname.)
        engines = {getattr(engine, "bl_idname", None) for engine in bpy.types.RenderEngine.__subclasses__()
                   if engine.is_registered}
        return hasattr(bpy.types.Scene, "raysplats"), operator, "RAYSPLATS" in engines

    def test_a_failed_registration_leaves_blender_as_it_was(self):
        self.assertEqual(self.registered(), (True, True, True))
        raysplats.unregister()
        try:
            self.assertEqual(self.registered(), (False, False, False))
            # A late module fails (e.g. a class name another add-on took): every module before it is taken back.
            with mock.patch.object(raysplats.ui.panels, "register", side_effect=ValueError("register_class(...): "
                                                                                      "already registered")), \
                    self.assertRaisesRegex(ValueError, "already registered"):
                raysplats.register()
            self.assertEqual(self.registered(), (False, False, False))
        finally:
            raysplats.register()
        self.assertEqual(self.registered(), (True, True, True))
