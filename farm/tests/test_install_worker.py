# farm/install_worker.py on a worker's Blender, each case in a fresh user folder: the extension zip installs, the
# worker renders with it in a new Blender process and runs its command line as a farm job does; a zip without the
# native module, or with only another Python's, a zip of another platform and a file that is no extension zip fail
# with a non-zero status and a message that says why.
#   python3 test_install_worker.py --zip dist/raysplats-0.1.0-linux_x64.zip --data-dir ../shared/data --tmp-dir DIR
#           [--blender blender | --bpy-python ~/.cache/raysplats/bpy45-venv/bin/python]
# With --wine-site DIR (Blender 4.2 for Windows as a module, scripts/windows/setup_pythons.sh), a Windows worker under
# Wine: install_worker.py itself runs in Windows CPython 3.11 (scripts/windows/wine_python.sh), every path it is given
# (the zip, the user folder, the bpy Python) in Windows' form, and installs the Windows zip; the install, the check
# and the refusals of a file that is no extension zip and of the Linux zip are tested there.
import argparse
import os
import re
import shutil
import subprocess
import sys
import unittest

# The test command's reporting: skips counted and named, exit 77 (a skip for ctest) when every test skipped.
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scripts", "lib"))
import unittest_report  # noqa: E402
import zipfile

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
INSTALL = os.path.join(os.path.dirname(HERE), "install_worker.py")
WINE_PYTHON = os.path.join(REPO, "scripts", "windows", "wine_python.sh")
ARGS = None


def worker_path(path):
    """`path` as the worker is given it: under Wine in Windows' form, on the drive Wine maps to / (Z:\\work\\...)."""
    path = os.path.abspath(path)
    return "Z:" + path.replace("/", "\\") if ARGS.wine_site else path


def bpy_python():
    """The command that runs Blender as a Python module: the bpy venv's Python, or Windows' under Wine."""
    if ARGS.wine_site:
        return [WINE_PYTHON, "3.11", "--site", ARGS.wine_site]
    return [ARGS.bpy_python] if ARGS.bpy_python else None


def native_module(tag):
    """The file name of the zip's native module for the worker's Python `tag` ("311")."""
    return f"_native.cp{tag}-win_amd64.pyd" if ARGS.wine_site else f"_native.cpython-{tag}-x86_64-linux-gnu.so"


def install(case, zip_path=None, by_blender=False):
    """Runs install_worker.py with a fresh user folder (with by_blender, run by the worker's Blender itself, which it
    then installs into); returns (status, stdout + stderr, user folder)."""
    user = os.path.join(ARGS.tmp_dir, case)
    shutil.rmtree(user, ignore_errors=True)
    os.makedirs(user)
    if by_blender:
        command = [ARGS.blender, "-b", "-noaudio", "--python", INSTALL, "--"]
    elif ARGS.wine_site:
        # The Windows Python running the installer, with bpy on its path, is the worker's bpy Python too.
        command = bpy_python() + [worker_path(INSTALL), "--bpy-python", ARGS.windows_python]
    else:
        command = [sys.executable, INSTALL]
        command += ["--bpy-python", ARGS.bpy_python] if ARGS.bpy_python else ["--blender", ARGS.blender]
    if zip_path:
        command.append(worker_path(zip_path))
    # TMPDIR stays a Linux path: under Wine, wineserver reads it too (and Windows' Python takes it as on Z:).
    env = dict(os.environ, BLENDER_USER_RESOURCES=worker_path(user), TMPDIR=ARGS.tmp_dir)
    run = subprocess.run(command, env=env, capture_output=True, text=True, timeout=600)
    return run.returncode, run.stdout + run.stderr, user


def worker_python():
    """The worker Blender's Python as "311" or "313" (Blender 5.1+ embeds 3.13; the test itself may run on another)."""
    probe = "import sys; print('WORKER_PYTHON %d%d' % sys.version_info[:2])"
    if bpy_python():
        command = bpy_python() + ["-c", probe]
    else:
        command = [ARGS.blender, "-b", "--factory-startup", "-noaudio", "--python-expr", probe]
    output = subprocess.run(command, capture_output=True, text=True, timeout=300).stdout
    return next(line.split()[1] for line in output.splitlines() if line.startswith("WORKER_PYTHON "))


def variant(name, drop=lambda member: False, manifest=lambda text: text):
    """A copy of the zip without the members `drop` picks and with its manifest's text through `manifest` (stored,
    not compressed: it is read once)."""
    path = os.path.join(ARGS.tmp_dir, name)
    with zipfile.ZipFile(ARGS.zip) as source, zipfile.ZipFile(path, "w", zipfile.ZIP_STORED) as target:
        for info in source.infolist():
            if drop(info.filename):
                continue
            data = source.read(info)
            if info.filename == "blender_manifest.toml":
                data = manifest(data.decode()).encode()
            target.writestr(info.filename, data)
    return path


class InstallWorker(unittest.TestCase):
    def test_installs_and_renders(self):
        status, output, user = install("ok", ARGS.zip)
        self.assertEqual(status, 0, output)
        self.assertIn("check_worker: RAYSPLATS works in Blender", output)
        # The add-on the fresh process rendered with is the installed copy, in this user folder.
        self.assertRegex(output, r"add-on \S*raysplats at " + re.escape(worker_path(os.path.realpath(user))))
        self.assertIn(f"native module {native_module(worker_python())}", output)
        if ARGS.wine_site:  # the user folder given in Windows' form is the one the files went to
            installed = os.path.join(user, "extensions", "user_default", "raysplats", native_module("311"))
            self.assertTrue(os.path.isfile(installed), installed)

    def test_run_by_the_workers_blender(self):
        # A worker with no Python of its own: its Blender runs the installer and is the Blender installed into.
        if bpy_python():
            self.skipTest("expected: Blender as a module has no executable to run the installer with")
        status, output, user = install("by_blender", ARGS.zip, by_blender=True)
        self.assertEqual(status, 0, output)
        self.assertRegex(output, r"check_worker: RAYSPLATS works in Blender .* add-on \S*raysplats at "
                         + re.escape(os.path.realpath(user)))

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
            command = bpy_python() + ["-c", runner] + args
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
        zip_path = variant(f"python{other}_only.zip", lambda n: n == native_module(own))
        status, output, _ = install("wrong_python", zip_path)
        self.assertEqual(status, 1, output)
        self.assertIn(f"Python {own[0]}.{own[1:]}", output)
        self.assertIn(native_module(other), output)  # what the add-on has instead

    def test_not_an_extension_zip_fails(self):
        zip_path = variant("no_manifest.zip", lambda n: n == "blender_manifest.toml")
        status, output, _ = install("no_manifest", zip_path)
        self.assertEqual(status, 1, output)
        self.assertIn(f"install_worker: {worker_path(zip_path)} is not the RaySplats extension zip: no "
                      "blender_manifest.toml at its root", output)

    def test_zip_for_another_platform_fails(self):
        # Blender's installer leaves such a zip out, says so and exits with status 0: the check would then only see
        # an add-on that is not enabled.
        own, other = ("windows-x64", "linux-x64") if ARGS.wine_site else ("linux-x64", "windows-x64")
        zip_path = variant("other_platform.zip", manifest=lambda text: re.sub(
            r"^platforms = .*$", f'platforms = ["{other}"]', text, count=1, flags=re.M))
        status, output, _ = install("other_platform", zip_path)
        self.assertEqual(status, 1, output)
        self.assertIn(f"install_worker: {worker_path(zip_path)} is for {other}, not this worker's {own}", output)


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
    parser.add_argument("--wine-site", help="Blender 4.2 for Windows as a module: a Windows worker under Wine")
    ARGS = parser.parse_args()
    ARGS.tmp_dir = os.path.abspath(ARGS.tmp_dir)
    ARGS.zip = os.path.abspath(ARGS.zip)
    os.makedirs(ARGS.tmp_dir, exist_ok=True)
    loader = unittest.TestLoader()
    if ARGS.wine_site:
        # The Windows python.exe, as Windows names it, for --bpy-python (bpy comes from the PYTHONPATH it inherits).
        probe = subprocess.run([WINE_PYTHON, "3.11", "-c", "import sys; print('WINDOWS_PYTHON', sys.executable)"],
                               capture_output=True, text=True, timeout=300)
        found = [line.split(" ", 1)[1] for line in probe.stdout.splitlines() if line.startswith("WINDOWS_PYTHON ")]
        if probe.returncode != 0 or not found:
            sys.exit(f"test_install_worker: Windows Python 3.11 does not run under Wine:\n{probe.stdout}{probe.stderr}")
        ARGS.windows_python = found[0]
        ARGS.bpy_python = ARGS.windows_python
        # An install imports bpy for Windows twice, slowly under Wine: the install and the refusals (which stop
        # before Blender runs) are what differs on Windows.
        suite = unittest.TestSuite(InstallWorker(name) for name in (
            "test_installs_and_renders", "test_not_an_extension_zip_fails", "test_zip_for_another_platform_fails"))
        sys.exit(unittest_report.run(suite))
    suite = loader.loadTestsFromTestCase(InstallWorker)
    if ARGS.source_tree:
        suite.addTests(loader.loadTestsFromTestCase(SourceTreeInstall))
    sys.exit(unittest_report.run(suite))


if __name__ == "__main__":
    main()
