"""Installs RaySplats into a render-farm worker's Blender, headless, then checks in a fresh Blender process that the
worker can render with it (farm/check_worker.py: add-on enabled, RAYSPLATS engine registered, native module loaded
for that Blender's Python, a tiny render through the engine). Any Python 3.11+ runs it, on Linux, Windows or macOS
(only the standard library), and so does the worker's Blender itself:
  python farm/install_worker.py [--blender EXE | --bpy-python PYTHON] [ZIP]
  blender -b --python farm/install_worker.py -- [--bpy-python PYTHON] [ZIP]        (this Blender, by default)
ZIP is the extension zip of scripts/package_extension.sh or scripts/windows/package.sh
(dist/raysplats-<version>-linux_x64.zip, dist/raysplats-<version>-windows_x64.zip).
  Blender 4.2+ (EXE, default `blender`): Blender's own `EXE --command extension install-file -r user_default -e ZIP`.
  Blender as a Python module (PyPI bpy 4.2+, --bpy-python): the implementation of that same command, through bpy.
  Blender 3.x (Debian 12's 3.4, which has no extensions): ZIP unpacked into the user add-on folder as raysplats/
  and enabled; without ZIP, this source tree's add-on (built by scripts/build.sh) is linked there and enabled.
The user folder is Blender's default for the user running this; BLENDER_USER_RESOURCES picks another (one per
worker slot, or a shared read-only one), and the jobs must then run with the same.
Exit status: 0 installed and checked; 1 the install or the check failed (the reason on stderr); 2 bad arguments."""
import argparse
import glob
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import tomllib
import zipfile

HERE = os.path.dirname(os.path.abspath(__file__))
SOURCE_ADDON = os.path.join(os.path.dirname(HERE), "addon", "raysplats")
CHECK = os.path.join(HERE, "check_worker.py")
PROBE = "RAYSPLATS_WORKER "

# Blender as a Python module: bl_pkg's `extension install-file` handler, what `blender --command extension
# install-file` runs.
BPY_INSTALL = """\
import os, sys
import bpy
if bpy.app.version < (4, 2, 0):
    sys.exit(f"install_worker: Blender {bpy.app.version_string} has no extensions (4.2+); use its add-on folder")
from bl_pkg import bl_extension_cli
status = bl_extension_cli.cli_extension_handler(["install-file", "--repo", "user_default", "--enable", sys.argv[1]])
sys.stdout.flush()
sys.stderr.flush()
os._exit(status)  # bpy as a module crashes at exit while the enabled add-on's classes are registered
"""
# A Blender's version and user add-on folder, one line (JSON: the folder may hold any character).
BLENDER_PROBE = (f"import bpy, json; print({PROBE!r} + json.dumps(['%d.%d' % bpy.app.version[:2], "
                 "bpy.utils.user_resource('SCRIPTS', path='addons', create=True)]))")
ENABLE = "import bpy\nbpy.ops.preferences.addon_enable(module='raysplats')\nbpy.ops.wm.save_userpref()"


class Failure(Exception):
    """The install cannot go on: the message says why (exit status 1)."""


def this_platform():
    """This system as extension manifests name platforms (windows-x64, linux-x64, macos-arm64: Blender's bl_pkg)."""
    system = {"win32": "windows", "darwin": "macos"}.get(sys.platform, sys.platform)
    machine = platform.machine().lower()
    machine = {"x86_64": "x64", "amd64": "x64", "aarch64": "arm64"}.get(machine, machine)
    return f"{system}-{machine}"


def check_zip(path):
    """Refuses a file that is not the extension zip (the add-on's package at the root, with Blender's manifest), and
    the zip of another platform: Blender's installer says it installed nothing, yet exits with status 0."""
    try:
        with zipfile.ZipFile(path) as archive:
            names = set(archive.namelist())
            missing = {"__init__.py", "blender_manifest.toml"} - names
            if missing:
                raise Failure(f"{path} is not the RaySplats extension zip: no {', '.join(sorted(missing))} at its "
                              "root")
            manifest = tomllib.loads(archive.read("blender_manifest.toml").decode("utf-8"))
    except (OSError, zipfile.BadZipFile) as error:
        raise Failure(f"{path} is not a zip file ({error})")
    except (UnicodeDecodeError, tomllib.TOMLDecodeError) as error:
        raise Failure(f"{path} is not the RaySplats extension zip: its blender_manifest.toml does not parse ({error})")
    platforms = manifest.get("platforms") or []
    if platforms and this_platform() not in platforms:
        raise Failure(f"{path} is for {', '.join(platforms)}, not this worker's {this_platform()}: install the zip "
                      f"made for {this_platform()}")


def run(command):
    """Runs a worker's Blender (or its bpy Python) headless; returns its exit status and output (stdout and stderr
    together). A pipe, not a file: under Wine a process that bpy starts holds its handles a moment after it ends."""
    done = subprocess.run(command, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    return done.returncode, done.stdout.decode("utf-8", errors="replace")


def fail(output, message):
    """Shows the output of what just failed and stops with `message`."""
    sys.stderr.write(output)
    raise Failure(message)


def blender_info(blender):
    """(version as (major, minor), user add-on folder) of a Blender executable."""
    status, output = run([blender, "-b", "--factory-startup", "-noaudio", "--python-expr", BLENDER_PROBE])
    for line in output.splitlines() if status == 0 else ():
        if line.startswith(PROBE):
            version, addons = json.loads(line[len(PROBE):])
            return tuple(int(part) for part in version.split(".")), addons
    raise Failure(f"could not ask {blender} for its version and add-on folder")


def check(blender, bpy_python):
    """check_worker.py in a fresh process, as a job starts the worker's Blender: its preferences, no source tree on
    sys.path. Its verdict goes to stderr; the whole output is kept in a log file when it fails."""
    if bpy_python:
        status, output = run([bpy_python, CHECK])
    else:
        status, output = run([blender, "-b", "-noaudio", "--python-exit-code", "1", "--python", CHECK])
    for line in output.splitlines():
        if line.startswith("check_worker:"):
            print(line, file=sys.stderr)
    if status != 0:
        handle, log = tempfile.mkstemp(prefix="raysplats_install_worker.", suffix=".log")
        with os.fdopen(handle, "w", encoding="utf-8") as out:
            out.write(output)
        raise Failure(f"the worker cannot render with RaySplats (above; full log: {log})")


def replace_addon(addons, make):
    """Puts a new `raysplats` into the add-on folder: `make(path)` builds it beside the old one, which is replaced
    only when that succeeded (a failed unpack leaves the old install as it was)."""
    os.makedirs(addons, exist_ok=True)
    target = os.path.join(addons, "raysplats")
    stage = tempfile.mkdtemp(prefix=".raysplats_install.", dir=addons)
    try:
        make(stage)
    except BaseException:
        shutil.rmtree(stage, ignore_errors=True)
        raise
    if os.path.islink(target) or os.path.isfile(target):
        os.remove(target)
    elif os.path.isdir(target):
        shutil.rmtree(target)
    os.replace(stage, target)


def unpack(zip_path, addons):
    def make(stage):
        try:
            with zipfile.ZipFile(zip_path) as archive:
                archive.extractall(stage)
        except (OSError, zipfile.BadZipFile) as error:
            raise Failure(f"could not unpack {zip_path} into {addons} ({error})")
        if os.name == "posix":  # readable by every user the jobs may run as (mkdtemp made the folder private)
            for folder, _, files in os.walk(stage):
                os.chmod(folder, os.stat(folder).st_mode | 0o755)
                for name in files:
                    path = os.path.join(folder, name)
                    os.chmod(path, os.stat(path).st_mode | 0o644)
    replace_addon(addons, make)


def link_source_tree(addons):
    """This source tree's add-on, linked (not copied): a developer's worker renders what scripts/build.sh built."""
    if not glob.glob(os.path.join(SOURCE_ADDON, "_native*")):
        raise Failure(f"the native module is not built in {SOURCE_ADDON}; run scripts/build.sh first, or give the "
                      "extension ZIP")

    def make(stage):
        os.rmdir(stage)
        os.symlink(SOURCE_ADDON, stage, target_is_directory=True)
    replace_addon(addons, make)


def install(blender, bpy_python, zip_path):
    if bpy_python:
        if not zip_path:
            raise Failure("--bpy-python needs the extension ZIP")
        if shutil.which(bpy_python) is None:
            raise Failure(f"no Python '{bpy_python}' (give --bpy-python PYTHON)")
        status, output = run([bpy_python, "-c", BPY_INSTALL, zip_path])
        if status != 0:
            fail(output, f"installing {zip_path} into {bpy_python}'s Blender failed (status {status})")
        check(blender, bpy_python)
        return
    if shutil.which(blender) is None:
        raise Failure(f"no Blender '{blender}' (give --blender EXE)")
    version, addons = blender_info(blender)
    name = "%d.%d" % version
    if version >= (4, 2):
        if not zip_path:
            raise Failure(f"Blender {name} installs extensions: give the extension ZIP")
        status, output = run([blender, "--command", "extension", "install-file", "--repo", "user_default", "--enable",
                              zip_path])
        if status != 0:
            fail(output, f"Blender {name}: extension install-file {zip_path} failed")
    else:
        if zip_path:
            unpack(zip_path, addons)
        else:
            link_source_tree(addons)
        status, output = run([blender, "-b", "-noaudio", "--python-exit-code", "1", "--python-expr", ENABLE])
        if status != 0:
            fail(output, f"Blender {name}: enabling raysplats failed")
    check(blender, bpy_python)


def parse_arguments(argv, own_blender):
    parser = argparse.ArgumentParser(
        prog="install_worker", usage="farm/install_worker.py [--blender EXE | --bpy-python PYTHON] [ZIP]",
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter, allow_abbrev=False)
    where = parser.add_mutually_exclusive_group()
    where.add_argument("--blender", default=own_blender or os.environ.get("BLENDER", "blender"),
                       help="the worker's Blender executable (default: $BLENDER, or blender on PATH)")
    where.add_argument("--bpy-python", help="a Python with Blender as a module (PyPI bpy 4.2+)")
    parser.add_argument("zip", nargs="?", metavar="ZIP", help="the extension zip")
    return parser.parse_args(argv)


def main():
    # Run by Blender (`blender -b --python install_worker.py -- ARGS`): its arguments follow "--", and the Blender
    # to install into is that one.
    own_blender = None
    if "bpy" in sys.modules:
        import bpy
        own_blender = bpy.app.binary_path or None
    argv = sys.argv[sys.argv.index("--") + 1:] if own_blender and "--" in sys.argv else sys.argv[1:]
    args = parse_arguments(argv, own_blender)
    try:
        zip_path = None
        if args.zip:
            if not os.path.isfile(args.zip):
                raise Failure(f"{args.zip}: no such file (make it with scripts/package_extension.sh)")
            zip_path = os.path.abspath(args.zip)
            check_zip(zip_path)
        install(args.blender, args.bpy_python, zip_path)
    except Failure as failure:
        print(f"install_worker: {failure}", file=sys.stderr, flush=True)
        sys.exit(1)
    except OSError as error:  # a worker's folder that cannot be written, an executable that cannot start
        print(f"install_worker: {error}", file=sys.stderr, flush=True)
        sys.exit(1)


if __name__ == "__main__":
    main()
