# Installs the extension zip the way a user does, into a fresh user folder, in an official Blender build (the PyPI
# bpy module), and uses it: enable, import a real scene, render it with RAYSPLATS, export it. Nothing of the source
# tree is on sys.path, so the add-on and its native module can only come from the zip.
#   python test_extension_install.py --zip dist/raysplats-0.1.0-linux_x64.zip --data-dir ../shared/data --tmp-dir DIR
import argparse
import os
import shutil
import sys
import unittest

ARGS = None
PACKAGE = "bl_ext.user_default.raysplats"  # Blender 4.2+: add-ons installed as extensions live in bl_ext.<repo>
SCENE = "small_sh3_inria.ply"  # a real 3DGS scene with SH degree 3 (shared/data), small enough to render fast


def parse_arguments():
    parser = argparse.ArgumentParser()
    parser.add_argument("--zip", required=True)
    parser.add_argument("--data-dir", required=True)
    parser.add_argument("--tmp-dir", required=True)
    return parser.parse_args()


class ExtensionInstall(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        import bpy
        cls.bpy = bpy
        # A user folder of our own: the install must work on a Blender that has never seen RaySplats.
        cls.user_dir = os.path.realpath(os.environ["BLENDER_USER_RESOURCES"])
        extensions = os.path.realpath(bpy.utils.user_resource("EXTENSIONS"))
        assert extensions.startswith(cls.user_dir), f"Blender's extension folder {extensions} is not in {cls.user_dir}"
        result = bpy.ops.extensions.package_install_files(
            filepath=os.path.abspath(ARGS.zip), repo="user_default", enable_on_install=True)
        assert result == {"FINISHED"}, f"package_install_files: {result}"

    @classmethod
    def tearDownClass(cls):
        # bpy crashes at interpreter exit while add-on classes are still registered (run_blender_test.py).
        if PACKAGE in cls.bpy.context.preferences.addons:
            cls.bpy.ops.preferences.addon_disable(module=PACKAGE)

    def test_installed_into_the_user_folder_and_enabled(self):
        import addon_utils
        self.assertIn(PACKAGE, self.bpy.context.preferences.addons)
        self.assertTrue(addon_utils.check(PACKAGE)[1], "the add-on is not loaded")
        package = sys.modules[PACKAGE]
        self.assertTrue(os.path.realpath(package.__file__).startswith(self.user_dir), package.__file__)
        self.assertTrue(hasattr(self.bpy.types.Object, "raysplats"))

    def test_native_module_is_the_zips_for_this_python(self):
        core = sys.modules[PACKAGE + ".native"].core()
        path = os.path.realpath(core.__file__)
        self.assertTrue(path.startswith(self.user_dir), path)
        tag = f"cpython-{sys.version_info.major}{sys.version_info.minor}"
        self.assertIn(tag, os.path.basename(path))
        # Its libraries come from the zip: the loaded Embree 3 is the one beside the module.
        with open("/proc/self/maps") as maps:
            embree = {line.split()[-1] for line in maps if "libembree3" in line}
        self.assertEqual(embree, {os.path.join(os.path.dirname(path), "libembree3.so.3")})

    def test_import_render_export_a_real_scene(self):
        bpy = self.bpy
        # (Not read_factory_settings: that would also drop the user preferences, and with them the installed add-on.)
        for other in list(bpy.data.objects):
            bpy.data.objects.remove(other)
        result = bpy.ops.import_scene.gaussian_splats(filepath=os.path.join(ARGS.data_dir, SCENE))
        self.assertEqual(result, {"FINISHED"})
        obj = bpy.context.active_object
        imported = len(obj.data.polygons)
        self.assertGreater(imported, 1000)

        scene = bpy.context.scene
        camera = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
        scene.collection.objects.link(camera)
        scene.camera = camera
        self.frame(camera, obj)
        scene.render.engine = "RAYSPLATS"
        scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 48, 32, 100
        scene.raysplats.samples = 1
        scene.render.film_transparent = True
        scene.render.image_settings.file_format = "PNG"
        scene.render.image_settings.color_mode = "RGBA"
        image_path = os.path.join(ARGS.tmp_dir, "extension_render.png")
        scene.render.filepath = image_path
        self.assertEqual(bpy.ops.render.render(write_still=True), {"FINISHED"})
        image = bpy.data.images.load(image_path)
        pixels = list(image.pixels)
        covered = sum(1 for alpha in pixels[3::4] if alpha > 0.05)
        # The scene fills much of the frame: an engine that drew nothing (or failed silently) leaves it empty.
        self.assertGreater(covered, 48 * 32 // 10, "the RaySplats render is (nearly) empty")

        out = os.path.join(ARGS.tmp_dir, "extension_export.spz")
        if os.path.exists(out):
            os.remove(out)
        self.assertEqual(bpy.ops.export_scene.gaussian_splats(filepath=out), {"FINISHED"})
        written = sys.modules[PACKAGE + ".native"].core().read_splats(out)
        self.assertEqual(len(written["opacities"]), imported)

    @staticmethod
    def frame(camera, obj):
        """Points the camera at the object's bounding box from outside it (no 3D view in background mode)."""
        from mathutils import Vector
        corners = [obj.matrix_world @ Vector(corner) for corner in obj.bound_box]
        centre = sum(corners, Vector()) / 8
        radius = max((corner - centre).length for corner in corners)
        camera.location = centre + Vector((0.0, -2.5 * radius, 0.6 * radius))
        camera.rotation_euler = (centre - camera.location).to_track_quat("-Z", "Y").to_euler()
        camera.data.clip_end = 10 * radius


def main():
    global ARGS
    ARGS = parse_arguments()
    user_dir = os.path.join(os.path.abspath(ARGS.tmp_dir), "blender_user")
    shutil.rmtree(user_dir, ignore_errors=True)
    os.makedirs(user_dir)
    # Read by Blender when bpy is imported: every user folder (config, scripts, extensions) under it.
    os.environ["BLENDER_USER_RESOURCES"] = user_dir
    suite = unittest.TestLoader().loadTestsFromTestCase(ExtensionInstall)
    result = unittest.TextTestRunner(verbosity=2, stream=sys.stdout).run(suite)
    print(f"{result.testsRun - len(result.failures) - len(result.errors)} passed, "
          f"{len(result.failures) + len(result.errors)} failed")
    sys.exit(0 if result.wasSuccessful() and result.testsRun else 1)


if __name__ == "__main__":
    main()
