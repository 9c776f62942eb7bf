#!/usr/bin/env python3
# Checks that the extension zip needs nothing from the system but glibc and libstdc++: every NEEDED entry of
# every shared object in the zip is either a file beside it in the zip or one of the allowed system libraries,
# and the dynamic loader, with an empty LD_LIBRARY_PATH, resolves each of them to exactly that (ldd). Prints
# the newest glibc and libstdc++ symbol versions the objects need (the minimum system they run on).
#   scripts/check_extension_libraries.py dist/raysplats-<version>-linux_x64.zip
# Exit status 0 when everything resolves, 1 with one line per problem otherwise.
import os
import re
import subprocess
import sys
import tempfile
import zipfile

# What every Linux that runs Blender has: glibc's libraries, the loader, and GCC's C++ runtime (which Blender
# itself needs). Anything else must travel in the zip.
ALLOWED_SYSTEM_LIBRARIES = {
    "libc.so.6", "libm.so.6", "libpthread.so.0", "libdl.so.2", "librt.so.1", "ld-linux-x86-64.so.2",
    "libstdc++.so.6", "libgcc_s.so.1",
}


def readelf(*args):
    return subprocess.run(["readelf", *args], check=True, capture_output=True, text=True).stdout


def needed_entries(path):
    return re.findall(r"\(NEEDED\)\s+Shared library: \[([^\]]+)\]", readelf("-d", path))


def search_paths(path):
    return re.findall(r"\((?:RPATH|RUNPATH)\)\s+Library (?:rpath|runpath): \[([^\]]*)\]", readelf("-d", path))


def required_versions(path, prefix):
    """The symbol versions `path` requires with this prefix (GLIBC_, GLIBCXX_), as tuples of ints."""
    return {tuple(int(part) for part in name.split(".")) for name in
            re.findall(rf"Name: {prefix}([0-9.]+)\b", readelf("-V", "-W", path))}


def ldd(path):
    """name -> resolved path (None: not found) as the loader sees it with an empty LD_LIBRARY_PATH."""
    environment = {"PATH": os.environ.get("PATH", "/usr/bin:/bin"), "LD_LIBRARY_PATH": ""}
    output = subprocess.run(["ldd", path], capture_output=True, text=True, env=environment).stdout
    resolved = {}
    for line in output.splitlines():
        match = re.match(r"\s*(\S+) => (not found|(\S+) \(0x)", line)
        if match:
            resolved[match.group(1)] = None if match.group(2) == "not found" else match.group(3)
    return resolved


def version_text(version):
    return ".".join(str(part) for part in version)


def check(zip_path):
    problems = []
    with tempfile.TemporaryDirectory(prefix="raysplats-zip-") as directory:
        with zipfile.ZipFile(zip_path) as archive:
            archive.extractall(directory)
        objects = []
        for folder, _, files in os.walk(directory):
            objects += [os.path.join(folder, name) for name in files if re.search(r"\.so(\.[0-9]+)*$", name)]
        if not objects:
            return [f"{zip_path}: no shared objects in the zip"], None, None
        glibc, glibcxx = set(), set()
        for path in sorted(objects):
            name = os.path.relpath(path, directory)
            here = set(os.listdir(os.path.dirname(path)))
            for needed in needed_entries(path):
                if needed not in here and needed not in ALLOWED_SYSTEM_LIBRARIES:
                    problems.append(f"{name}: NEEDED {needed} is neither in the zip beside it nor an allowed system library")
            bundled = [needed for needed in needed_entries(path) if needed in here]
            if bundled and "$ORIGIN" not in search_paths(path):
                problems.append(f"{name}: needs {', '.join(bundled)} from the zip but its RPATH is {search_paths(path)}, not $ORIGIN")
            for needed, resolved in ldd(path).items():
                if resolved is None:
                    problems.append(f"{name}: the loader finds no {needed}")
                elif needed in ALLOWED_SYSTEM_LIBRARIES:
                    continue
                elif os.path.dirname(os.path.realpath(resolved)) != os.path.dirname(os.path.realpath(path)):
                    problems.append(f"{name}: {needed} resolves to {resolved}, outside the zip")
            glibc |= required_versions(path, "GLIBC_")
            glibcxx |= required_versions(path, "GLIBCXX_")
        print(f"{len(objects)} shared objects: " + ", ".join(sorted(os.path.relpath(p, directory) for p in objects)))
    return problems, max(glibc, default=None), max(glibcxx, default=None)


def main():
    if len(sys.argv) != 2 or not os.path.isfile(sys.argv[1]):
        sys.exit("usage: check_extension_libraries.py EXTENSION.zip (an existing file)")
    problems, glibc, glibcxx = check(sys.argv[1])
    for problem in problems:
        print("PROBLEM:", problem)
    if glibc:
        print(f"minimum glibc {version_text(glibc)}, libstdc++ with GLIBCXX_{version_text(glibcxx)}")
    print("bundled libraries: " + ("FAILED" if problems else "all resolve inside the zip or to allowed system libraries"))
    sys.exit(1 if problems else 0)


if __name__ == "__main__":
    main()
