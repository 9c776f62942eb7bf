# Benchmark of a scene too big to edit whole: showroom_1.5M.ply tiled 3 x 3 (13.5 M Gaussians, the size
# of a drone capture) is imported with the default settings (Automatic: compact points beyond 3 M Gaussians),
# rendered with F12 at 1920 x 1080 with one sample, a region of it is edited as polygons and merged back, and the
# scene is exported to .ply. Prints each stage's time, the resident memory it added (now - before) and Blender's peak
# resident memory after it; the region stages separately: take it, enter Edit Mode on it, move it, leave Edit Mode,
# merge it back.
#   blender -b --factory-startup --python examples/benchmark_big_scene.py -- [--data-dir D] [--tiles 3] [--work DIR]
#       [--region 200000] [--region-k K] [--no-render] [--addon-dir DIR (another checkout's addon/, to compare)]
# The tiled file (~760 MB) is written to --work (default: a temporary folder) once and reused.
import argparse
import os
import resource
import sys
import tempfile
import time

import bpy
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
parser = argparse.ArgumentParser()
parser.add_argument("--data-dir", default=os.path.join(HERE, "..", "..", "shared", "data"))
parser.add_argument("--tiles", type=int, default=3, help="tiles per side: tiles² copies of the scene")
parser.add_argument("--work", default=os.path.join(tempfile.gettempdir(), "raysplats_big_scene"))
parser.add_argument("--region", type=int, default=200_000, help="Gaussians of the region edited as polygons")
parser.add_argument("--region-k", type=int, default=0, help="polygon vertices of the region (0: the add-on's default)")
parser.add_argument("--no-render", action="store_true", help="leave out the F12 render and the export")
parser.add_argument("--addon-dir", default=os.path.join(HERE, "..", "addon"))
args = parser.parse_args(argv)

sys.path.insert(0, os.path.abspath(args.addon_dir))
import raysplats  # noqa: E402

raysplats.register()
from raysplats.io import export_splats, import_splats
from raysplats.objects import compact_points, splat_object
from raysplats.tools import region_editing
from raysplats import native  # noqa: E402

core = native.core()


def peak_rss_gb():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024 / 1e9


def current_rss_gb():
    with open("/proc/self/statm") as statm:
        return int(statm.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 1e9


rows = []
_before = [0.0, 0.0]


def start():
    """The clock, the CPU time and the resident memory before a stage."""
    _before[:] = current_rss_gb(), time.process_time()
    return time.perf_counter()


def stage(name, seconds):
    """A stage's wall time, the CPU time Blender spent in it (on a busy machine the better measure of single-threaded
    work: the wall time grows with the load, printed at the end), the resident memory it added and the peak."""
    now = current_rss_gb()
    rows.append((name, seconds, now, peak_rss_gb()))
    print(f"  {name:<46} {seconds:7.2f} s (CPU {time.process_time() - _before[1]:6.2f} s)   "
          f"added {now - _before[0]:+6.2f} GB   now {now:5.2f} GB   peak {rows[-1][3]:5.2f} GB", flush=True)


def tiled_scene():
    """showroom tiled tiles x tiles on its floor (x and z of its -Y-up frame), written once."""
    os.makedirs(args.work, exist_ok=True)
    path = os.path.join(args.work, f"showroom_x{args.tiles * args.tiles}.ply")
    if os.path.exists(path):
        return path
    cloud = core.read_splats(os.path.join(args.data_dir, "showroom_1.5M.ply"))
    extent = cloud["positions"].max(axis=0) - cloud["positions"].min(axis=0)
    offsets = [(i * extent[0], 0.0, j * extent[2]) for i in range(args.tiles) for j in range(args.tiles)]
    tiled = {key: np.concatenate([cloud[key]] * len(offsets)) for key in ("rotations", "scales", "opacities", "sh")}
    tiled["positions"] = np.concatenate([cloud["positions"] + np.array(o, dtype=np.float32) for o in offsets])
    del cloud
    core.write_splats(path, tiled["positions"], tiled["rotations"], tiled["scales"], tiled["opacities"], tiled["sh"])
    return path


t = time.perf_counter()
scene_path = tiled_scene()
print(f"\nRaySplats big-scene benchmark: {os.path.basename(scene_path)} "
      f"({os.path.getsize(scene_path) / 1e6:.0f} MB); empty Blender {current_rss_gb():.2f} GB "
      f"(tiled file ready in {time.perf_counter() - t:.1f} s)")
empty = current_rss_gb()
context = bpy.context

t = start()
bpy.ops.import_scene.gaussian_splats(filepath=scene_path)  # the defaults a user gets
obj = context.view_layer.objects.active
count = splat_object.shown_count(obj)
stage(f"import ({count / 1e6:.1f} M, {splat_object.kind_of(obj).lower()})",
      time.perf_counter() - t)

scene = context.scene
scene.render.engine = "RAYSPLATS"
scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 1920, 1080, 100
scene.raysplats.samples = 1
camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
scene.collection.objects.link(camera)
# As examples/benchmark_engine.py: inside the first showroom (its median splat), looking along it.
points = compact_points.object_cloud(obj)["positions"] if splat_object.kind_of(obj) == splat_object.POINTS else None
if points is not None:
    median = np.median(points[: count // (args.tiles ** 2)], axis=0)
    del points
    world = np.array(obj.matrix_world, dtype=np.float64)
    camera.location = world[:3, :3] @ median + world[:3, 3]
camera.rotation_euler = (np.pi / 2, 0.0, -np.pi / 2)
camera.data.sensor_fit, camera.data.sensor_width = "HORIZONTAL", 36.0
camera.data.lens = 18.0 / np.tan(np.radians(30))
scene.camera = camera
scene.render.filepath = os.path.join(args.work, "render.png")
if not args.no_render:
    t = start()
    bpy.ops.render.render(write_still=True)
    stage("F12, 1920 x 1080, 1 sample", time.perf_counter() - t)

if splat_object.kind_of(obj) == splat_object.POINTS:
    positions = compact_points.object_cloud(obj)["positions"]
    # The region: the Gaussians nearest the first tile's centre, as a crop would give them.
    distance = np.linalg.norm(positions - positions[: len(positions) // (args.tiles ** 2)].mean(axis=0), axis=1)
    mask = distance <= np.partition(distance, args.region)[args.region]
    del positions, distance
    options = {"vertices_per_polygon": args.region_k} if args.region_k else {}
    t = start()
    region, _ = region_editing.edit_region_as_polygons(context, obj, mask, **options)
    context.view_layer.update()  # the evaluation it causes (the next redraw's) belongs to this stage
    stage(f"edit region as polygons ({int(mask.sum()) / 1e3:.0f} k, K = {region.raysplats.vertices_per_polygon})",
          time.perf_counter() - t)
    context.view_layer.objects.active = region
    t = start()
    bpy.ops.object.mode_set(mode="EDIT")
    stage("enter Edit Mode on the region", time.perf_counter() - t)
    t = start()
    bpy.ops.mesh.select_all(action="SELECT")  # (an import selects nothing)
    bpy.ops.transform.translate(value=(0.0, 0.0, 0.1))
    stage("select all, move it", time.perf_counter() - t)
    t = start()
    bpy.ops.object.mode_set(mode="OBJECT")
    stage("leave Edit Mode", time.perf_counter() - t)
    t = start()
    region_editing.merge_region_back(context, region, obj)
    context.view_layer.update()
    stage("merge the region back", time.perf_counter() - t)

if not args.no_render:
    out = os.path.join(args.work, "exported.ply")
    t = start()
    export_splats.export_gaussian_splats(context, out)
    stage("export .ply", time.perf_counter() - t)
    print(f"  written {os.path.getsize(out) / 1e6:.0f} MB", flush=True)
    os.remove(out)
print(f"  peak above the empty Blender {peak_rss_gb() - empty:.2f} GB "
      f"({(peak_rss_gb() - empty) * 1e9 / count:.0f} bytes per Gaussian); load average {os.getloadavg()[0]:.1f}")
if not bpy.app.binary_path:  # the bpy module (PyPI) can hang in its exit handlers: leave at once
    sys.stdout.flush()
    os._exit(0)
