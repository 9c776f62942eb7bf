# Benchmark of Camera Rays as Splats against traced camera rays (sorted compositing, as F12), on real scenes from near
# and far: the render's time (the best of --repeats, after a render that builds the BVH), the splatting pre-pass and
# what it keeps (splats in view, tile-list entries, MB). Core only: no Blender scene, so the figures are the renderer's.
#   blender -b --factory-startup --python examples/benchmark_camera_splatting.py -- [--data DIR] [--repeats 2]
import argparse
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
parser = argparse.ArgumentParser()
parser.add_argument("--data", default=os.path.join(HERE, "..", "..", "shared", "data"))
parser.add_argument("--repeats", type=int, default=2)
args = parser.parse_args(argv)

sys.path.insert(0, os.path.join(HERE, "..", "addon"))
from raysplats import native  # noqa: E402

core = native.core()

# Blender's default 3D view (startup file: 50 mm lens on the viewport's 72 mm sensor), and the camera that
# blender_gui.viewport_rendered_showroom's F12 frames the whole imported showroom_1.5M with (View Selected: its
# outlying splats make the room itself about 30 px wide at 640 x 360).
DEFAULT_VIEW = np.array([[0.6859207, -0.3240135, 0.6515583, 7.358893], [0.7276764, 0.3054208, -0.6141704, -6.925791],
                         [0.0, 0.8953958, 0.4452714, 4.958310], [0.0, 0.0, 0.0, 1.0]], np.float32)
SHOWROOM_WHOLE = np.array([[1, 0, 0, -16.242052], [0, 1, 0, 98.567497], [0, 0, 1, 639.995117], [0, 0, 0, 1]],
                          np.float32)


def facing_camera(cloud, distance):
    """Looking along the file's +Z at the middle 96 % of the centres, from `distance` times their extent."""
    lo, hi = np.percentile(cloud["positions"], 2, axis=0), np.percentile(cloud["positions"], 98, axis=0)
    m = np.eye(4, dtype=np.float32)
    m[:3, :3] = np.array([[1, 0, 0], [0, -1, 0], [0, 0, -1]], np.float32)
    m[:3, 3] = (lo + hi) / 2 - np.array([0, 0, distance * float(np.max(hi - lo))])
    return {"matrix": m, "type": "PERSP", "lens": 30.0, "sensor_width": 36.0, "sensor_fit": "HORIZONTAL",
            "clip_start": 0.01, "clip_end": 1e4}


CASES = [  # (scene file, view, camera, width, height, samples)
    ("showroom_1.5M.ply", "from inside (the default 3D view)",
     {"matrix": DEFAULT_VIEW, "type": "PERSP", "lens": 50.0, "sensor_width": 72.0, "clip_start": 0.01,
      "clip_end": 1000.0}, 1000, 650, 8),
    ("showroom_1.5M.ply", "whole, far (the showroom GUI test's F12)",
     {"matrix": SHOWROOM_WHOLE, "type": "PERSP", "lens": 50.0, "sensor_width": 36.0, "clip_start": 0.1,
      "clip_end": 1e4}, 640, 360, 16),
    ("showroom_1.5M.ply", "whole, facing", 1.0, 1920, 1080, 1),
    ("small.splat", "facing", 0.6, 1920, 1080, 1),
    ("unicorn_sh3_reordered.ply", "facing", 1.0, 1920, 1080, 1),
]

print(f"{'scene':28} {'view':42} {'size':>11} {'spp':>4} {'traced s':>9} {'splatted s':>10} {'pre-pass s':>10} "
      f"{'splats':>9} {'entries':>10} {'MB':>6}", flush=True)
loaded = {}
for name, view, camera, width, height, samples in CASES:
    if name not in loaded:
        cloud = core.read_splats(os.path.join(args.data, name))
        scene = core.RenderScene()
        scene.add_gaussians(cloud["positions"], cloud["rotations"], cloud["scales"], cloud["opacities"], cloud["sh"])
        loaded = {name: (cloud, scene)}
    cloud, scene = loaded[name]
    if not isinstance(camera, dict):
        camera = facing_camera(cloud, camera)
    times, film = {}, None
    for splatting in (False, True):
        # (The add-on's pixel filter, Cycles' default: its samples reach a pixel beyond their own.)
        settings = {"width": width, "height": height, "samples": samples, "compositing": "SORTED", "seed": 0,
                    "pixel_filter": "BLACKMAN_HARRIS", "filter_width": 1.5, "camera_ray_splatting": splatting}
        core.RenderJob(scene, camera, dict(settings, samples=1, width=64, height=36)).result()  # BVH built
        best = float("inf")
        for _ in range(args.repeats):
            start = time.perf_counter()
            result = core.RenderJob(scene, camera, settings).result()
            best = min(best, time.perf_counter() - start)
        times[splatting] = best
        if splatting:
            film = result
    print(f"{name:28} {view:42} {width:>5} x {height:<4} {samples:>3} {times[False]:>9.2f} {times[True]:>10.2f} "
          f"{film['splat_prepass_seconds']:>10.2f} {film['splats']:>9,} {film['splat_tile_entries']:>10,} "
          f"{film['splat_bytes'] / 1e6:>6.0f}", flush=True)
