# Where the CPU seconds of a final frame go: F12 of a splat scene with a ground plane and a sun, split into Blender's
# part before the engine is called (depsgraph evaluation, the render result), the add-on's reads of Blender's data,
# the core's recovery of the Gaussians, handing the arrays to the core, the BVH build, camera-ray splatting's
# pre-pass, the sample passes, the film, writing the passes into Blender's result, and Blender's part after the
# engine returns (writing the image). Then the frames of an animation: the same frame again, the next frame with only
# the camera moved, a frame with one object moved and one with a piece's splats edited, each without and with
# Persistent Data (render.use_persistent_data). CPU seconds are the process's own (every thread).
#   blender -b --factory-startup --python examples/benchmark_frame_cost.py -- [--scene showroom_1.5M.ply]
#   ~/.cache/raysplats/bpy53-venv/bin/python examples/benchmark_frame_cost.py --blender-splats
#       (Blender 5.3's own splat object, made by its wm.ply_import)
import argparse
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
# (Blender passes a script the arguments after "--"; a Python running bpy as a module, its own.)
argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:] if sys.argv[0].endswith(".py") else []
parser = argparse.ArgumentParser()
parser.add_argument("--data", default=os.path.join(HERE, "..", "..", "shared", "data"))
parser.add_argument("--scene", default="showroom_1.5M.ply")
parser.add_argument("--width", type=int, default=640)
parser.add_argument("--height", type=int, default=360)
parser.add_argument("--samples", type=int, default=1)
parser.add_argument("--blender-splats", action="store_true",
                    help="import with Blender's own PLY import (Blender 5.3+: its splat object) instead of the add-on's")
parser.add_argument("--out", default=None, help="folder for the frames (default: a temporary one)")
args = parser.parse_args(argv)

import bpy  # noqa: E402
from mathutils import Matrix, Vector  # noqa: E402

sys.path.insert(0, os.path.join(HERE, "..", "addon"))
import raysplats  # noqa: E402

raysplats.register()
from raysplats.engine import final  # noqa: E402

STAGES = ("read", "convert", "scene", "bvh", "prepass", "samples", "film", "write")


def clocks():
    return time.process_time(), time.perf_counter()


def setup():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    path = os.path.join(args.data, args.scene)
    if args.blender_splats:
        bpy.ops.wm.ply_import(filepath=path)
    else:
        bpy.ops.import_scene.gaussian_splats(filepath=path)
    root = bpy.context.view_layer.objects.active
    while root.parent is not None:
        root = root.parent
    splat_objects = [o for o in scene.objects if o.type in ("MESH", "POINTCLOUD")]
    # The scene's extent from its objects' bounds, in world space.
    corners = np.array([tuple(o.matrix_world @ Vector(c)) for o in splat_objects for c in o.bound_box])
    low, high = np.percentile(corners, 5, axis=0), np.percentile(corners, 95, axis=0)
    centre, size = (low + high) / 2, float(np.max(high - low))
    bpy.ops.mesh.primitive_plane_add(size=4 * size, location=(centre[0], centre[1], low[2]))
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
    scene.collection.objects.link(sun)
    sun.rotation_euler = (0.6, 0.2, 0.8)
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    scene.collection.objects.link(camera)
    scene.camera = camera
    # From outside the scene, looking at its centre; frame 2 moves the camera a little (an animation's next frame).
    for frame, offset in ((1, 0.0), (2, 0.02 * size)):
        eye = Vector(centre) + Vector((offset, -1.2 * size, 0.4 * size))
        camera.matrix_world = Matrix.Translation(eye) @ (Vector(centre) - eye).to_track_quat("-Z", "Y") \
            .to_matrix().to_4x4()
        camera.keyframe_insert("location", frame=frame)
        camera.keyframe_insert("rotation_euler", frame=frame)
    scene.render.engine = "RAYSPLATS"
    scene.render.resolution_x, scene.render.resolution_y = args.width, args.height
    scene.render.resolution_percentage = 100
    scene.raysplats.samples = args.samples
    scene.raysplats.use_adaptive_sampling = False
    scene.render.image_settings.file_format = "PNG"
    return scene, root, splat_objects


def f12(scene, name):
    """One F12 written to a PNG, as `blender -b -f` does: a dict of stage -> (CPU s, wall s)."""
    scene.render.filepath = os.path.join(out, name + ".png")
    start = clocks()
    bpy.ops.render.render(write_still=True)
    end = clocks()
    r = final.last_render
    stages = {"blender before": tuple(a - b for a, b in zip(r["entered"], start))}
    stages.update({s: r["stages"].get(s, (0.0, 0.0)) for s in STAGES})
    inside = tuple(a - b for a, b in zip(r["left"], r["entered"]))
    stages["engine other"] = tuple(i - sum(v[k] for s, v in stages.items() if s != "blender before")
                                   for k, i in enumerate(inside))
    stages["blender after"] = tuple(a - b for a, b in zip(end, r["left"]))
    stages["total"] = tuple(a - b for a, b in zip(end, start))
    return stages, r["scene"]


def edit_piece(obj):
    """Moves one splat object's first 100 Gaussians' vertices (an edit of a few splats)."""
    if obj.type == "MESH":
        co = np.empty(len(obj.data.vertices) * 3, dtype=np.float32)
        obj.data.vertices.foreach_get("co", co)
        co[:300] += 0.01
        obj.data.vertices.foreach_set("co", co)
        obj.data.update()
    else:
        co = np.empty(len(obj.data.points) * 3, dtype=np.float32)
        obj.data.attributes["position"].data.foreach_get("vector", co)
        co[:300] += 0.01
        obj.data.attributes["position"].data.foreach_set("vector", co)
    obj.data.update_tag()


out = args.out or os.path.join(os.environ.get("TMPDIR", "/tmp"), "raysplats_frame_cost")
os.makedirs(out, exist_ok=True)
scene, root, splat_objects = setup()
runs = []
for persistent in (False, True):
    scene.render.use_persistent_data = persistent
    tag = "persistent" if persistent else "plain"
    scene.frame_set(1)
    runs.append((f"{tag}: frame 1", *f12(scene, f"{tag}_1")))
    runs.append((f"{tag}: frame 1 again", *f12(scene, f"{tag}_1_again")))
    scene.frame_set(2)
    runs.append((f"{tag}: frame 2 (camera moved)", *f12(scene, f"{tag}_2")))
    root.location.x += 0.05
    runs.append((f"{tag}: an object moved", *f12(scene, f"{tag}_moved")))
    edit_piece(splat_objects[0])
    runs.append((f"{tag}: a few splats edited", *f12(scene, f"{tag}_edited")))
    root.location.x -= 0.05
scene.render.use_persistent_data = False

print(f"\nRaySplats frame cost: {args.scene}{' (Blender splat object)' if args.blender_splats else ''}, "
      f"{args.width} x {args.height}, {args.samples} sample(s), Blender {bpy.app.version_string}, "
      f"{os.cpu_count()} CPUs, load {os.getloadavg()[0]:.2f}; CPU s (wall s)")
names = ["blender before", *STAGES, "engine other", "blender after", "total"]
print(f"{'':34}" + "".join(f"{n:>15}" for n in names) + "  scene")
for label, stages, how in runs:
    print(f"{label:34}" + "".join(f"{stages[n][0]:7.2f} ({stages[n][1]:4.2f})" for n in names) + f"  {how}")
raysplats.unregister()
