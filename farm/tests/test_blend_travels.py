# The data travels with the .blend: a saved shot holds everything a RaySplats render needs, in each form of a splat
# object (one polygon object, pieces under an empty, compact points, and on 5.3+ the Gaussian-splat point cloud of
# Blender's own PLY importer), with no path back to the splat file it came
# from. Each form: imported from a copy of a real scene, saved, rendered headless on "machine 1"; then the .blend is
# copied to another folder, the splat file deleted, and "machine 2" (another process, another home and user folder,
# and as root another user, who could not read the first folder anyway) renders it: the same pixels, bit for bit
# (fixed seeds; Animate Seed on, the frame is 2 so its seed is the frame's).
import os
import shutil
import stat
import unittest

import bpy
import numpy as np

import farm_testing as ft
from farm_testing import st

FRAME = 2


class BlendTravels(unittest.TestCase):
    def travel(self, form, **import_options):
        root = st.tmp_file(f"travel_{form}")
        shutil.rmtree(root, ignore_errors=True)
        source = os.path.join(root, "source", "scan.ply")
        os.makedirs(os.path.dirname(source))
        shutil.copyfile(st.data_file(ft.SCENE), source)
        blend = os.path.join(root, "machine1", "shot.blend")
        obj = ft.build_shot(blend, splat_path=source, **import_options)
        gaussian_objects = [o for o in bpy.data.objects if o.type in {"MESH", "POINTCLOUD"}]
        self.assertTrue(gaussian_objects)
        # Blender's list of the file's external files (images, libraries, caches...) has nothing of the splat file.
        external = bpy.utils.blend_paths(absolute=True)
        self.assertFalse([path for path in external if "scan" in path], external)

        first = ft.frame_path(os.path.join(root, "machine1", "out", "frame_####"), FRAME)
        ft.run(ft.worker_command(blend, first[:-len("0002.png")] + "####", (FRAME, FRAME)))

        # Machine 2: the .blend alone, elsewhere; the splat file gone.
        elsewhere = os.path.join(root, "machine2", "farm", "shots")
        os.makedirs(elsewhere)
        moved = os.path.join(elsewhere, "shot.blend")
        shutil.copyfile(blend, moved)
        shutil.rmtree(os.path.dirname(source))
        home = os.path.join(root, "machine2", "home")
        os.makedirs(home)
        out_dir = os.path.join(root, "machine2", "out")
        os.makedirs(out_dir)
        env = dict(os.environ, HOME=home, BLENDER_USER_RESOURCES=os.path.join(home, "blender"))
        options = {"env": env, "cwd": home}
        if os.geteuid() == 0 and not ft.AS_MODULE and shutil.which("setpriv"):
            # Another user (nobody) who could not read the first folder: open the shot and the output to them only.
            for path in (root, os.path.join(root, "machine2"), elsewhere, os.path.dirname(elsewhere), home, out_dir):
                os.chmod(path, os.stat(path).st_mode | stat.S_IRWXO)
            os.chmod(os.path.join(root, "machine1"), 0o700)
            command = ["setpriv", "--reuid=65534", "--regid=65534", "--clear-groups"]
        else:
            command = []
        second = ft.frame_path(os.path.join(out_dir, "frame_####"), FRAME)
        ft.run(command + ft.worker_command(moved, os.path.join(out_dir, "frame_####"), (FRAME, FRAME)), **options)

        a, b = ft.load_pixels(first), ft.load_pixels(second)
        covered = np.count_nonzero(a[..., 3] > 0.05)
        self.assertGreater(covered, a.shape[0] * a.shape[1] // 10, "the render is (nearly) empty")
        self.assertEqual(np.abs(a - b).max(), 0.0, f"{form}: machine 2's frame differs from machine 1's")
        return obj

    def test_polygon_object(self):
        obj = self.travel("polygons", objects="ONE")
        self.assertEqual(obj.type, "MESH")

    def test_pieces(self):
        obj = self.travel("pieces", objects="PIECES", piece_size=3000)
        self.assertEqual(obj.type, "EMPTY")
        self.assertGreaterEqual(len(obj.children), 3)

    def test_compact_points(self):
        obj = self.travel("compact", representation="POINTS")
        if obj.type == "POINTCLOUD":  # Blender 5.3+: the compact form is a Gaussian-splat point cloud
            self.assertGreater(len(obj.data.points), 9000)
        else:
            self.assertEqual(len(obj.data.polygons), 0)
            self.assertGreater(len(obj.data.vertices), 9000)

    def test_blender_made_splats(self):
        from raysplats.blender import compat
        if not compat.HAS_NATIVE_GAUSSIAN_SPLATS:
            self.skipTest(f"expected: Blender {bpy.app.version_string} has no Gaussian-splat point clouds (5.3+)")
        obj = self.travel("blender_splats", blender_import=True)
        self.assertEqual(obj.type, "POINTCLOUD")
        self.assertGreater(len(obj.data.points), 9000)
