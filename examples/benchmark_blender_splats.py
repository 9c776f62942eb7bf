# F12 of a splat object Blender 5.3 made itself (wm.ply_import: a GAUSSIAN_SPLAT point cloud), by Cycles (CPU) and by
# RaySplats, on the same object and camera: the CPU seconds each takes to a given noise (RMSE of the display image
# against its own high-sample render, adaptive sampling and denoising off), and each one's PSNR against the
# independent numpy EWA rasterizer of the file (native/tests/reference/ewa_rasterizer.py: what 3DGS viewers show).
# With --noise seeds, noise is each pixel's standard deviation across seeds (two renders per count) and Cycles is
# rendered once more at the sample count that reaches RaySplats' one-sample noise: the CPU ratio at equal noise.
# Optionally (--lit) both under a sun: RaySplats' Lit shading beside Cycles, which does not light splats.
#   python examples/benchmark_blender_splats.py --data DIR --out DIR [--scene unicorn_sh3_reordered.ply]
#       (the Python of a bpy 5.3 venv, ~/.cache/raysplats/bpy53-venv/bin/python; CPU seconds are the process's own)
import argparse
import json
import os
import resource
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
parser = argparse.ArgumentParser()
parser.add_argument("--data", default=os.path.join(HERE, "..", "..", "shared", "data"))
parser.add_argument("--out", required=True)
parser.add_argument("--scene", default="unicorn_sh3_reordered.ply")
parser.add_argument("--width", type=int, default=960)
parser.add_argument("--height", type=int, default=540)
parser.add_argument("--raysplats-samples", default="1,2,4,8,16", help="sample counts measured; the last x4: reference")
parser.add_argument("--cycles-samples", default="1,2,4,8,16", help="sample counts measured; the last x4: reference")
parser.add_argument("--lit", action="store_true", help="also render both under a sun (RaySplats Lit shading)")
parser.add_argument("--noise", choices=("reference", "seeds"), default="reference",
                    help="reference: RMS difference from the same engine's render at 4x the largest count; seeds: "
                         "RMS difference of two renders with different seeds over sqrt 2 (each pixel's standard "
                         "deviation: no reference, so neither its own noise nor either engine's bias enters), then "
                         "the Cycles samples and CPU seconds at RaySplats' one-sample noise, rendered to confirm")
parser.add_argument("--confirm-max", type=int, default=128,
                    help="--noise seeds: the most Cycles samples rendered to confirm equal noise; beyond it the count "
                         "and its CPU seconds are extrapolated from the measured rows")
args = parser.parse_args()

import bpy  # noqa: E402
from mathutils import Matrix  # noqa: E402

sys.path.insert(0, os.path.join(HERE, "..", "addon"))
sys.path.insert(0, os.path.join(HERE, "..", "native", "tests", "reference"))
import ewa_rasterizer as ewa  # noqa: E402
import raysplats  # noqa: E402
from test_viewer_agreement import LENS, SENSOR, view_camera  # noqa: E402

raysplats.register()
os.makedirs(args.out, exist_ok=True)


def cpu_seconds():
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def render(engine, samples, name, seed=None):
    """F12 into a 32-bit EXR: (display image, sRGB of the linear film under the Standard view, and CPU seconds).
    The seed is the sample count unless given."""
    seed = samples if seed is None else seed
    scene = bpy.context.scene
    scene.render.engine = engine
    if engine == "CYCLES":
        scene.cycles.device = "CPU"
        scene.cycles.samples = samples
        scene.cycles.use_adaptive_sampling = False
        scene.cycles.use_denoising = False
        scene.cycles.seed = seed
    else:  # (Camera Rays as Splats as by default: F12 as a user gets it)
        scene.raysplats.samples = samples
        scene.raysplats.use_adaptive_sampling = False
        scene.raysplats.seed = seed
    path = os.path.join(args.out, f"{name}.exr")
    scene.render.filepath = path
    start = cpu_seconds()
    bpy.ops.render.render(write_still=True)
    seconds = cpu_seconds() - start
    image = bpy.data.images.load(path)
    width, height = image.size
    pixels = np.empty(width * height * 4, np.float32)
    image.pixels.foreach_get(pixels)
    bpy.data.images.remove(image)
    rgb = pixels.reshape(height, width, 4)[::-1, :, :3]  # rows top to bottom, as the rasterizer's
    return ewa.linear_to_srgb(np.maximum(rgb, 0.0)), seconds


def save_png(image, name):
    """A display image (rows top to bottom) as out/name.png."""
    height, width = image.shape[:2]
    png = bpy.data.images.new(name, width, height)
    rgba = np.concatenate([np.clip(image[::-1], 0, 1), np.ones((height, width, 1))], axis=2)
    png.pixels.foreach_set(rgba.astype(np.float32).ravel())
    png.filepath_raw = os.path.join(args.out, f"{name}.png")
    png.file_format = "PNG"
    png.save()
    bpy.data.images.remove(png)


def rmse(a, b):
    return float(np.sqrt(np.mean((np.clip(a, 0, 1) - np.clip(b, 0, 1)) ** 2)))


bpy.ops.wm.read_factory_settings(use_empty=True)
scene = bpy.context.scene
scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = args.width, args.height, 100
scene.render.image_settings.file_format = "OPEN_EXR"
scene.render.image_settings.color_depth = "32"
scene.view_settings.view_transform = "Standard"
scene.render.film_transparent = False
world = bpy.data.worlds.new("black")
scene.world = world
world.color = (0.0, 0.0, 0.0)
if world.node_tree is not None and "Background" in world.node_tree.nodes:
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)

bpy.ops.wm.ply_import(filepath=os.path.join(args.data, args.scene))
obj = bpy.context.view_layer.objects.active
assert obj.type == "POINTCLOUD" and obj.data.type == "GAUSSIAN_SPLAT", "needs Blender 5.3's splat import"
# Blender's import keeps the file's axes (identity matrix): the camera of the viewer-agreement test, in those axes.
splats = ewa.read_splats(os.path.join(args.data, args.scene))
camera_to_world, world_to_view, near = view_camera(splats, "front")
camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
scene.collection.objects.link(camera)
camera.matrix_world = Matrix(camera_to_world.tolist())  # (a plain nested list is read column by column)
camera.data.lens, camera.data.sensor_width, camera.data.sensor_fit = LENS, SENSOR, "HORIZONTAL"
camera.data.clip_start, camera.data.clip_end = near, 1e6
scene.camera = camera
fx = args.width * LENS / SENSOR
viewer = ewa.rasterize(splats, world_to_view, fx, fx, args.width, args.height, near=near)
save_png(viewer, "viewer")

results = {"scene": args.scene, "size": [args.width, args.height], "load": os.getloadavg(), "noise": args.noise,
           "cpu": next((line.split(":", 1)[1].strip() for line in open("/proc/cpuinfo") if line.startswith("model name")),
                       "?") if os.path.exists("/proc/cpuinfo") else "?",
           "blender": bpy.app.version_string, "engines": {}}


def measure(engine, samples):
    """One row: CPU seconds (the mean of the renders made), noise, PSNR against the rasterizer."""
    image, seconds = render(engine, samples, f"{engine.lower()}_{samples}")
    row = {"samples": samples, "psnr_vs_viewer": round(ewa.psnr(viewer, image), 2)}
    if args.noise == "seeds":
        other, other_seconds = render(engine, samples, f"{engine.lower()}_{samples}_b", seed=samples + 1000)
        row.update(cpu_seconds=round((seconds + other_seconds) / 2, 2), noise=round(rmse(image, other) / 2 ** 0.5, 5))
    else:
        row.update(cpu_seconds=round(seconds, 2), noise=round(rmse(image, reference), 5))
    print(engine, row, flush=True)
    return row


for engine, counts in (("RAYSPLATS", args.raysplats_samples), ("CYCLES", args.cycles_samples)):
    counts = [int(c) for c in counts.split(",")]
    entry = results["engines"][engine] = {}
    if args.noise == "reference":
        reference, reference_seconds = render(engine, 4 * counts[-1], f"{engine.lower()}_reference")
        save_png(reference, f"{engine.lower()}_reference")
        entry.update(reference_samples=4 * counts[-1], reference_cpu_seconds=round(reference_seconds, 1),
                     reference_psnr_vs_viewer=round(ewa.psnr(viewer, reference), 2))
    entry["rows"] = [measure(engine, samples) for samples in counts]

if args.noise == "seeds":
    # Cycles' first sample goes through the pixel's centre whatever the seed (its camera ray's filter sample is fixed
    # at sample 0), so with nothing else random in the scene (no lights, a black world) a 1-sample render is the same
    # for every seed and its rows' noise is 0: only the rows with random samples count.
    rows = [r for r in results["engines"]["CYCLES"]["rows"] if r["noise"] > 0]
    if len(rows) < 2:
        sys.exit("--noise seeds needs two Cycles sample counts above 1 (--cycles-samples)")
    target = results["engines"]["RAYSPLATS"]["rows"][0]

    def samples_at(noise, slope, samples, at):
        """The sample count where a power law of this slope through (samples, at) reaches `noise`."""
        return int(np.ceil(samples * (noise / at) ** (1.0 / slope)))

    # Cycles' noise against its samples is a power law whose slope steepens with the count (towards -0.5 and
    # beyond, as the fixed first sample weighs less), so the slope between the two largest counts gives the fewer
    # samples and the slope of a fit through every row the more: the equal-noise count lies about between them.
    last, before = rows[-1], rows[-2]
    local_slope = float(np.log(last["noise"] / before["noise"]) / np.log(last["samples"] / before["samples"]))
    fit_slope, fit_intercept = np.polyfit(np.log([r["samples"] for r in rows]), np.log([r["noise"] for r in rows]), 1)
    needed = samples_at(target["noise"], local_slope, last["samples"], last["noise"])
    needed_by_fit = samples_at(target["noise"], fit_slope, 1, float(np.exp(fit_intercept)))
    if needed <= args.confirm_max:
        confirm = measure("CYCLES", needed)
    else:
        # Too many samples to render here: the CPU seconds from a straight line through the rows (a fixed cost per
        # frame plus a cost per sample).
        cost, fixed = np.polyfit([r["samples"] for r in rows], [r["cpu_seconds"] for r in rows], 1)
        confirm = {"samples": needed, "cpu_seconds": round(float(fixed + cost * needed), 1), "extrapolated": True,
                   "cpu_seconds_per_sample": round(float(cost), 3),
                   "samples_by_fit": needed_by_fit,
                   "cpu_seconds_by_fit": round(float(fixed + cost * needed_by_fit), 1)}
        print("CYCLES (extrapolated)", confirm, flush=True)
    results["equal_noise"] = {"raysplats": target, "cycles_local_slope": round(local_slope, 3),
                              "cycles_fit_slope": round(float(fit_slope), 3), "cycles": confirm,
                              "cpu_ratio": round(confirm["cpu_seconds"] / target["cpu_seconds"], 1)}
    print("equal noise", results["equal_noise"], flush=True)

if args.lit:
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
    scene.collection.objects.link(sun)
    sun.data.energy = 3.0
    sun.matrix_world = Matrix(camera_to_world.tolist())  # from over the camera's shoulder
    world.color = (0.05, 0.05, 0.05)
    scene.raysplats.gaussian_shading = "LIT"
    for engine, samples in (("RAYSPLATS", 32), ("CYCLES", 64)):
        image, seconds = render(engine, samples, f"{engine.lower()}_lit")
        save_png(image, f"{engine.lower()}_lit")
        results[f"{engine.lower()}_lit_cpu_seconds"] = round(seconds, 2)

results["load_at_end"] = os.getloadavg()
with open(os.path.join(args.out, "results.json"), "w") as f:
    json.dump(results, f, indent=1)
print(json.dumps(results, indent=1))
raysplats.unregister()
