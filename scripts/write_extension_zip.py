#!/usr/bin/env python3
# Writes one platform's extension zip from a staged add-on folder, as Blender's `extension build --split-platforms`
# does: the files at the zip's root, and the manifest's `platforms` narrowed to the one platform the zip is for (the
# repository's manifest lists every platform built). Sorted entries with fixed times, so the same files give the
# same zip; written beside the target and then moved over it.
#   scripts/write_extension_zip.py STAGE ZIP PLATFORM        (PLATFORM: linux-x64, windows-x64)
import os
import re
import sys
import zipfile


def narrowed_manifest(text, platform, path):
    pattern = re.compile(r"^platforms\s*=\s*\[([^\]]*)\]", re.MULTILINE)
    match = pattern.search(text)
    if not match:
        sys.exit(f"write_extension_zip: {path} has no 'platforms = [...]' line")
    listed = re.findall(r'"([^"]+)"', match.group(1))
    if platform not in listed:
        sys.exit(f"write_extension_zip: {path} does not list the platform {platform} (it lists {listed})")
    return text[:match.start()] + f'platforms = ["{platform}"]' + text[match.end():]


def main():
    stage, zip_path, platform = sys.argv[1:4]
    manifest = os.path.join(stage, "blender_manifest.toml")
    with open(manifest, encoding="utf-8") as handle:
        text = narrowed_manifest(handle.read(), platform, manifest)
    with open(manifest, "w", encoding="utf-8", newline="\n") as handle:
        handle.write(text)
    temporary = zip_path + ".tmp"
    with zipfile.ZipFile(temporary, "w", zipfile.ZIP_DEFLATED, compresslevel=9) as archive:
        for folder, folders, files in os.walk(stage):
            folders.sort()
            for name in sorted(files):
                path = os.path.join(folder, name)
                info = zipfile.ZipInfo(os.path.relpath(path, stage).replace(os.sep, "/"), date_time=(1980, 1, 1, 0, 0, 0))
                binary = name.endswith((".so", ".pyd")) or ".so." in name
                info.external_attr = (0o755 if binary else 0o644) << 16
                info.compress_type = zipfile.ZIP_DEFLATED
                with open(path, "rb") as source:
                    archive.writestr(info, source.read())
    os.replace(temporary, zip_path)


if __name__ == "__main__":
    main()
