# The native module's render cost on the platform it runs on: the same script in Linux's Python and, under Wine, in
# Windows' (scripts/windows/wine_python.sh), on the same scene, camera and settings, so that the CPU seconds per
# sample of the Linux and the Windows build can be set side by side. Prints the instruction set Embree ran with,
# the BVH build, and the process's CPU seconds per sample over several renders (the median).
#   python examples/benchmark_platform_render.py MODULE_DIR DATA_DIR [--scene unicorn_sh3_reordered.ply]
#       [--size 640x360] [--samples 4] [--repeats 3]
#   scripts/windows/wine_python.sh 3.11 examples/benchmark_platform_render.py build-windows/native/python/python311 ...
import argparse
import os
import statistics
import sys
import time

import numpy as np

parser = argparse.ArgumentParser()
parser.add_argument("module_dir")
parser.add_argument("data_dir")
parser.add_argument("--scene", default="unicorn_sh3_reordered.ply")
parser.add_argument("--size", default="640x360")
parser.add_argument("--samples", type=int, default=4)
parser.add_argument("--repeats", type=int, default=3)
args = parser.parse_args()
sys.path.insert(0, args.module_dir)
import _native  # noqa: E402

width, height = (int(v) for v in args.size.split("x"))
cloud = _native.read_splats(os.path.join(args.data_dir, args.scene))
scene = _native.RenderScene()
scene.add_material()
scene.add_gaussians(cloud["positions"], cloud["rotations"], cloud["scales"], cloud["opacities"], cloud["sh"])
centre = cloud["positions"].mean(axis=0)
size = float(np.percentile(np.linalg.norm(cloud["positions"] - centre, axis=1), 90))
cpu = time.process_time()
scene.build()
build_cpu = time.process_time() - cpu
camera = np.eye(4, dtype=np.float32)
camera[:3, 3] = centre + np.array([0.0, 0.0, 2.5 * size])
per_sample = []
for _ in range(args.repeats):
    cpu, wall = time.process_time(), time.perf_counter()
    job = _native.RenderJob(scene, {"matrix": camera}, {"width": width, "height": height, "samples": args.samples,
                                                        "seed": 1})
    while not job.wait(0.5):
        pass
    job.result()
    per_sample.append((time.process_time() - cpu) / args.samples)
print(f"platform {sys.platform}, Python {sys.version.split()[0]}, Embree {scene.embree_device}")
print(f"{args.scene} ({len(cloud['opacities'])} Gaussians) at {width}x{height}, {args.samples} samples: BVH build "
      f"{build_cpu:.3f} CPU-s, render {statistics.median(per_sample):.3f} CPU-s per sample "
      f"(median of {args.repeats}: {', '.join(f'{v:.3f}' for v in per_sample)})")
