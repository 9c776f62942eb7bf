#!/usr/bin/env python3
# Checks the Windows extension zip: it carries the native module for Python 3.11 and 3.13 and no other binary; each
# module imports only its own Python's DLL and DLLs every Windows has (no libstdc++, libgcc, winpthread, TBB or Embree
# DLL: all of it is linked in); no file in the zip has the name of a DLL Blender for Windows ships (Windows would
# load Blender's copy instead); the manifest names windows-x64 alone.
#   scripts/windows/check_windows_zip.py dist/raysplats-<version>-windows_x64.zip
# Exit status 0 when all holds, 1 with one line per problem otherwise.
import os
import re
import subprocess
import sys
import tempfile
import zipfile

MODULES = {"_native.cp311-win_amd64.pyd": "python311.dll", "_native.cp313-win_amd64.pyd": "python313.dll"}
# Windows' own DLLs (lower case): the C runtime MinGW targets, the kernel, and the few system libraries the module may
# use. Anything else would have to travel in the zip.
SYSTEM_DLLS = {"kernel32.dll", "msvcrt.dll", "advapi32.dll", "user32.dll", "shell32.dll", "ws2_32.dll", "psapi.dll"}
# DLLs in Blender for Windows' own folder (4.2 to 5.3) that a library of ours could be mistaken for.
BLENDER_DLLS = {"embree4.dll", "tbb.dll", "tbb12.dll", "tbbmalloc.dll", "openvdb.dll", "osdcpu.dll", "osdgpu.dll",
                "openimagedenoise.dll", "openimagedenoise_core.dll", "python3.dll", "zlib.dll", "zstd.dll",
                "libgmp-10.dll", "libgmpxx.dll", "libfftw3-3.dll", "sycl7.dll", "shaderc_shared.dll"}


def imported_dlls(path):
    output = subprocess.run(["x86_64-w64-mingw32-objdump", "-p", path], check=True, capture_output=True,
                            text=True).stdout
    return [name for name in re.findall(r"DLL Name: (\S+)", output)]


def check(zip_path):
    problems = []
    with zipfile.ZipFile(zip_path) as archive:
        names = archive.namelist()
        manifest = archive.read("blender_manifest.toml").decode("utf-8")
        platforms = re.search(r'^platforms\s*=\s*\[([^\]]*)\]', manifest, re.MULTILINE)
        if not platforms or re.findall(r'"([^"]+)"', platforms.group(1)) != ["windows-x64"]:
            problems.append(f"the manifest's platforms are not exactly windows-x64: {platforms and platforms.group(0)}")
        binaries = [name for name in names if name.lower().endswith((".pyd", ".dll", ".exe", ".so"))]
        for name in sorted(set(binaries) - set(MODULES)):
            problems.append(f"{name}: a binary the Windows zip should not carry")
        for name in sorted(set(MODULES) - set(names)):
            problems.append(f"{name}: missing from the zip")
        for name in names:
            if os.path.basename(name).lower() in BLENDER_DLLS:
                problems.append(f"{name}: Blender for Windows ships a DLL of this name, which would be loaded instead")
        with tempfile.TemporaryDirectory(prefix="raysplats-winzip-") as directory:
            for module, python_dll in MODULES.items():
                if module not in names:
                    continue
                path = archive.extract(module, directory)
                for dll in imported_dlls(path):
                    if dll.lower() not in SYSTEM_DLLS | {python_dll}:
                        problems.append(f"{module} imports {dll}, which is neither Windows' own nor {python_dll}")
                print(f"{module}: imports {', '.join(imported_dlls(path))}")
    return problems


def main():
    problems = check(sys.argv[1])
    for problem in problems:
        print(f"check_windows_zip: {problem}")
    if not problems:
        print(f"check_windows_zip: {os.path.basename(sys.argv[1])} carries both modules, each needing only Windows "
              "and its Python")
    sys.exit(1 if problems else 0)


if __name__ == "__main__":
    main()
