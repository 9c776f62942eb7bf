# The RaySplats demo, headless: import a real trained splat scene, edit it with Blender tools, render it and
# export it back to splat formats.
#   blender -b --factory-startup --python-exit-code 1 --python examples/demo.py -- \
#       --data-dir ../shared/data --out-dir demo_output [--scene biker_v4.spz] [--samples 16]
import argparse
import math
import os
import sys
import time

import bpy
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))


def parse_args():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    parser = argparse.ArgumentParser(description="RaySplats demo: import, edit, render, export")
    parser.add_argument("--data-dir", default=os.path.join(HERE, "..", "..", "shared", "data"))
    parser.add_argument("--out-dir", default=os.path.join(HERE, "..", "demo_output"))
    parser.add_argument("--scene", default="biker_v4.spz")
    parser.add_argument("--resolution", type=int, nargs=2, default=(640, 360))
    parser.add_argument("--samples", type=int, default=8)
    return parser.parse_args(argv)


def enable_addon():
    """Uses the installed add-on if there is one, else the one in this source tree."""
    try:
        import raysplats  # noqa: F401  (installed and enabled by scripts/install_addon.sh)
        if not hasattr(bpy.types.Object, "raysplats"):
            raysplats.register()
    except ImportError:
        sys.path.insert(0, os.path.join(HERE, "..", "addon"))
        import raysplats
        raysplats.register()


def main():
    args = parse_args()
    args.out_dir = os.path.abspath(args.out_dir)  # (Blender's save operator refuses a relative path)
    os.makedirs(args.out_dir, exist_ok=True)
    enable_addon()
    from raysplats.io import export_splats
    from raysplats import cli

    bpy.ops.wm.read_factory_settings(use_empty=True)
    enable_addon()
    scene_path = os.path.join(args.data_dir, args.scene)
    t0 = time.perf_counter()

    # 1. Import: one polygon per Gaussian, upright (the up axis follows the format's convention).
    bpy.ops.import_scene.gaussian_splats(filepath=scene_path)
    obj = bpy.context.view_layer.objects.active
    print(f"demo: imported {len(obj.data.polygons):,} Gaussians from {args.scene}")

    # 2. Edit with Blender tools: crop away the lowest fifth of the splats (a ground/floater clean-up),
    #    turn the object 30° and scale it up.
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.select_all(action="DESELECT")
    bpy.ops.object.mode_set(mode="OBJECT")
    centres = np.empty(len(obj.data.polygons) * 3, dtype=np.float32)
    obj.data.polygons.foreach_get("center", centres)
    world = np.array(obj.matrix_world)
    heights = (centres.reshape(-1, 3) @ world[:3, :3].T + world[:3, 3])[:, 2]
    obj.data.polygons.foreach_set("select", heights < np.percentile(heights, 20))
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.delete(type="FACE")
    bpy.ops.object.mode_set(mode="OBJECT")
    obj.rotation_euler.z += math.radians(30)
    obj.scale = (1.2, 1.2, 1.2)
    print(f"demo: edited: {len(obj.data.polygons):,} Gaussians left after the crop, rotated 30°, scaled 1.2")

    # 3. Render with the RaySplats engine: splats and a floor, ray traced together.
    scene = bpy.context.scene
    cli.frame_camera(scene, distance=1.6, elevation=0.3)
    # A floor under the splats and a sun: the splats cast their semi-transparent shadow on it.
    corners = np.empty(len(obj.data.vertices) * 3, dtype=np.float32)
    obj.data.vertices.foreach_get("co", corners)
    world_matrix = np.array(obj.matrix_world)
    points = corners.reshape(-1, 3) @ world_matrix[:3, :3].T + world_matrix[:3, 3]
    floor_height = float(np.percentile(points[:, 2], 1))
    bpy.ops.mesh.primitive_plane_add(size=50.0, location=(*np.median(points, axis=0)[:2], floor_height))
    bpy.ops.object.light_add(type="SUN", rotation=(math.radians(35), 0.0, math.radians(-40)))
    bpy.context.object.data.energy = 1.2
    cli.setup_render(scene, args.resolution, args.samples)
    scene.render.image_settings.file_format = "PNG"
    scene.view_settings.view_transform = "Standard"
    world = bpy.data.worlds.new("World")
    world.color = (0.05, 0.05, 0.05)
    scene.world = world
    render_path = os.path.join(args.out_dir, "render.png")
    scene.render.filepath = render_path
    t_render, cpu_render = time.perf_counter(), time.process_time()
    bpy.ops.render.render(write_still=True)
    print(f"demo: rendered {render_path} with {scene.render.engine} in {time.perf_counter() - t_render:.1f} s "
          f"({time.process_time() - cpu_render:.1f} s of CPU)")

    # 3b. Relight: the same splats as lit surfaces (their captured light divided out) under a sun that turns round
    #     them; two frames of that animation, at half the resolution, 4 samples and one bounce to keep the demo quick
    #     (examples/relight_moving_sun.py renders the unicorn at full quality).
    if scene.render.engine == "RAYSPLATS":
        sys.path.insert(0, HERE)
        import relight_moving_sun
        kept = scene.raysplats.samples, scene.raysplats.max_bounces
        scene.render.resolution_percentage = 50
        scene.raysplats.samples, scene.raysplats.max_bounces = 4, 1
        t_relight, cpu_relight = time.perf_counter(), time.process_time()
        relight_moving_sun.relight_frame_pair(scene, obj, args.out_dir, frames=(1, 24))
        print(f"demo: relit frame pair in {time.perf_counter() - t_relight:.1f} s "
              f"({time.process_time() - cpu_relight:.1f} s of CPU)")
        scene.render.resolution_percentage = 100
        scene.raysplats.samples, scene.raysplats.max_bounces = kept

    # 4. Export the edited scene back to splat formats (edits applied, file convention restored).
    for extension in (".ply", ".spz"):
        path = os.path.join(args.out_dir, "edited_" + os.path.splitext(args.scene)[0] + extension)
        count, stats, _ = export_splats.export_gaussian_splats(bpy.context, path)
        print(f"demo: exported {count:,} Gaussians to {path} ({os.path.getsize(path) / 1e6:.1f} MB)")
    bpy.ops.wm.save_as_mainfile(filepath=os.path.join(args.out_dir, "demo.blend"))
    print(f"demo: done in {time.perf_counter() - t0:.1f} s; outputs in {args.out_dir}")


if __name__ == "__main__":
    main()
