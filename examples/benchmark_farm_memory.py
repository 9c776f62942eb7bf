# Memory a render-farm worker needs for a big scene: a splat file imported in each form (polygons in pieces, compact
# points), saved as a .blend, then rendered headless in a fresh worker process (farm/tests/render_worker.py: open the
# .blend, render one frame with RaySplats), whose peak resident memory is measured; and the same for a .blend with
# only a camera (Blender, the add-on and the core alone), so that the scene's share and its bytes per Gaussian show.
#   blender -b --factory-startup --python examples/benchmark_farm_memory.py -- [FILE] [--work DIR] [--size W H]
#   ~/.cache/raysplats/bpy45-venv/bin/python examples/benchmark_farm_memory.py -- [FILE] ...       (PyPI bpy)
# FILE defaults to showroom_1.5M.ply.
import argparse
import os
import subprocess
import sys
import tempfile
import time

import bpy

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
parser = argparse.ArgumentParser()
parser.add_argument("file", nargs="?", default=os.path.join(REPO, "..", "shared", "data", "showroom_1.5M.ply"))
parser.add_argument("--work", default=tempfile.gettempdir(), help="folder for the .blend files and frames")
parser.add_argument("--size", type=int, nargs=2, default=(960, 540), metavar=("W", "H"))
parser.add_argument("--samples", type=int, default=4)
args = parser.parse_args(argv)

sys.path.insert(0, os.path.join(REPO, "addon"))
import raysplats  # noqa: E402

raysplats.register()
from raysplats.io import import_splats
from raysplats import cli  # noqa: E402

AS_MODULE = not bpy.app.binary_path
WORKER = os.path.join(REPO, "farm", "tests", "render_worker.py")


def save_shot(name, representation=None):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    count = 0
    if representation:
        obj, _, _ = import_splats.import_gaussian_splats(bpy.context, args.file, representation=representation)
        count = len(obj.data.vertices) if representation == "POINTS" else sum(
            len(o.data.polygons) for o in scene.objects if o.type == "MESH")
        cli.frame_camera(scene)
    else:
        camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
        scene.collection.objects.link(camera)
        scene.camera = camera
    scene.render.engine = "RAYSPLATS"
    scene.render.resolution_x, scene.render.resolution_y = args.size
    scene.render.resolution_percentage = 100
    scene.raysplats.samples = args.samples
    path = os.path.join(args.work, f"farm_memory_{name}.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path, compress=False)
    return path, count


def worker_peak(blend):
    """Peak resident memory (bytes) and wall time of a fresh worker process rendering frame 1 of `blend`."""
    worker_args = ["--addon-dir", os.path.join(REPO, "addon"), "--blend", blend, "--output",
                   os.path.join(args.work, "farm_memory_####"), "--frames", "1", "1"]
    if AS_MODULE:
        command = [sys.executable, WORKER] + worker_args
    else:
        command = [bpy.app.binary_path, "-b", "-noaudio", "--factory-startup", "--python", WORKER, "--"] + worker_args
    # A wrapper process of its own, so that RUSAGE_CHILDREN's maximum is this worker's alone.
    wrapper = ("import resource, subprocess, sys; status = subprocess.run(sys.argv[1:], stdout=subprocess.DEVNULL)"
               ".returncode; print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss); sys.exit(status)")
    started = time.perf_counter()
    result = subprocess.run(["/usr/bin/python3", "-c", wrapper] + command, capture_output=True, text=True, check=True)
    return int(result.stdout.split()[-1]) * 1024, time.perf_counter() - started


empty_blend, _ = save_shot("empty")
shots = [("pieces (polygons)", *save_shot("pieces", "POLYGONS")), ("compact points", *save_shot("compact", "POINTS"))]
raysplats.unregister()
empty_peak, empty_seconds = worker_peak(empty_blend)
print(f"\nBlender {bpy.app.version_string}, {os.path.basename(args.file)}, {args.size[0]} x {args.size[1]}, "
      f"{args.samples} samples; a worker with only a camera: peak {empty_peak / 1e9:.2f} GB ({empty_seconds:.1f} s)")
print(f"{'form':20} {'Gaussians':>10} {'.blend':>9} {'peak RSS':>9} {'scene':>9} {'B/Gaussian':>10} {'wall':>7}")
for name, blend, count in shots:
    peak, seconds = worker_peak(blend)
    print(f"{name:20} {count:>10,} {os.path.getsize(blend) / 1e9:7.2f} GB {peak / 1e9:6.2f} GB "
          f"{(peak - empty_peak) / 1e9:6.2f} GB {(peak - empty_peak) / max(count, 1):10.0f} {seconds:6.1f} s")
