# Benchmark of the render engine's Blender side on the 1.5 M-splat scene plus a few meshes: depsgraph ->
# native scene (sync), BVH build, a quarter-resolution stochastic sample (the viewport's first image), a
# 1-sample final frame and a 4-sample frame whole and within a 25 % x 25 % render region. Prints each stage.
#   blender -b --factory-startup --python examples/benchmark_engine.py -- [--scene FILE] [--width 1920 --height 1080]
import argparse
import os
import sys
import time

import bpy
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
parser = argparse.ArgumentParser()
parser.add_argument("--scene", default=os.path.join(HERE, "..", "..", "shared", "data", "showroom_1.5M.ply"))
parser.add_argument("--width", type=int, default=1920)
parser.add_argument("--height", type=int, default=1080)
args = parser.parse_args(argv)

sys.path.insert(0, os.path.join(HERE, "..", "addon"))
import raysplats  # noqa: E402

raysplats.register()
from raysplats.objects import polygon_mesh
from raysplats import native  # noqa: E402
from raysplats.engine import sync  # noqa: E402

bpy.ops.import_scene.gaussian_splats(filepath=args.scene)
splats = bpy.context.object
for location in ((0, 0, -2), (2, 0, 0), (-2, 0, 0)):
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.5, location=location, segments=64, ring_count=32)
bpy.ops.mesh.primitive_plane_add(size=20, location=(0, 0, -3))
bpy.ops.object.light_add(type="SUN")
# Camera at the median of the splat centres, looking along a horizontal axis, 60° field of view.
world_centres = []
for piece in polygon_mesh.scene_pieces(splats.parent or splats):  # (a big scene is imported in pieces)
    centres = np.empty(len(piece.data.polygons) * 3, dtype=np.float32)
    piece.data.polygons.foreach_get("center", centres)
    world = np.array(piece.matrix_world)
    world_centres.append(centres.reshape(-1, 3) @ world[:3, :3].T + world[:3, 3])
median = np.median(np.concatenate(world_centres), axis=0)
bpy.ops.object.camera_add(location=median, rotation=(np.pi / 2, 0, -np.pi / 2))
camera = bpy.context.object
camera.data.sensor_fit, camera.data.sensor_width = "HORIZONTAL", 36.0
camera.data.lens = 18.0 / np.tan(np.radians(30))
scene = bpy.context.scene
scene.camera = camera
scene.render.engine = "RAYSPLATS"
scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = args.width, args.height, 100
depsgraph = bpy.context.evaluated_depsgraph_get()

t = time.perf_counter()
render_scene, stats = sync.build_render_scene(depsgraph)
t_sync_first = time.perf_counter() - t
# Again, as every later frame or re-render does (the first call also pays first-touch costs of new arrays).
t = time.perf_counter()
render_scene, stats = sync.build_render_scene(depsgraph)
t_sync = time.perf_counter() - t
t_build = render_scene.build("FLAT")
core = native.core()


def frame(width, height, compositing, samples=1, **extra):
    settings = sync.render_settings(scene, width, height, samples)
    settings["compositing"] = compositing
    settings.update(extra)
    cam = sync.camera_settings(scene, camera, width, height)
    t0 = time.perf_counter()
    film = core.RenderJob(render_scene, cam, settings).result()
    return time.perf_counter() - t0, film


t_quarter, _ = frame(args.width // 4, args.height // 4, "STOCHASTIC")
t_stochastic, _ = frame(args.width, args.height, "STOCHASTIC")
t_sorted, film = frame(args.width, args.height, "SORTED")
print(f"\nRaySplats engine benchmark: {stats.splats:,} splats, {stats.triangles:,} triangles, "
      f"{args.width}x{args.height}")
print(f"  depsgraph -> native scene (sync)   {t_sync:6.2f} s   (first time after import {t_sync_first:.2f} s)")
print(f"  BVH build                          {t_build:6.2f} s")
print(f"  viewport first image (1/4 res, 1 spp stochastic) {t_quarter:6.2f} s (+ sync and build after an edit)")
print(f"  final frame, 1 spp stochastic      {t_stochastic:6.2f} s")
print(f"  final frame, 1 spp sorted          {t_sorted:6.2f} s   {film['gaussian_hits'] / max(1, film['camera_rays']):.1f} "
      "Gaussian hits per camera ray")
# A render region (Blender's border) renders only its pixels: a 25 % x 25 % region in the middle of the frame.
t_whole, _ = frame(args.width, args.height, "SORTED", samples=4)
rw, rh = args.width // 4, args.height // 4
t_region, _ = frame(args.width, args.height, "SORTED", samples=4, region_x=(args.width - rw) // 2,
                    region_y=(args.height - rh) // 2, region_width=rw, region_height=rh)
print(f"  final frame, 4 spp sorted          {t_whole:6.2f} s; in a 25 % x 25 % region {t_region:.2f} s "
      f"({t_whole / t_region:.1f}x faster)")

# The viewport after an edit: the same path as view_update/view_draw (sync.SceneSync.update from the depsgraph's
# updates, then the build of what changed and the quarter-resolution first image), driven here by a depsgraph
# handler because a background Blender has no viewport.
viewport_sync = sync.SceneSync(depsgraph, interactive=True)
viewport_sync.render_scene.build("FLAT")
render_scene = viewport_sync.render_scene
timings = {}


def on_update(scene_, depsgraph_):
    t0 = time.perf_counter()
    change = viewport_sync.update(depsgraph_)
    t1 = time.perf_counter()
    build = viewport_sync.render_scene.build("FLAT")
    report = viewport_sync.render_scene.last_build()
    t_first, _ = frame(args.width // 4, args.height // 4, "STOCHASTIC")
    timings["last"] = (change, t1 - t0, build, report, t_first)


bpy.app.handlers.depsgraph_update_post.append(on_update)


def measure(label, edit):
    t0 = time.perf_counter()
    edit()
    bpy.context.view_layer.update()
    total = time.perf_counter() - t0
    change, t_update, t_build, report, t_first = timings.pop("last")
    # `total` includes the edit itself and Blender's own update of the mesh and depsgraph; the engine's part starts
    # when the depsgraph reports the change (view_update) and ends with the first image.
    print(f"  viewport after {label:<22} {total:6.2f} s to the first image, engine {t_update + t_build + t_first:.2f} s: "
          f"{change}, sync {t_update:.2f} s, build {t_build:.2f} s ({report['gaussian_chunks']} chunks, "
          f"{report['meshes']} meshes), image {t_first:.2f} s")


def move():
    splats.location.x += 0.1


def edit_vertices():
    co = np.empty(len(splats.data.vertices) * 3, dtype=np.float32)
    splats.data.vertices.foreach_get("co", co)
    co[2:3 * 64:3] += 0.05  # the first 8 splats move
    splats.data.vertices.foreach_set("co", co)
    splats.data.update()


measure("moving the splats", move)
measure("editing 8 splats", edit_vertices)
