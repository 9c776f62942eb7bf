# GUI test (needs a display for EEVEE; ctest runs it under xvfb-run): Blender's own viewport shows an
# imported splat scene as it will render.
# 1. Material Preview: EEVEE's render of a real scene (the import material, Alpha Hashed / Dithered) against the
#    RaySplats render from the same camera, from the front and from the back, must reach MIN_PSNR_SPLATS; the
#    material in alpha Blend mode (what imports used before Alpha Hashed) must fall short of it from the front, where
#    Blend draws the back of the model over its face. Measured with examples/material_preview_agreement.py's code.
# 2. Solid shading, in Object and in Edit Mode, shows the splat colours: the 3D view's pixels on the object are
#    coloured (mean chroma above MIN_SOLID_CHROMA), not Solid's default grey.
#   xvfb-run -a -s "-screen 0 1280x800x24" blender --factory-startup -noaudio --python material_preview_agreement.py \
#       -- --addon-dir A --data-dir D --out-dir DIR [--examples-dir E]
import math
import os
import sys
import traceback

import bpy
import mathutils
import numpy as np

argv = sys.argv[sys.argv.index("--") + 1:]
options = dict(zip(argv[::2], argv[1::2]))
sys.path.insert(0, options["--addon-dir"])
sys.path.insert(0, options.get("--examples-dir", os.path.join(os.path.dirname(__file__), "..", "..", "examples")))
import raysplats  # noqa: E402

raysplats.register()
# Before the event loop starts, so that no splash covers the 3D view in the screenshots.
bpy.context.preferences.view.show_splash = False
import material_preview_agreement as agreement  # noqa: E402
from raysplats.blender import compat
from raysplats.objects import falloff_material  # noqa: E402

SCENE = "unicorn_sh3_reordered.ply"
SIZE, EEVEE_SAMPLES, RAYSPLATS_SAMPLES = 240, 64, 32
# PSNR over the pixels the splats cover, measured at this size and these samples on Blender 3.4 (llvmpipe):
# Alpha Hashed front 27.8 dB, back 27.3 dB; alpha Blend front 11.9 dB, back 23.2 dB. The remaining difference
# with Hashed is the view-dependent SH colour EEVEE does not draw and the hashed samples' noise; 25 dB leaves 2 dB
# of margin to the hashed results and is 13 dB above Blend's front view.
MIN_PSNR_SPLATS = 25.0
# Mean chroma (max - min of the screenshot's RGB, 0..1) of the 3D view's pixels on the unicorn, measured on Blender
# 3.4: splat colours 0.127 in Object Mode and 0.080 in Edit Mode (black edges and vertices cover part of the faces);
# Solid's material colour (grey) 0.008 in Edit Mode. 0.03 is 2.7x below the one and 4x above the other.
MIN_SOLID_CHROMA = 0.03

state = {"tick": 0}


def fail(message):
    print(f"MATERIAL PREVIEW TEST FAILED: {message}", flush=True)
    os._exit(1)


def view3d():
    for area in bpy.context.screen.areas:
        if area.type == "VIEW_3D":
            return area, next(region for region in area.regions if region.type == "WINDOW")
    fail("no 3D view")


def check_material_preview():
    rows = agreement.measure(os.path.join(options["--data-dir"], SCENE), options["--out-dir"], SIZE, EEVEE_SAMPLES,
                             RAYSPLATS_SAMPLES, views=agreement.VIEWS, modes=("hashed", "blend"))
    print(agreement.format_table(rows), flush=True)
    for row in rows:
        if row["mode"] == "hashed" and not row["splats"] >= MIN_PSNR_SPLATS:
            fail(f"Material Preview differs from the render: {row['scene']} {row['view']} PSNR {row['splats']:.2f} dB "
                 f"< {MIN_PSNR_SPLATS} dB")
    blend_front = next(row for row in rows if row["mode"] == "blend" and row["view"] == "front")
    if blend_front["splats"] >= MIN_PSNR_SPLATS:
        fail(f"the threshold does not tell alpha Blend apart: Blend front view {blend_front['splats']:.2f} dB")


def solid_chroma(name):
    """Mean chroma of the 3D view's pixels that are not its background, from a screenshot of the view."""
    area, region = view3d()
    path = os.path.join(options["--out-dir"], f"solid_{name}.png")
    with bpy.context.temp_override(area=area, region=region):
        bpy.ops.screen.screenshot_area(filepath=path)
    image = bpy.data.images.load(path)
    pixels = np.empty(image.size[0] * image.size[1] * 4, dtype=np.float32)
    image.pixels.foreach_get(pixels)
    rgb = pixels.reshape(image.size[1], image.size[0], 4)[..., :3]
    bpy.data.images.remove(image)
    # The middle half of the view, where view_selected put the object; the background is the most common colour.
    h, w = rgb.shape[:2]
    centre = rgb[h // 4:3 * h // 4, w // 4:3 * w // 4].reshape(-1, 3)
    colours, counts = np.unique(np.round(centre * 255).astype(np.int32), axis=0, return_counts=True)
    background = colours[np.argmax(counts)] / 255.0
    on_object = np.abs(centre - background).max(axis=1) > 0.05
    if on_object.mean() < 0.05:
        fail(f"the object covers only {100 * on_object.mean():.1f} % of the 3D view ({name})")
    chroma = centre[on_object].max(axis=1) - centre[on_object].min(axis=1)
    return float(chroma.mean())


def step():
    try:
        state["tick"] += 1
        area, region = view3d()
        space = area.spaces.active
        if state["tick"] == 1:
            os.makedirs(options["--out-dir"], exist_ok=True)
            check_material_preview()
            # measure() left the imported scene, switched Solid views and the Hashed material: look at it in Solid.
            obj = bpy.context.active_object
            if space.shading.color_type != compat.SOLID_COLOR_TYPE_ATTRIBUTE:
                fail(f"the import left Solid colour at {space.shading.color_type}")
            space.shading.type = "SOLID"
            # Frame the bulk of the splats from the front (view_selected would frame the floaters too).
            centre, radius = agreement.splat_bounds(obj)
            view = space.region_3d
            view.view_perspective = "PERSP"
            view.view_location = centre
            view.view_rotation = mathutils.Euler((math.radians(75.0), 0.0, 0.0)).to_quaternion()
            view.view_distance = 3.0 * radius
            # Selection colours are orange: no outline in Object Mode, nothing selected in Edit Mode, so that the
            # chroma measures the shading alone.
            space.overlay.show_outline_selected = False
            area.tag_redraw()
            return 1.0
        if state["tick"] == 2:
            state["object chroma"] = solid_chroma("object_mode")
            obj = bpy.context.active_object
            with bpy.context.temp_override(area=area, region=region, active_object=obj, object=obj):
                bpy.ops.object.mode_set(mode="EDIT")
                bpy.ops.mesh.select_all(action="DESELECT")
            area.tag_redraw()
            return 1.0
        if state["tick"] == 3:
            state["edit chroma"] = solid_chroma("edit_mode")
            space.shading.color_type = "MATERIAL"
            area.tag_redraw()
            return 1.0
        state["grey chroma"] = solid_chroma("edit_mode_material_colour")
        print(f"SOLID CHROMA: Object Mode {state['object chroma']:.3f}, Edit Mode {state['edit chroma']:.3f}, "
              f"Edit Mode with the material colour {state['grey chroma']:.3f}", flush=True)
        for mode in ("object", "edit"):
            if state[f"{mode} chroma"] < MIN_SOLID_CHROMA:
                fail(f"Solid shading in {mode} mode is not coloured: chroma {state[f'{mode} chroma']:.3f}")
        if state["grey chroma"] >= MIN_SOLID_CHROMA:
            fail(f"the chroma limit does not tell grey Solid shading apart: {state['grey chroma']:.3f}")
        print("MATERIAL PREVIEW TEST PASSED", flush=True)
        os._exit(0)
    except Exception:
        traceback.print_exc()
        fail("exception")


bpy.app.timers.register(step, first_interval=0.5)
