# The module on the platform it runs on, through the operating system's own file API: the same file run by Linux's
# Python and by Windows' (under Wine, scripts/windows/test_windows.sh). Every real scene of shared/data is read;
# files are written and read under names no code page holds, through backslashes and drive letters on Windows, and
# over existing files (on Windows a plain rename onto an existing file fails); polygons are built and recovered; a
# small scene of meshes and Gaussians with a light is rendered. What it makes goes to OUT_DIR, so that
# scripts/windows/compare_platforms.py can compare the two platforms' results file by file.
#   python test_module_platform.py DIRECTORY_OF_THE_MODULE DATA_DIR OUT_DIR
import ctypes
import glob
import hashlib
import os
import shutil
import sys
import tempfile
import unittest

# The test command's reporting: skips counted and named, exit 77 (a skip for ctest) when every test skipped.
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scripts", "lib"))
import unittest_report  # noqa: E402

import numpy as np

sys.path.insert(0, sys.argv[1])
import _native  # noqa: E402

DATA_DIR = sys.argv[2]
OUT_DIR = sys.argv[3]
WINDOWS = sys.platform == "win32"
# Letters from four scripts and one outside the Basic Multilingual Plane (a UTF-16 surrogate pair on Windows).
FOREIGN = "Ünïcødé 日本語 Ελληνικά ñ \U0001F642"
SCENES = ["small_sh3_inria.ply", "donut_sh0.ply", "unicorn_sh3_reordered.ply", "small.splat", "biker_v4.spz",
          "unicorn_sh3.sog", "guitar_supersplat.compressed.ply", "showroom_1.5M.ply"]
WRITABLE = [f for f in _native.splat_formats() if f["writable"]]


def native_form(path):
    """The absolute path as this system's users write it: drive letter and backslashes on Windows."""
    path = os.path.abspath(path)
    return path.replace("/", "\\") if WINDOWS else path


def cloud_digest(cloud):
    h = hashlib.sha256()
    for key in ("positions", "rotations", "scales", "opacities", "sh"):
        h.update(np.ascontiguousarray(cloud[key]).tobytes())
    return h.hexdigest()


def physical_memory_bytes():
    if WINDOWS:
        class Status(ctypes.Structure):
            _fields_ = [("length", ctypes.c_uint32), ("load", ctypes.c_uint32), ("total", ctypes.c_uint64),
                        ("available", ctypes.c_uint64), ("page_total", ctypes.c_uint64),
                        ("page_available", ctypes.c_uint64), ("virtual_total", ctypes.c_uint64),
                        ("virtual_available", ctypes.c_uint64), ("extended", ctypes.c_uint64)]
        status = Status(length=ctypes.sizeof(Status))
        assert ctypes.windll.kernel32.GlobalMemoryStatusEx(ctypes.byref(status))
        return status.total
    return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")


class Platform(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        os.makedirs(OUT_DIR, exist_ok=True)
        cls.tmp = tempfile.mkdtemp(prefix="raysplats-platform-")
        cls.small = _native.read_splats(os.path.join(DATA_DIR, "small_sh3_inria.ply"))

    @classmethod
    def tearDownClass(cls):
        shutil.rmtree(cls.tmp, ignore_errors=True)

    def test_every_real_scene_reads_through_the_native_path_form(self):
        digests = []
        for name in SCENES:
            cloud = _native.read_splats(native_form(os.path.join(DATA_DIR, name)))
            self.assertGreater(len(cloud["opacities"]), 9000, name)
            summary = _native.probe_splat_file(native_form(os.path.join(DATA_DIR, name)))
            self.assertEqual(summary["count"], len(cloud["opacities"]), name)
            digests.append(f"{name} {len(cloud['opacities'])} {cloud['sh_degree']} {cloud_digest(cloud)}\n")
        with open(os.path.join(OUT_DIR, "scene_digests.txt"), "w", newline="\n") as out:
            out.writelines(digests)

    def test_every_writable_format_under_a_foreign_name_and_over_an_existing_file(self):
        folder = os.path.join(self.tmp, FOREIGN)
        os.makedirs(folder)
        c = self.small
        for info in WRITABLE:
            ending = info["extensions"][0]
            path = os.path.join(folder, f"spläts {FOREIGN}{ending}")
            for attempt in range(2):  # the second write replaces the first file
                _native.write_splats(native_form(path), c["positions"], c["rotations"], c["scales"], c["opacities"],
                                     c["sh"])
                self.assertTrue(os.path.isfile(path), f"{ending}: written under another name")
            back = _native.read_splats(native_form(path))
            self.assertEqual(len(back["opacities"]), len(c["opacities"]), ending)
            with open(path, "rb") as written:
                data = written.read()
            with open(os.path.join(OUT_DIR, "export" + ending), "wb") as out:
                out.write(data)
        # Exactly one file per format: no temporary file is left beside them.
        self.assertEqual(sorted(os.listdir(folder)),
                         sorted(f"spläts {FOREIGN}{info['extensions'][0]}" for info in WRITABLE))

    def test_a_failed_write_leaves_the_old_file_and_nothing_else(self):
        folder = os.path.join(self.tmp, "failed " + FOREIGN)
        os.makedirs(folder)
        target = os.path.join(folder, "keep.ply")
        c = self.small
        _native.write_splats(target, c["positions"], c["rotations"], c["scales"], c["opacities"], c["sh"])
        with open(target, "rb") as old:
            before = old.read()
        with self.assertRaises(Exception):  # one Gaussian fewer in the scales than in the positions
            _native.write_splats(target, c["positions"], c["rotations"], c["scales"][1:], c["opacities"], c["sh"])
        with self.assertRaises(Exception) as raised:
            _native.write_splats(folder, c["positions"], c["rotations"], c["scales"], c["opacities"], c["sh"])
        self.assertIn(os.path.basename(folder), str(raised.exception))
        with open(target, "rb") as kept:
            self.assertEqual(kept.read(), before)
        self.assertEqual(os.listdir(folder), ["keep.ply"])

    def test_a_missing_foreign_file_is_an_error_naming_it(self):
        path = os.path.join(self.tmp, f"nowhere {FOREIGN}.ply")
        with self.assertRaises(Exception) as raised:
            _native.read_splats(native_form(path))
        self.assertIn(FOREIGN, str(raised.exception))

    def test_mesh_exports_under_a_foreign_name(self):
        c = self.small
        scene = _native.MeshExportScene()
        scene.add_splats("scene", c["positions"], c["rotations"], c["scales"], c["opacities"], c["sh"])
        folder = os.path.join(self.tmp, "meshes " + FOREIGN)
        os.makedirs(folder)
        for name, draco in (("mesh.obj", False), ("mesh.ply", False), ("mesh.glb", False), ("mesh_draco.glb", True),
                            ("mesh.gltf", False)):
            path = os.path.join(folder, f"{FOREIGN} {name}")
            for attempt in range(2):
                scene.write(native_form(path), draco=draco)
            shutil.copyfile(path, os.path.join(OUT_DIR, name))
            # The files written beside it, which the first one names by their file name alone.
            if name.endswith(".obj"):
                shutil.copyfile(path[:-4] + ".mtl", os.path.join(OUT_DIR, "mesh.mtl"))
            if name.endswith(".gltf"):
                shutil.copyfile(path[:-5] + ".bin", os.path.join(OUT_DIR, "mesh.bin"))
        leftovers = [name for name in os.listdir(folder) if ".tmp" in name]
        self.assertEqual(leftovers, [])

    def test_polygons_round_trip(self):
        c = self.small
        polygons = _native.gaussians_to_polygons(c["positions"], c["rotations"], c["scales"], c["opacities"], c["sh"],
                                                 vertices_per_polygon=8, radius=3.0)
        n = len(polygons["face_corner_start"])
        back = _native.recover_gaussians(
            polygons["vertex_positions"], polygons["corner_vertices"], polygons["face_corner_start"],
            polygons["face_corner_count"], 8, 3.0, np.eye(4, dtype=np.float64),
            opacity=polygons["opacity"], polygon_radius=polygons["polygon_radius"], sh_local=polygons["sh_local"],
            rest_centers=polygons["rest_centers"], rest_rotations=polygons["rest_rotations"],
            rest_scales=polygons["rest_scales"])
        kept = np.flatnonzero(c["opacities"] >= 1.0 / 255.0)
        self.assertEqual(n, len(kept))
        np.testing.assert_allclose(back["positions"], c["positions"][kept], atol=1e-4)
        np.savez(os.path.join(OUT_DIR, "polygons.npz"), vertex_positions=polygons["vertex_positions"],
                 positions=back["positions"], rotations=back["rotations"], scales=back["scales"])

    def test_render_of_meshes_gaussians_and_a_light(self):
        c = self.small
        scene = _native.RenderScene()
        scene.add_material(base_color=[0.8, 0.8, 0.8])
        # Rounded, so that the numpy version each platform's Python has (their float sums differ in the last bits)
        # cannot move the camera: only the module's own arithmetic may differ between the platforms.
        positions = c["positions"].astype(np.float64)
        centre = np.round(positions.mean(axis=0), 3)
        size = round(float(np.percentile(np.linalg.norm(positions - centre, axis=1), 90)), 3)
        ground = np.array([[-3, -3, 0], [3, -3, 0], [3, 3, 0], [-3, 3, 0]], np.float32) * size
        ground += (centre - [0, 0, size]).astype(np.float32)
        scene.add_mesh(ground, np.array([[0, 1, 2], [0, 2, 3]], np.uint32))
        scene.add_gaussians(c["positions"], c["rotations"], c["scales"], c["opacities"], c["sh"])
        sun = np.eye(4, dtype=np.float32)
        scene.add_light("SUN", [1.0, 1.0, 1.0], 3.0, sun)
        scene.set_world([0.05, 0.05, 0.05])
        scene.build()
        camera = np.eye(4, dtype=np.float32)
        camera[:3, 3] = centre + np.array([0.0, 0.0, 3.0 * size])
        # 61 x 45: not a multiple of any packet's width or height, so edge packets have inactive lanes.
        def render(**threads):
            job = _native.RenderJob(scene, {"matrix": camera}, {"width": 61, "height": 45, "samples": 4, "seed": 7},
                                    **threads)
            while not job.wait(1.0):
                pass
            film = job.result()
            return np.asarray(film["rgba"] if isinstance(film, dict) else film)

        rgba = render()
        self.assertGreater(float(rgba[..., 3].mean()), 0.2, "the render is nearly empty")
        # One thread at lowered priority (the system's own call for it) gives the film all cores give.
        np.testing.assert_array_equal(render(max_threads=1, below_normal_priority=True), rgba)
        np.save(os.path.join(OUT_DIR, "render_rgba.npy"), rgba.astype(np.float32))
        with open(os.path.join(OUT_DIR, "render_device.txt"), "w", newline="\n") as out:
            out.write(f"{scene.embree_device}\n")

    def test_available_memory_is_the_systems(self):
        available = _native.available_memory_bytes()
        self.assertGreater(available, 32 << 20)
        self.assertLessEqual(available, physical_memory_bytes())


if __name__ == "__main__":
    unittest_report.main()
