# farm/install_worker.sh on a worker's Blender, each case in a fresh user folder: the extension zip installs, the
# worker renders with it in a new Blender process and runs its command line as a farm job does; a zip without the
# native module, or with only another Python's, and a file that is no extension zip fail with a non-zero status and
# a message that says why.
#   python3 test_install_worker.py --zip dist/raysplats-0.1.0-linux_x64.zip --data-dir ../shared/data --tmp-dir DIR
#           [--blender blender | --bpy-python ~/.cache/raysplats/bpy45-venv/bin/python]
import argparse
import os
import shutil
import subprocess
import sys
import unittest

# The test command's reporting: skips counted and named, exit 77 (a skip for ctest) when every test skipped.
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scripts", "lib"))
import unittest_report  # noqa: E402
import zipfile

HERE = os.path.dirname(os.path.abspath(__file__))
INSTALL = os.path.join(os.path.dirname(HERE), "install_worker.sh")
ARGS = None


def install(case, zip_path=None):
    """Runs install_worker.sh with a fresh user folder; returns (status, stdout + stderr, user folder)."""
    user = os.path.join(ARGS.tmp_dir, case)
    shutil.rmtree(user, ignore_errors=True)
    os.makedirs(user)
    command = [INSTALL]
    command += ["--bpy-python", ARGS.bpy_python] if ARGS.bpy_python else ["--blender", ARGS.blender]
    if zip_path:
        command.append(zip_path)
    env = dict(os.environ, BLENDER_USER_RESOURCES=user, TMPDIR=ARGS.tmp_dir)
    run = subprocess.run(command, env=env, capture_output=True, text=True, timeout=300)
    return run.returncode, run.stdout + run.stderr, user


def worker_python():
    """The worker Blender's Python as "311" or "313" (Blender 5.1+ embeds 3.13; the test itself may run on another)."""
    probe = "import sys; print('WORKER_PYTHON %d%d' % sys.version_info[:2])"
    if ARGS.bpy_python:
        command = [ARGS.bpy_python, "-c", probe]
    else:
        command = [ARGS.blender, "-b", "--factory-startup", "-noaudio", "--python-expr", probe]
    output = subprocess.run(command, capture_output=True, text=True, timeout=300).stdout
    return next(line.split()[1] for line in output.splitlines() if line.startswith("WORKER_PYTHON "))


def variant(name, drop):
    """A copy of the zip without the members `drop` picks (stored, not compressed: it is read once)."""
    path = os.path.join(ARGS.tmp_dir, name)
    with zipfile.ZipFile(ARGS.zip) as source, zipfile.ZipFile(path, "w", zipfile.ZIP_STORED) as target:
        for info in source.infolist():
            if not drop(info.filename):
                target.writestr(info.filename, source.read(info))
    return path


class InstallWorker(unittest.TestCase):
    def test_installs_and_renders(self):
        status, output, user = install("ok", ARGS.zip)
        self.assertEqual(status, 0, output)
        self.assertIn("check_worker: RAYSPLATS works in Blender", output)
        # The add-on the fresh process rendered with is the installed copy, in this user folder.
        self.assertRegex(output, r"add-on \S*raysplats at " + os.path.realpath(user))
        self.assertIn(f"_native.cpython-{worker_python()}", output)

    def test_installed_command_line_converts(self):
        # The add-on's command line as a farm job runs it (farm/openjd/raysplats_convert.yaml): imported from the
        # enabled add-on, "raysplats" on 3.x, "bl_ext.user_default.raysplats" as an extension.
        status, output, user = install("cli", ARGS.zip)
        self.assertEqual(status, 0, output)
        target = os.path.join(ARGS.tmp_dir, "cli_out", "small.spz")
        shutil.rmtree(os.path.dirname(target), ignore_errors=True)
        runner = (
            "import importlib, os, sys\n"
            "import bpy\n"
            "if not bpy.app.binary_path:  # Blender as a module: enable the installed extension, as a job script does\n"
            "    bpy.ops.preferences.addon_enable(module='bl_ext.user_default.raysplats')\n"
            "name = next(n for n in bpy.context.preferences.addons.keys() if n.rsplit('.', 1)[-1] == 'raysplats')\n"
            "print('RUNNING', name)\n"
            "try:\n"
            "    importlib.import_module(name + '.cli').main(sys.argv[sys.argv.index('--') + 1:])\n"
            "except SystemExit as done:\n"
            "    sys.stdout.flush()\n"
            "    os._exit(done.code)\n")
        args = ["--", "convert", os.path.join(ARGS.data_dir, "small.splat"), "-o", os.path.dirname(target),
                "--format", "spz"]
        if ARGS.bpy_python:
            command = [ARGS.bpy_python, "-c", runner] + args
        else:
            command = [ARGS.blender, "-b", "-noaudio", "--python-expr", runner] + args
        run = subprocess.run(command, env=dict(os.environ, BLENDER_USER_RESOURCES=user), capture_output=True,
                             text=True, timeout=300)
        self.assertEqual(run.returncode, 0, run.stdout + run.stderr)
        self.assertRegex(run.stdout, r"RUNNING \S*raysplats")
        self.assertIn("raysplats convert: 1 of 1 done", run.stdout)
        self.assertGreater(os.path.getsize(target), 22_764 * 8)  # small.splat's 22,764 Gaussians, a few bytes each

    def test_zip_without_the_native_module_fails(self):
        status, output, _ = install("no_native", variant("no_native.zip", lambda n: n.startswith("_native")))
        self.assertEqual(status, 1, output)
        self.assertIn("native module", output)
        self.assertIn("the add-on has no native module", output)
        self.assertIn("install_worker: the worker cannot render with RaySplats", output)

    def test_zip_for_another_python_fails(self):
        # Only the other Python's module (3.13 for Blender 4.2-5.0 and 3.4, 3.11 for 5.1+): the worker cannot load it.
        own = worker_python()
        other = "311" if own == "313" else "313"
        zip_path = variant(f"python{other}_only.zip", lambda n: n.startswith(f"_native.cpython-{own}"))
        status, output, _ = install("wrong_python", zip_path)
        self.assertEqual(status, 1, output)
        self.assertIn(f"Python {own[0]}.{own[1:]}", output)
        self.assertIn(f"_native.cpython-{other}-x86_64-linux-gnu.so", output)  # what the add-on has instead

    def test_not_an_extension_zip_fails(self):
        zip_path = variant("no_manifest.zip", lambda n: n == "blender_manifest.toml")
        status, output, _ = install("no_manifest", zip_path)
        self.assertEqual(status, 1, output)
        self.assertIn("no_manifest.zip is not the RaySplats extension zip: no blender_manifest.toml", output)


class SourceTreeInstall(unittest.TestCase):
    """Blender 3.x without a zip: scripts/install_addon.sh links the source tree's add-on."""

    def test_links_the_source_tree_and_renders(self):
        status, output, user = install("source_tree")
        self.assertEqual(status, 0, output)
        self.assertIn("check_worker: RAYSPLATS works in Blender 3.", output)
        link = os.path.join(user, "scripts", "addons", "raysplats")
        self.assertTrue(os.path.islink(link), link)
        repository = os.path.dirname(os.path.dirname(HERE))
        self.assertEqual(os.path.realpath(link), os.path.join(repository, "addon", "raysplats"))


def main():
    global ARGS
    parser = argparse.ArgumentParser()
    parser.add_argument("--zip", required=True)
    parser.add_argument("--tmp-dir", required=True)
    parser.add_argument("--data-dir", required=True, help="the real scenes (shared/data)")
    parser.add_argument("--blender", default="blender")
    parser.add_argument("--bpy-python")
    parser.add_argument("--source-tree", action="store_true", help="also install from the source tree (Blender 3.x)")
    ARGS = parser.parse_args()
    ARGS.tmp_dir = os.path.abspath(ARGS.tmp_dir)
    ARGS.zip = os.path.abspath(ARGS.zip)
    os.makedirs(ARGS.tmp_dir, exist_ok=True)
    loader = unittest.TestLoader()
    suite = loader.loadTestsFromTestCase(InstallWorker)
    if ARGS.source_tree:
        suite.addTests(loader.loadTestsFromTestCase(SourceTreeInstall))
    sys.exit(unittest_report.run(suite))


if __name__ == "__main__":
    main()
