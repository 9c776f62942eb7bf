# Pipeline example: every splat file of a folder -> a Draco-compressed GLB and a PNG thumbnail.
#
#   blender -b --factory-startup --python examples/batch_draco_thumbnails.py -- SPLAT_FOLDER OUT_FOLDER \
#       [--size 320 240] [--samples 8] [--skip showroom_1.5M.ply]
#
# Copy it and change what you need. It drives the add-on's command line (addon/raysplats/cli.py) per file,
# so one bad file is reported and skipped while the others are still written, and every output appears
# complete or not at all. Exit status 0 when everything was written, 1 otherwise.
# The same without this script, from a shell:
#   blender -b --python addon/raysplats/cli.py -- export "scans/*.ply" -o out --format glb --draco
#   blender -b --python addon/raysplats/cli.py -- render "scans/*.ply" -o out --resolution 320 240
import argparse
import glob
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "addon"))

from raysplats import cli  # noqa: E402  (registers the add-on from this source tree when needed)


def main():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    parser = argparse.ArgumentParser(description="Splat folder -> Draco GLB + thumbnail per file")
    parser.add_argument("splat_folder")
    parser.add_argument("out_folder")
    parser.add_argument("--size", type=int, nargs=2, default=(320, 240), metavar=("W", "H"))
    parser.add_argument("--samples", type=int, default=8)
    parser.add_argument("--skip", action="append", default=[], help="file names to leave out")
    args = parser.parse_args(argv)

    inputs = sorted(path for pattern in ("*.ply", "*.splat", "*.spz")
                    for path in glob.glob(os.path.join(args.splat_folder, pattern))
                    if os.path.basename(path) not in args.skip)
    if not inputs:
        print(f"batch: no splat files in {args.splat_folder}")
        sys.exit(1)
    os.makedirs(args.out_folder, exist_ok=True)
    start = time.perf_counter()
    # cli.run() processes every file and returns 0, or 1 if any failed (it never stops at a bad file).
    status = cli.run(["export", *inputs, "-o", args.out_folder, "--format", "glb", "--draco"])
    status |= cli.run(["render", *inputs, "-o", args.out_folder, "--resolution", *map(str, args.size),
                       "--samples", str(args.samples)])
    print(f"batch: {len(inputs)} files in {time.perf_counter() - start:.1f} s -> {args.out_folder}"
          + ("" if status == 0 else " (some files FAILED, see above)"))
    sys.exit(status)


if __name__ == "__main__":
    cli.ensure_addon()
    main()
