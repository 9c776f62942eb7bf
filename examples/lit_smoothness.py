# Lit splats as a user renders them: each scene imported, framed, and rendered with F12 twice, its Gaussians Lit
# (under a sun and a dim sky) and Baked, at the same seed. Lit camera rays are always ray traced (never splatted), so
# this is the image that shows what the traced camera path does on this CPU. Writes both PNGs per scene and prints:
# - smoothness of the Lit/Baked luminance ratio r over splat pixels (alpha > 0.5): median |r - median3x3(r)| /
#   median3x3(r). Shading varies slowly over a surface; speckle or stripes of lost Gaussians raise it;
# - packet rows: the mean alpha of image rows 2-3 of every 4 against rows 0-1 (camera rays travel in 4 x 4 packets;
#   a callback that mistakes one ray for another loses the lower half of each packet: ratio far below 1).
#   blender -b --factory-startup --python-exit-code 1 --python examples/lit_smoothness.py -- \
#       --data-dir ../shared/data --out-dir demo_output [--scenes biker_v4.spz unicorn_sh3_reordered.ply] \
#       [--resolution 640 360] [--samples 64]
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
    parser = argparse.ArgumentParser(description="Lit/Baked luminance smoothness of real splat scenes")
    parser.add_argument("--data-dir", default=os.path.join(HERE, "..", "..", "shared", "data"))
    parser.add_argument("--out-dir", default=os.path.join(HERE, "..", "demo_output"))
    parser.add_argument("--scenes", nargs="+", default=["biker_v4.spz", "unicorn_sh3_reordered.ply"])
    parser.add_argument("--resolution", type=int, nargs=2, default=(640, 360))
    parser.add_argument("--samples", type=int, default=64)
    parser.add_argument("--measure-only", action="store_true",
                        help="only measure the PNGs an earlier run left in --out-dir")
    return parser.parse_args(argv)


def load_rgba(path):
    image = bpy.data.images.load(path)
    width, height = image.size
    pixels = np.array(image.pixels[:], dtype=np.float32).reshape(height, width, 4)[::-1]
    bpy.data.images.remove(image)
    return pixels


def render_rgba(scene, path):
    """F12 to `path` (16-bit PNG, RGBA); returns the image as float rows top to bottom."""
    scene.render.filepath = path
    bpy.ops.render.render(write_still=True)
    return load_rgba(path)


def median3x3(a):
    padded = np.pad(a, 1, mode="edge")
    windows = np.lib.stride_tricks.sliding_window_view(padded, (3, 3))
    return np.median(windows.reshape(*a.shape, 9), axis=-1)


def luminance(rgb):
    return rgb @ np.array([0.2126, 0.7152, 0.0722], dtype=np.float32)


def main():
    args = parse_args()
    args.out_dir = os.path.abspath(args.out_dir)
    os.makedirs(args.out_dir, exist_ok=True)
    sys.path.insert(0, HERE)
    from demo import enable_addon

    enable_addon()

    print(f"lit_smoothness: Embree configuration \"{os.environ.get('RAYSPLATS_EMBREE_CONFIG', '')}\", "
          f"Blender {bpy.app.version_string}")
    for name in args.scenes:
        stem = os.path.splitext(name)[0]
        if args.measure_only:
            report(name, *(load_rgba(os.path.join(args.out_dir, f"lit_smoothness_{stem}_{s}.png")) for s in ("lit", "baked")))
            continue
        bpy.ops.wm.read_factory_settings(use_empty=True)
        enable_addon()
        from raysplats import cli

        bpy.ops.import_scene.gaussian_splats(filepath=os.path.join(args.data_dir, name))
        obj = bpy.context.view_layer.objects.active
        scene = bpy.context.scene
        cli.frame_camera(scene, distance=1.4, elevation=0.35)
        bpy.ops.object.light_add(type="SUN", rotation=(math.radians(40), 0.0, math.radians(-30)))
        bpy.context.object.data.energy = 2.5
        if cli.setup_render(scene, tuple(args.resolution), args.samples) != "RAYSPLATS":
            raise SystemExit("lit_smoothness: the RaySplats engine is not available (build the native module first)")
        scene.render.film_transparent = True
        scene.render.image_settings.file_format = "PNG"
        scene.render.image_settings.color_mode = "RGBA"
        scene.render.image_settings.color_depth = "16"
        scene.view_settings.view_transform = "Standard"
        world = bpy.data.worlds.new("World")
        world.color = (0.08, 0.09, 0.12)
        scene.world = world
        images = {}
        for shading in ("LIT", "BAKED"):
            obj.raysplats.gaussian_shading = shading
            t0 = time.perf_counter()
            images[shading] = render_rgba(scene, os.path.join(args.out_dir, f"lit_smoothness_{stem}_{shading.lower()}.png"))
            print(f"lit_smoothness: {name} {shading} rendered in {time.perf_counter() - t0:.1f} s")
        report(name, images["LIT"], images["BAKED"])


def report(name, lit, baked):
    """Prints the two figures of the header for a Lit and a Baked render (float RGBA rows, top to bottom)."""
    splat = (lit[..., 3] > 0.5) & (baked[..., 3] > 0.5) & (luminance(baked[..., :3]) > 0.02)
    ratio = np.where(splat, luminance(lit[..., :3]) / np.maximum(luminance(baked[..., :3]), 1e-6), np.nan)
    local = median3x3(np.nan_to_num(ratio, nan=0.0))
    keep = splat & (local > 0)
    roughness = float(np.median(np.abs(ratio[keep] - local[keep]) / local[keep])) if keep.any() else float("nan")
    # Packet rows, over the pixels the Baked render covers (its camera rays are splatted, not traced in packets).
    covered = baked[..., 3] > 0.5
    lower = (np.arange(lit.shape[0]) % 4 >= 2)[:, None] & covered
    upper = (np.arange(lit.shape[0]) % 4 < 2)[:, None] & covered
    packet_rows = float(lit[..., 3][lower].mean() / max(lit[..., 3][upper].mean(), 1e-6))
    print(f"lit_smoothness: {name}: {int(splat.sum())} splat pixels, Lit/Baked luminance ratio median "
          f"{float(np.nanmedian(ratio)):.3f}, smoothness median|r - med3x3(r)|/med3x3(r) = {roughness:.4f}, "
          f"Lit alpha in packet rows 2-3 / rows 0-1 = {packet_rows:.3f}")

if __name__ == "__main__":
    main()
