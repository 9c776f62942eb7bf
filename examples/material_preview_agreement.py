# Material Preview against the render: how close EEVEE's drawing of an imported splat scene (the import
# material's falloff alpha, docs/design.md §5) comes to the RaySplats render of the same scene from the same camera,
# with the material's stochastic transparency (Alpha Hashed / Dithered, today's import) and with alpha Blend (what
# imports used before Alpha Hashed). Prints a table of PSNR (dB) per scene, view and mode.
#
# EEVEE needs an OpenGL context, which Blender in --background mode may not have: run Blender with a window, on a
# virtual display when there is no screen:
#   xvfb-run -a -s "-screen 0 1280x800x24" blender --factory-startup -noaudio \
#       --python examples/material_preview_agreement.py -- --addon-dir addon --data-dir ../shared/data \
#       [--scenes unicorn_sh3_reordered.ply,donut_sh0.ply] [--size 320] [--eevee-samples 64] \
#       [--raysplats-samples 32] [--views front,back] [--out /tmp/preview_agreement]
# Blender 4.2 as a Python module (bpy from PyPI) renders EEVEE Next where it finds a display, too (slowly on llvmpipe):
#   xvfb-run -a python examples/material_preview_agreement.py -- --addon-dir addon --data-dir ../shared/data
# The functions below are also what blender_tests/gui/material_preview_agreement.py measures with.
#
# What is compared: both engines render with a transparent film, so each image is the scene's premultiplied
# colour, i.e. the scene over black; that is encoded with the sRGB curve (the Standard view transform, both
# engines use it here) and clamped to [0, 1] as a display would show it. PSNR = 10 log10(1 / MSE) over all pixels
# and channels ("image"), and over the pixels that either render covers (alpha > 1/255, "splats": the background
# does not inflate it). Two sources of difference remain with the right mode: EEVEE draws the colour of the SH
# DC term only (the render adds the view-dependent SH bands of degree 1-3), and the hashed samples' noise.
import argparse
import math
import os
import sys
import time

import bpy
import mathutils
import numpy as np

DEFAULT_SCENES = ("unicorn_sh3_reordered.ply", "donut_sh0.ply")
# Views around the splats' centre: (name, azimuth about the world Z axis, elevation), in degrees. Opposite sides,
# so that each scene is seen once with the faces drawn first in front and once behind.
VIEWS = (("front", 0.0, 15.0), ("back", 180.0, 15.0))
MODES = ("blend", "hashed")  # falloff_material.set_eevee_transparency(sorted_blending=True / False)
COVERED_ALPHA = 1.0 / 255.0


def clear_scene():
    for obj in list(bpy.data.objects):
        bpy.data.objects.remove(obj)
    for mesh in list(bpy.data.meshes):
        bpy.data.meshes.remove(mesh)
    for camera in list(bpy.data.cameras):
        bpy.data.cameras.remove(camera)


def import_scene(path):
    """A fresh scene holding only the imported splats; returns the Gaussian object."""
    clear_scene()
    result = bpy.ops.import_scene.gaussian_splats(filepath=path)
    if result != {"FINISHED"}:
        raise RuntimeError(f"importing '{path}' returned {result}")
    return bpy.context.active_object


def splat_bounds(obj):
    """Centre and radius of the bulk of the splats in world space: the median of the vertices, and the 90th
    percentile of their distance to it (floaters far out would otherwise shrink the subject to a dot)."""
    mesh = obj.data
    co = np.empty(len(mesh.vertices) * 3, dtype=np.float32)
    mesh.vertices.foreach_get("co", co)
    co = co.reshape(-1, 3).astype(np.float64)
    matrix = np.array(obj.matrix_world, dtype=np.float64)
    world = co @ matrix[:3, :3].T + matrix[:3, 3]
    centre = np.median(world, axis=0)
    radius = float(np.percentile(np.linalg.norm(world - centre, axis=1), 90))
    return mathutils.Vector(centre), radius


def place_camera(scene, centre, radius, azimuth, elevation, lens=50.0):
    camera = scene.camera
    if camera is None:
        camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
        scene.collection.objects.link(camera)
        scene.camera = camera
    camera.data.lens = lens
    # Distance at which a sphere of `radius` fills the narrower of the two fields of view (36 mm sensor fitted
    # to the wider side; the images here are 4:3).
    half_angle = math.atan(0.5 * 36.0 * 0.75 / lens)
    distance = radius / math.sin(half_angle)
    a, e = math.radians(azimuth), math.radians(elevation)
    offset = mathutils.Vector((math.sin(a) * math.cos(e), -math.cos(a) * math.cos(e), math.sin(e)))
    camera.location = centre + distance * offset
    camera.rotation_euler = (-offset).to_track_quat("-Z", "Y").to_euler()
    camera.data.clip_start = max(1e-3, 0.01 * distance)
    camera.data.clip_end = 100.0 * distance
    return camera


def prepare_scene(scene, size, world_color=(0.0, 0.0, 0.0)):
    scene.render.resolution_x, scene.render.resolution_y = size, size * 3 // 4
    scene.render.resolution_percentage = 100
    scene.render.film_transparent = True
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.view_settings.exposure = 0.0
    scene.view_settings.gamma = 1.0
    world = scene.world or bpy.data.worlds.new("World")
    world.use_nodes = False
    world.color = world_color
    scene.world = world


def render_rgba(scene, engine, path, samples):
    """Renders with F12's operator into a 32-bit EXR; returns linear premultiplied RGBA, rows bottom to top."""
    scene.render.engine = engine
    if engine == "RAYSPLATS":
        scene.raysplats.samples = samples
        scene.raysplats.seed = 1
        # EEVEE composites its hashed transparency in linear light: the reference is the linear blend, not the
        # splat viewers' display blend (the default).
        scene.raysplats.blend_space = "LINEAR"
        # EEVEE draws the flat polygons, not the viewers' projected footprints: the reference is the traced image.
        scene.raysplats.camera_ray_splatting = False
    else:
        scene.eevee.taa_render_samples = samples
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.image_settings.color_depth = "32"
    scene.render.image_settings.color_mode = "RGBA"
    scene.render.filepath = path
    bpy.ops.render.render(write_still=True)
    image = bpy.data.images.load(path)
    pixels = np.empty(image.size[0] * image.size[1] * 4, dtype=np.float32)
    image.pixels.foreach_get(pixels)
    result = pixels.reshape(image.size[1], image.size[0], 4).astype(np.float64)
    bpy.data.images.remove(image)
    return result


def srgb_display(linear):
    """sRGB transfer (IEC 61966-2-1), clamped to the displayable [0, 1]."""
    x = np.clip(linear, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)


def psnr(a, b):
    mse = float(np.mean((a - b) ** 2))
    return float("inf") if mse == 0.0 else 10.0 * math.log10(1.0 / mse)


def compare(reference_rgba, test_rgba):
    """PSNR (dB) of the test image against the reference over the whole image and over the covered pixels."""
    reference, test = srgb_display(reference_rgba[..., :3]), srgb_display(test_rgba[..., :3])
    covered = (reference_rgba[..., 3] > COVERED_ALPHA) | (test_rgba[..., 3] > COVERED_ALPHA)
    return {"image": psnr(reference, test),
            "splats": psnr(reference[covered], test[covered]) if covered.any() else float("nan"),
            "covered": float(covered.mean())}


def measure(scene_path, out_dir, size=320, eevee_samples=64, raysplats_samples=32, views=VIEWS, modes=MODES,
            save_png=True):
    """Renders one scene from each view with RaySplats and with EEVEE in each material mode.
    Returns rows {scene, view, mode, image, splats, covered, seconds}."""
    from raysplats.blender import compat
    from raysplats.objects import falloff_material

    os.makedirs(out_dir, exist_ok=True)
    scene = bpy.context.scene
    obj = import_scene(scene_path)
    prepare_scene(scene, size)
    centre, radius = splat_bounds(obj)
    name = os.path.splitext(os.path.basename(scene_path))[0]
    gaussian_material = obj.data.materials[0]
    rows = []
    for view, azimuth, elevation in views:
        place_camera(scene, centre, radius, azimuth, elevation)
        stem = os.path.join(out_dir, f"{name}_{view}")
        reference = render_rgba(scene, "RAYSPLATS", f"{stem}_raysplats.exr", raysplats_samples)
        if save_png:
            save_display_png(reference, f"{stem}_raysplats.png")
        for mode in modes:
            falloff_material.set_eevee_transparency(gaussian_material, sorted_blending=(mode == "blend"))
            start = time.perf_counter()
            eevee = render_rgba(scene, compat.EEVEE_ENGINE, f"{stem}_eevee_{mode}.exr", eevee_samples)
            seconds = time.perf_counter() - start
            if save_png:
                save_display_png(eevee, f"{stem}_eevee_{mode}.png")
            rows.append({"scene": os.path.basename(scene_path), "view": view, "mode": mode, "seconds": seconds,
                         **compare(reference, eevee)})
    falloff_material.set_eevee_transparency(gaussian_material, sorted_blending=False)
    return rows


def save_display_png(rgba, path):
    """The image as displayed (over black, sRGB) into an 8-bit PNG, for looking at."""
    height, width = rgba.shape[:2]
    image = bpy.data.images.new(os.path.basename(path), width, height, alpha=False, float_buffer=True)
    image.colorspace_settings.name = "Non-Color"  # the values are already display-encoded
    pixels = np.ones((height, width, 4), dtype=np.float32)
    pixels[..., :3] = srgb_display(rgba[..., :3])
    image.pixels.foreach_set(pixels.ravel())
    image.filepath_raw = path
    image.file_format = "PNG"
    image.save()
    bpy.data.images.remove(image)


def format_table(rows):
    lines = [f"{'scene':<28} {'view':<6} {'EEVEE mode':<11} {'PSNR image':>10} {'PSNR splats':>11} "
             f"{'covered':>8} {'EEVEE s':>8}"]
    for row in rows:
        mode = {"blend": "Blend", "hashed": "Hashed" if bpy.app.version < (4, 2, 0) else "Dithered"}[row["mode"]]
        lines.append(f"{row['scene']:<28} {row['view']:<6} {mode:<11} {row['image']:>8.2f}dB {row['splats']:>9.2f}dB "
                     f"{100 * row['covered']:>7.1f}% {row['seconds']:>8.1f}")
    return "\n".join(lines)


def main():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    parser = argparse.ArgumentParser()
    parser.add_argument("--addon-dir", required=True)
    parser.add_argument("--data-dir", required=True)
    parser.add_argument("--scenes", default=",".join(DEFAULT_SCENES))
    parser.add_argument("--size", type=int, default=320, help="image width in pixels (height is 3/4 of it)")
    parser.add_argument("--eevee-samples", type=int, default=64)
    parser.add_argument("--raysplats-samples", type=int, default=32)
    parser.add_argument("--views", default=",".join(view[0] for view in VIEWS))
    parser.add_argument("--out", default="/tmp/material_preview_agreement")
    args = parser.parse_args(argv)
    sys.path.insert(0, os.path.abspath(args.addon_dir))
    import raysplats
    raysplats.register()
    views = [view for view in VIEWS if view[0] in args.views.split(",")]

    def run():
        try:
            bpy.context.preferences.view.show_splash = False
            rows = []
            for scene_file in args.scenes.split(","):
                rows += measure(os.path.join(args.data_dir, scene_file), args.out, args.size, args.eevee_samples,
                                args.raysplats_samples, views)
            print(f"\nMaterial Preview (EEVEE, {args.eevee_samples} samples) against the RaySplats render "
                  f"({args.raysplats_samples} samples), {args.size}x{args.size * 3 // 4}, Blender "
                  f"{bpy.app.version_string}; images in {args.out}\n{format_table(rows)}", flush=True)
            code = 0
        except Exception:
            import traceback
            traceback.print_exc()
            code = 1
        # Quit without saving or asking ("save changes?" in a window), and without the add-on's classes being
        # unregistered at exit, which crashes the bpy module.
        os._exit(code)

    if bpy.app.background:
        # Blender as a Python module, or --background: there is no event loop to wait for.
        run()
    else:
        # EEVEE renders once the window and its OpenGL context exist: start from the first timer tick.
        bpy.app.timers.register(run, first_interval=0.5)


if __name__ == "__main__":
    main()
