# Installs the extension zip the way a user does, into a fresh user folder, in an official Blender build (the PyPI
# bpy module), and uses it: enable, import a real scene, edit it (a transform applied exactly), render it with
# RAYSPLATS beside a mesh under a sun (shadows), export it to .spz and .glb. Nothing of the source tree is on
# sys.path, so the add-on and its native module can only come from the zip. The same file runs in Blender for Linux
# and, under Wine, in Blender for Windows (scripts/windows/test_windows.sh); with --out-dir it leaves the exports and
# the render's pixels there, for scripts/windows/compare_platforms.py.
#   python test_extension_install.py --zip dist/raysplats-0.1.0-linux_x64.zip --data-dir ../shared/data --tmp-dir DIR
#                                    [--out-dir DIR]
import argparse
import ctypes
import importlib.machinery
import os
import shutil
import sys
import unittest

# The test command's reporting: skips counted and named, exit 77 (a skip for ctest) when every test skipped.
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scripts", "lib"))
import unittest_report  # noqa: E402

ARGS = None
PACKAGE = "bl_ext.user_default.raysplats"  # Blender 4.2+: add-ons installed as extensions live in bl_ext.<repo>
SCENE = "small_sh3_inria.ply"  # a real 3DGS scene with SH degree 3 (shared/data), small enough to render fast


def parse_arguments():
    parser = argparse.ArgumentParser()
    parser.add_argument("--zip", required=True)
    parser.add_argument("--data-dir", required=True)
    parser.add_argument("--tmp-dir", required=True)
    parser.add_argument("--out-dir", help="where the exports and the render's pixels are left for comparison")
    args = parser.parse_args()
    # Absolute paths in this system's own form: on Windows (and under Wine) a path given as /tmp/x becomes
    # Z:\tmp\x here, where Blender would otherwise put its own default drive, C:, in front of it.
    for key in ("zip", "data_dir", "tmp_dir", "out_dir"):
        if getattr(args, key):
            setattr(args, key, os.path.abspath(getattr(args, key)))
    return args


def loaded_libraries():
    """The paths of every shared library this process has loaded."""
    if sys.platform == "win32":
        psapi, kernel32 = ctypes.WinDLL("psapi"), ctypes.WinDLL("kernel32")
        kernel32.GetCurrentProcess.restype = ctypes.c_void_p
        process = ctypes.c_void_p(kernel32.GetCurrentProcess())
        handles = (ctypes.c_void_p * 4096)()
        needed = ctypes.c_uint32()
        assert psapi.EnumProcessModules(process, handles, ctypes.sizeof(handles), ctypes.byref(needed))
        paths = []
        for handle in handles[:needed.value // ctypes.sizeof(ctypes.c_void_p)]:
            name = ctypes.create_unicode_buffer(1024)
            psapi.GetModuleFileNameExW(process, ctypes.c_void_p(handle), name, 1024)
            paths.append(name.value)
        return paths
    with open("/proc/self/maps") as maps:
        return sorted({line.split()[-1] for line in maps if line.split()[-1].startswith("/")})


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
        self.assertEqual(os.path.basename(path), "_native" + importlib.machinery.EXTENSION_SUFFIXES[0])
        folder = os.path.normcase(os.path.dirname(path))
        ours = sorted(library for library in loaded_libraries()
                      if os.path.normcase(os.path.dirname(os.path.realpath(library))) == folder)
        if sys.platform == "win32":
            # Everything is linked into the module: no DLL of ours, so none that Blender's own could stand in for.
            self.assertEqual([os.path.basename(library) for library in ours], [os.path.basename(path)])
        else:
            # Its libraries come from the zip: the loaded Embree 3 is the one beside the module.
            embree = {library for library in loaded_libraries() if "libembree3" in library}
            self.assertEqual(embree, {os.path.join(os.path.dirname(path), "libembree3.so.3")})

    def test_import_edit_render_export_a_real_scene(self):
        bpy = self.bpy
        import numpy as np
        # (Not read_factory_settings: that would also drop the user preferences, and with them the installed add-on.)
        for other in list(bpy.data.objects):
            bpy.data.objects.remove(other)
        result = bpy.ops.import_scene.gaussian_splats(filepath=os.path.join(ARGS.data_dir, SCENE))
        self.assertEqual(result, {"FINISHED"})
        obj = bpy.context.active_object
        imported = len(obj.data.polygons)
        self.assertGreater(imported, 1000)
        # An edit: a rotation and a non-uniform scale, applied to the Gaussians exactly.
        obj.rotation_euler = (0.3, -0.2, 0.9)
        obj.scale = (1.5, 1.0, 0.75)
        self.assertEqual(bpy.ops.object.raysplats_apply_transform(location=False, rotation=True, scale=True),
                         {"FINISHED"})
        self.assertEqual(tuple(obj.scale), (1.0, 1.0, 1.0))

        scene = bpy.context.scene
        camera = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
        scene.collection.objects.link(camera)
        scene.camera = camera
        centre, radius = self.frame(camera, obj)
        # A ground under the scene and a sun: the Gaussians cast their shadows on a mesh.
        bpy.ops.mesh.primitive_plane_add(size=6 * radius, location=(centre.x, centre.y, centre.z - radius))
        sun = bpy.data.objects.new("sun", bpy.data.lights.new("sun", "SUN"))
        sun.data.energy = 3.0
        sun.rotation_euler = (0.4, 0.3, 0.0)
        scene.collection.objects.link(sun)
        scene.render.engine = "RAYSPLATS"
        # 61 x 45: edge packets with inactive lanes.
        scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 61, 45, 100
        scene.raysplats.samples = 4
        scene.render.film_transparent = True
        scene.render.image_settings.file_format = "OPEN_EXR"
        scene.render.image_settings.color_depth = "32"
        scene.render.image_settings.exr_codec = "NONE"
        image_path = os.path.join(ARGS.tmp_dir, "extension_render.exr")
        scene.render.filepath = image_path
        self.assertEqual(bpy.ops.render.render(write_still=True), {"FINISHED"})
        image = bpy.data.images.load(image_path)
        pixels = np.array(image.pixels[:], np.float32).reshape(45, 61, 4)
        covered = int((pixels[..., 3] > 0.05).sum())
        # The scene and its ground fill much of the frame: an engine that drew nothing (or failed silently) leaves
        # it empty.
        self.assertGreater(covered, 61 * 45 // 3, "the RaySplats render is (nearly) empty")

        spz = os.path.join(ARGS.tmp_dir, "extension_export.spz")
        glb = os.path.join(ARGS.tmp_dir, "extension_export.glb")
        for out in (spz, glb):
            if os.path.exists(out):
                os.remove(out)
        obj.select_set(True)
        bpy.context.view_layer.objects.active = obj
        self.assertEqual(bpy.ops.export_scene.gaussian_splats(filepath=spz), {"FINISHED"})
        written = sys.modules[PACKAGE + ".native"].core().read_splats(spz)
        self.assertEqual(len(written["opacities"]), imported)
        self.assertEqual(bpy.ops.export_scene.raysplats_mesh(filepath=glb, draco=True), {"FINISHED"})
        self.assertGreater(os.path.getsize(glb), 1000)
        if ARGS.out_dir:
            os.makedirs(ARGS.out_dir, exist_ok=True)
            np.save(os.path.join(ARGS.out_dir, "blender_render_rgba.npy"), pixels)
            for path in (spz, glb):
                shutil.copyfile(path, os.path.join(ARGS.out_dir, "blender_" + os.path.basename(path)))

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
        return centre, radius


def main():
    global ARGS
    ARGS = parse_arguments()
    user_dir = os.path.join(os.path.abspath(ARGS.tmp_dir), "blender_user")
    shutil.rmtree(user_dir, ignore_errors=True)
    os.makedirs(user_dir)
    # Read by Blender when bpy is imported: every user folder (config, scripts, extensions) under it.
    os.environ["BLENDER_USER_RESOURCES"] = user_dir
    suite = unittest.TestLoader().loadTestsFromTestCase(ExtensionInstall)
    sys.exit(unittest_report.run(suite))


if __name__ == "__main__":
    main()
