# The headless command line (addon/raysplats/cli.py), run as pipelines run it: a separate `blender -b`
# (or, under the PyPI bpy module, a Python process importing bpy) over the real scenes, with progress lines,
# exit status and no half-written outputs.
import glob
import os
import shutil
import subprocess
import sys
import unittest

import bpy
import numpy as np

import mesh_export_testing as mt
import splat_testing as st

CLI = os.path.join(mt.REPO, "addon", "raysplats", "cli.py")
# (file, Gaussians, of them below opacity 1/255: not imported) of the real scenes; showroom_1.5M.ply is left out to
# keep the test short.
REAL_FILES = [("small_sh3_inria.ply", 9080, 0), ("donut_sh0.ply", 45624, 1518),
              ("unicorn_sh3_reordered.ply", 49602, 39), ("small.splat", 22764, 0), ("biker_v4.spz", 152746, 0)]


def run_cli(*args, blend=None):
    """Runs the CLI in a new Blender; returns (exit status, stdout + stderr)."""
    if bpy.app.binary_path and "python" not in os.path.basename(bpy.app.binary_path).lower():
        command = [bpy.app.binary_path, "-b", "--factory-startup", "-noaudio"] + ([blend] if blend else []) + \
                  ["--python", CLI, "--"] + list(args)
    else:  # Blender as a Python module (bpy from PyPI): the same script, run as __main__ after `import bpy`
        code = ("import sys, runpy, bpy\n"
                + (f"bpy.ops.wm.open_mainfile(filepath={blend!r})\n" if blend else "")
                + f"sys.argv = ['cli.py', '--'] + {list(args)!r}\n"
                + f"runpy.run_path({CLI!r}, run_name='__main__')\n")
        command = [sys.executable, "-c", code]
    out = subprocess.run(command, capture_output=True, text=True, timeout=1200)
    return out.returncode, out.stdout + out.stderr


def fresh_dir(name):
    path = st.tmp_file(name)
    shutil.rmtree(path, ignore_errors=True)
    os.makedirs(path)
    return path


def progress_lines(output, command):
    return [line for line in output.splitlines() if line.startswith(f"raysplats {command} [")]


class Batch(unittest.TestCase):
    def test_export_every_real_file_to_draco_glb(self):
        out = fresh_dir("batch_glb")
        inputs = [st.data_file(name) for name, _, _ in REAL_FILES]
        status, output = run_cli("export", *inputs, "-o", out, "--format", "glb", "--draco")
        self.assertEqual(status, 0, output)
        lines = progress_lines(output, "export")
        self.assertEqual(len(lines), len(REAL_FILES), output)
        self.assertTrue(all(": ok (" in line for line in lines), output)
        for name, count, invisible in REAL_FILES:
            path = os.path.join(out, os.path.splitext(name)[0] + ".glb")
            self.assertTrue(os.path.exists(path), path)
            doc = mt.gltf_json(path)
            self.assertIn("KHR_draco_mesh_compression", doc["extensionsRequired"])
            vertices = sum(doc["accessors"][p["attributes"]["POSITION"]]["count"]
                           for m in doc["meshes"] for p in m["primitives"])
            self.assertEqual(vertices, 9 * (count - invisible), name)  # a patch per imported Gaussian
        if not mt.gltf_tools_missing():
            for path in glob.glob(os.path.join(out, "*.glb")):
                report = mt.check_gltf(path)
                self.assertEqual(report["errors"], 0, (path, report["messages"]))
                self.assertEqual(sum(p["points"] for p in report["draco"]),
                                 sum(p["accessor_points"] for p in report["draco"]))

    def test_import_then_export_the_blend_files_and_convert(self):
        blends = fresh_dir("batch_blend")
        inputs = [st.data_file(name) for name, _, _ in REAL_FILES]
        status, output = run_cli("import", *inputs, "-o", blends)
        self.assertEqual(status, 0, output)
        for name, _, _ in REAL_FILES:
            self.assertTrue(os.path.exists(os.path.join(blends, os.path.splitext(name)[0] + ".blend")), name)
        # A .blend given to Blender on the command line is the input when none is listed.
        blend = os.path.join(blends, "small_sh3_inria.blend")
        obj_path = st.tmp_file("batch_from_blend.obj")
        if os.path.exists(obj_path):
            os.remove(obj_path)
        status, output = run_cli("export", "-o", obj_path, blend=blend)
        self.assertEqual(status, 0, output)
        with open(obj_path) as f:
            faces = sum(1 for line in f if line.startswith("f "))
        self.assertEqual(faces, 8 * 9080)
        # convert: every real file to .spz and back to 3DGS .ply, same Gaussian counts.
        spz = fresh_dir("batch_spz")
        status, output = run_cli("convert", *inputs, "-o", spz, "--format", "spz")
        self.assertEqual(status, 0, output)
        for name, count, _ in REAL_FILES:
            cloud = st.native().read_splats(os.path.join(spz, os.path.splitext(name)[0] + ".spz"))
            self.assertEqual(len(cloud["opacities"]), count, name)
        # A two-dot extension names its format: the output's ".compressed.ply" is SuperSplat's compressed PLY, not a
        # 3DGS .ply (before, the last dot decided).
        compressed = os.path.join(spz, "small.compressed.ply")
        status, output = run_cli("convert", st.data_file("small_sh3_inria.ply"), "-o", compressed)
        self.assertEqual(status, 0, output)
        summary = st.native().probe_splat_file(compressed)
        self.assertEqual((summary["format"], summary["count"], summary["sh_degree"]), ("compressed_ply", 9080, 3))

    def test_a_corrupt_file_is_reported_and_the_good_ones_still_written(self):
        out = fresh_dir("batch_corrupt")
        corrupt = os.path.join(fresh_dir("batch_corrupt_in"), "corrupt.ply")
        with open(corrupt, "wb") as f:
            f.write(b"ply\nformat binary_little_endian 1.0\nelement vertex 1000\nproperty float x\n"
                    b"property float y\nproperty float z\nend_header\n" + b"\0" * 100)
        inputs = [st.data_file("small_sh3_inria.ply"), corrupt, st.data_file("small.splat")]
        for command, extra in (("export", ["--format", "ply"]), ("import", []), ("convert", ["--format", "splat"])):
            with self.subTest(command=command):
                shutil.rmtree(out)
                os.makedirs(out)
                status, output = run_cli(command, *inputs, "-o", out, *extra)
                self.assertEqual(status, 1, output)
                failed = [line for line in progress_lines(output, command) if "FAILED" in line]
                self.assertEqual(len(failed), 1, output)
                self.assertIn("corrupt.ply", failed[0])
                self.assertIn("1 FAILED", output)
                written = sorted(os.listdir(out))
                extension = {"export": ".ply", "import": ".blend", "convert": ".splat"}[command]
                self.assertEqual(written, ["small" + extension, "small_sh3_inria" + extension], output)

    def test_render_a_thumbnail_with_the_fallback_engine(self):
        out = fresh_dir("batch_render")
        status, output = run_cli("render", st.data_file("small_sh3_inria.ply"), "-o", out,
                                 "--resolution", "64", "48", "--samples", "2")
        self.assertEqual(status, 0, output)
        engines = {getattr(e, "bl_idname", None) for e in bpy.types.RenderEngine.__subclasses__()}
        self.assertIn("RAYSPLATS" if "RAYSPLATS" in engines else "CYCLES", progress_lines(output, "render")[0])
        path = os.path.join(out, "small_sh3_inria.png")
        image = bpy.data.images.load(path)
        try:
            self.assertEqual(tuple(image.size), (64, 48))
            pixels = np.empty(64 * 48 * 4, dtype=np.float32)
            image.pixels.foreach_get(pixels)
            self.assertGreater(pixels.reshape(-1, 4)[:, :3].std(), 0.01, "the thumbnail is blank")
        finally:
            bpy.data.images.remove(image)
        self.assertEqual([f for f in os.listdir(out) if ".tmp" in f], [])

    def test_usage_errors_exit_2(self):
        status, output = run_cli("export", st.data_file("small.splat"), "-o", st.tmp_file("x"))
        self.assertEqual(status, 2, output)
        self.assertIn("--format", output)
        status, output = run_cli("export", st.tmp_file("no_such_*.ply"), "-o", st.tmp_file("x"), "--format", "glb")
        self.assertEqual(status, 2, output)
        self.assertIn("no file matches", output)
        # The help lists the formats from the core's table: every ending it reads, and the ones convert writes.
        status, output = run_cli("--help")
        self.assertEqual(status, 0, output)
        from raysplats import native
        for f in native.core().splat_formats():
            for ending in f["extensions"]:
                self.assertIn(ending, output)

    def test_works_from_an_installed_addon(self):
        if not bpy.app.binary_path or "python" in os.path.basename(bpy.app.binary_path).lower():
            self.skipTest("expected: needs the Blender executable (user script folders), not bpy as a module")
        # The add-on as scripts/install_addon.sh installs it: a link in <user scripts>/addons.
        scripts = fresh_dir("batch_user_scripts")
        os.makedirs(os.path.join(scripts, "addons"))
        os.symlink(os.path.join(mt.REPO, "addon", "raysplats"), os.path.join(scripts, "addons", "raysplats"))
        env = dict(os.environ, BLENDER_USER_SCRIPTS=scripts, BLENDER_USER_CONFIG=os.path.join(scripts, "config"))
        out = os.path.join(scripts, "small.glb")
        for entry in (["--python", os.path.join(scripts, "addons", "raysplats", "cli.py")],
                      ["--python-expr", "import raysplats.cli as cli; cli.main()"]):
            with self.subTest(entry=entry[0]):
                if os.path.exists(out):
                    os.remove(out)
                result = subprocess.run([bpy.app.binary_path, "-b", "-noaudio"] + entry +
                                        ["--", "export", st.data_file("small.splat"), "-o", out],
                                        capture_output=True, text=True, env=env, timeout=600)
                self.assertEqual(result.returncode, 0, result.stdout + result.stderr)
                self.assertTrue(os.path.exists(out))
