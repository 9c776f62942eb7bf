# Camera Rays as Splats' pre-pass and samples of showroom_1.5M at 640 x 360 (1 sample, sorted, Blackman-Harris 1.5),
# from far (the whole scene) and facing, in the CPU seconds the core reports for each (median of --frames), with the
# scene keeping its storage between frames as Persistent Data does. Given two builds of the native module (--b), it
# renders with each in turn, alternating frame by frame in one process, so that a busy or slowing machine weighs on
# both alike, and makes the two scenes in one order for half the frames and in the other for the rest; it prints each
# build's medians, tile-list entries and a hash of the image (equal hashes: the same image bit for bit). --ground
# renders instead the scene of examples/benchmark_frame_cost.py (its ground plane, sun and camera, view "f12"), whose
# plane pixels trace bounce and shadow rays through the Gaussians' BVH.
#   blender -b --factory-startup --python examples/benchmark_camera_splat_prepass.py -- \
#       --a addon/raysplats/_native.cpython-311-x86_64-linux-gnu.so [--b OTHER_BUILD.so] [--frames 10] [--ground]
import argparse
import hashlib
import importlib.machinery
import importlib.util
import os
import sys
import time
import types

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
parser = argparse.ArgumentParser()
parser.add_argument("--a", required=True, help="a native module file (_native.cpython-*.so)")
parser.add_argument("--b", help="another build of it to compare with")
parser.add_argument("--data", default=os.path.join(HERE, "..", "..", "shared", "data"))
parser.add_argument("--frames", type=int, default=10)
parser.add_argument("--views", default=None, help="far,facing by default; f12 with --ground")
parser.add_argument("--ground", action="store_true", help="benchmark_frame_cost.py's ground plane, sun and camera")
args = parser.parse_args(argv)


def load(name, path):
    """The module file at `path` under a package of its own, so that two builds load side by side."""
    sys.modules[name] = types.ModuleType(name)
    loader = importlib.machinery.ExtensionFileLoader(name + "._native", path)
    module = importlib.util.module_from_spec(importlib.util.spec_from_file_location(name + "._native", path,
                                                                                     loader=loader))
    loader.exec_module(module)
    return module


builds = {"A": load("build_a", args.a)}
if args.b:
    builds["B"] = load("build_b", args.b)
cloud = builds["A"].read_splats(os.path.join(args.data, "showroom_1.5M.ply"))
low, high = np.percentile(cloud["positions"], 2, axis=0), np.percentile(cloud["positions"], 98, axis=0)
facing = np.eye(4, dtype=np.float32)
facing[:3, :3] = np.array([[1, 0, 0], [0, -1, 0], [0, 0, -1]], np.float32)
facing[:3, 3] = (low + high) / 2 - np.array([0, 0, float(np.max(high - low))])
VIEWS = {  # the showroom GUI test's F12 camera (the whole scene, far), and the file's +Z at the middle 96 %
    "far": {"matrix": np.array([[1, 0, 0, -16.242052], [0, 1, 0, 98.567497], [0, 0, 1, 639.995117], [0, 0, 0, 1]],
                               np.float32), "type": "PERSP", "lens": 50.0, "sensor_width": 36.0, "clip_start": 0.1,
            "clip_end": 1e4},
    "facing": {"matrix": facing, "type": "PERSP", "lens": 30.0, "sensor_width": 36.0, "sensor_fit": "HORIZONTAL",
               "clip_start": 0.01, "clip_end": 1e4},
}
# benchmark_frame_cost.py's scene for showroom_1.5M at frame 1, as it computes it from the imported objects' bounds:
# the camera, the ground plane (4 times the scene's extent, at its 5th percentile height) and the sun.
VIEWS["f12"] = {"matrix": np.array([[1, 0, 0, 31.262278], [0, 0.31622761, -0.9486835, -159.82001],
                                    [0, 0.9486835, 0.31622761, 57.103889], [0, 0, 0, 1]], np.float32),
                "type": "PERSP", "lens": 50.0, "sensor_width": 36.0, "clip_start": 0.1, "clip_end": 1000.0}
GROUND = np.array([[-216.09746, -258.76392, -4.500102], [278.62201, -258.76392, -4.500102],
                   [-216.09746, 235.95557, -4.500102], [278.62201, 235.95557, -4.500102]], np.float32)
SUN = np.array([[0.68281895, -0.51390493, 0.51928794, 0], [0.70305675, 0.65548778, -0.27576613, 0],
                [-0.19866933, 0.55338722, 0.80888385, 0], [0, 0, 0, 1]], np.float32)
SETTINGS = {"width": 640, "height": 360, "samples": 1, "compositing": "SORTED", "seed": 0,
            "pixel_filter": "BLACKMAN_HARRIS", "filter_width": 1.5, "camera_ray_splatting": True}


def make_scenes(order):
    """A scene of the whole file per build, made in `order` (the one made first renders a few percent slower here,
    whichever build it is: the two halves of the run make them in opposite orders)."""
    made = {}
    for name in order:
        module = builds[name]
        scene = module.RenderScene()
        scene.add_gaussians(cloud["positions"], cloud["rotations"], cloud["scales"], cloud["opacities"], cloud["sh"])
        if args.ground:
            scene.add_mesh(GROUND, np.array([[0, 1, 3], [0, 3, 2]], np.uint32), material=scene.add_material())
            scene.add_light("SUN", [1, 1, 1], 10.0, SUN, sun_angle=0.00918)
        scene.set_keep_frame_buffers(True)
        module.RenderJob(scene, VIEWS["far"], dict(SETTINGS, width=64, height=36)).result()  # (the BVH built)
        made[name] = (module, scene)
    return made


print(f"showroom_1.5M, 640 x 360, 1 sample, median of {args.frames} frames, CPU s, load {os.getloadavg()[0]:.2f}")
names = sorted(builds)
views = (args.views or ("f12" if args.ground else "far,facing")).split(",")
figures = {(view, name): [] for view in views for name in names}
result = {}
for half in (0, 1):
    scenes = make_scenes(names if half == 0 else names[::-1])
    for view in views:
        for frame in range((args.frames + 1 - half) // 2):
            for name in sorted(scenes, reverse=frame % 2 == 1):
                module, scene = scenes[name]
                start = time.process_time()
                film = module.RenderJob(scene, VIEWS[view], SETTINGS).result()
                figures[view, name].append((time.process_time() - start, film["splat_prepass_cpu_seconds"],
                                            film["sample_cpu_seconds"]))
                result[view, name] = film
    del scenes
for view in views:
    for name in names:
        total, prepass, samples = np.median(np.array(figures[view, name]), axis=0)
        film = result[view, name]
        print(f"{view:7} {name}  frame {total:.4f}  pre-pass {prepass:.4f}  samples {samples:.4f}  "
              f"splats {film['splats']:,}  entries {film['splat_tile_entries']:,}  "
              f"image {hashlib.md5(np.asarray(film['rgba']).tobytes()).hexdigest()[:12]}", flush=True)
