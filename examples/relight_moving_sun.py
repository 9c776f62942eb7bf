# Relightable splats, headless: a real trained splat scene rendered as LIT surfaces (Object Properties > Gaussian
# Splats > Shading) on a floor, under a sun that sweeps round it during an animation; two frames of it are rendered.
# The captured light is divided out (grey-world albedo) and the splats take the sun's light and shadows instead:
# the shading and the shadows on the floor move with the sun between the frames.
#   blender -b --factory-startup --python-exit-code 1 --python examples/relight_moving_sun.py -- \
#       --data-dir ../shared/data --out-dir demo_output [--scene unicorn_sh3_reordered.ply] [--samples 16]
# examples/demo.py calls relight_frame_pair() on its own scene.
import argparse
import math
import os
import sys
import time

import bpy
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))

# The sun's path: its heading turns by SWEEP_DEGREES between the first and the last frame, at SUN_ELEVATION
# degrees above the horizon.
SWEEP_DEGREES = 120.0
SUN_ELEVATION = 40.0


def add_floor_and_moving_sun(scene, obj, frames, strength=2.5):
    """A floor plane under `obj` (a Gaussian object) and a sun keyframed to turn round it from frames[0] to
    frames[1]. Returns the sun object."""
    corners = np.empty(len(obj.data.vertices) * 3, dtype=np.float32)
    obj.data.vertices.foreach_get("co", corners)
    world_matrix = np.array(obj.matrix_world)
    points = corners.reshape(-1, 3) @ world_matrix[:3, :3].T + world_matrix[:3, 3]
    floor_height = float(np.percentile(points[:, 2], 1))
    if not any(o.type == "MESH" and not getattr(o.raysplats, "is_gaussian", False) for o in scene.objects):
        bpy.ops.mesh.primitive_plane_add(size=50.0, location=(*np.median(points, axis=0)[:2], floor_height))
    bpy.ops.object.light_add(type="SUN")
    sun = bpy.context.object
    sun.name = "Moving Sun"
    sun.data.energy = strength
    sun.data.angle = math.radians(3.0)  # a slightly soft sun: penumbrae
    # Blender's sun shines along its local -Z: tilting it by (90 - elevation) about X and turning it about Z sets
    # where it stands in the sky.
    tilt = math.radians(90.0 - SUN_ELEVATION)
    for frame, heading in zip(frames, (-0.5 * SWEEP_DEGREES, 0.5 * SWEEP_DEGREES)):
        sun.rotation_euler = (tilt, 0.0, math.radians(heading))
        sun.keyframe_insert("rotation_euler", frame=frame)
    scene.frame_start, scene.frame_end = frames
    return sun


def relight_frame_pair(scene, obj, out_dir, frames=(1, 24), prefix="relit"):
    """Renders `obj` (a Gaussian object) LIT under a moving sun at frames[0] and frames[1] to
    out_dir/prefix_frameNNNN.png; returns the paths. The scene's camera, engine and resolution are used as they are."""
    obj.raysplats.gaussian_shading = "LIT"
    if not any(o.type == "LIGHT" and o.name == "Moving Sun" for o in scene.objects):
        add_floor_and_moving_sun(scene, obj, frames)
    # The demo's other sun would fight the moving one.
    for other in scene.objects:
        if other.type == "LIGHT" and other.name != "Moving Sun":
            other.hide_render = True
    paths = []
    for frame in frames:
        scene.frame_set(frame)
        path = os.path.join(out_dir, f"{prefix}_frame{frame:04d}.png")
        scene.render.filepath = path
        t0 = time.perf_counter()
        bpy.ops.render.render(write_still=True)
        print(f"relight: frame {frame} rendered to {path} in {time.perf_counter() - t0:.1f} s")
        paths.append(path)
    # The sun moved, so the two frames must differ: say by how much (mean absolute difference of the 8-bit images).
    images = [bpy.data.images.load(p) for p in paths]
    pixels = [np.array(image.pixels[:], dtype=np.float32) for image in images]
    for image in images:
        bpy.data.images.remove(image)
    print(f"relight: frames differ by {np.abs(pixels[0] - pixels[1]).mean() * 255:.1f} / 255 on average")
    return paths


def parse_args():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    parser = argparse.ArgumentParser(description="RaySplats relighting: a splat scene lit by a moving sun")
    parser.add_argument("--data-dir", default=os.path.join(HERE, "..", "..", "shared", "data"))
    parser.add_argument("--out-dir", default=os.path.join(HERE, "..", "demo_output"))
    parser.add_argument("--scene", default="unicorn_sh3_reordered.ply")
    parser.add_argument("--resolution", type=int, nargs=2, default=(480, 360))
    parser.add_argument("--samples", type=int, default=16)
    parser.add_argument("--frames", type=int, nargs=2, default=(1, 24))
    return parser.parse_args(argv)


def main():
    args = parse_args()
    os.makedirs(args.out_dir, exist_ok=True)
    sys.path.insert(0, HERE)
    from demo import enable_addon  # the same add-on lookup as the demo (installed, else this tree's)

    enable_addon()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    enable_addon()
    from raysplats import cli

    bpy.ops.import_scene.gaussian_splats(filepath=os.path.join(args.data_dir, args.scene))
    obj = bpy.context.view_layer.objects.active
    scene = bpy.context.scene
    cli.frame_camera(scene, distance=1.4, elevation=0.35)
    add_floor_and_moving_sun(scene, obj, tuple(args.frames))
    engine = cli.setup_render(scene, tuple(args.resolution), args.samples)
    if engine != "RAYSPLATS":
        raise SystemExit("relight: the RaySplats engine is not available (build the native module first)")
    scene.render.image_settings.file_format = "PNG"
    scene.view_settings.view_transform = "Standard"
    world = bpy.data.worlds.new("World")
    world.color = (0.08, 0.09, 0.12)  # a dim blue sky: the shadowed sides are not black
    scene.world = world
    relight_frame_pair(scene, obj, args.out_dir, tuple(args.frames),
                       prefix="relit_" + os.path.splitext(args.scene)[0])


if __name__ == "__main__":
    main()
