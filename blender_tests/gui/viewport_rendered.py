# GUI test (needs a display; ctest runs it under xvfb-run): a real splat scene in a 3D view set to Rendered
# shading with the RaySplats engine must draw progressively refined images without errors.
#   xvfb-run blender --factory-startup --python viewport_rendered.py -- --addon-dir A --data-dir D --out PNG
import os
import sys
import traceback

import bpy

argv = sys.argv[sys.argv.index("--") + 1:]
options = dict(zip(argv[::2], argv[1::2]))
sys.path.insert(0, options["--addon-dir"])
import raysplats  # noqa: E402

raysplats.register()
from raysplats.engine import viewport  # noqa: E402

state = {"tick": 0}


def fail(message):
    print(f"VIEWPORT TEST FAILED: {message}", flush=True)
    os._exit(1)


def step():
    try:
        state["tick"] += 1
        if state["tick"] == 1:
            bpy.context.preferences.view.show_splash = False
            bpy.ops.import_scene.gaussian_splats(filepath=os.path.join(options["--data-dir"], "biker_v4.spz"))
            bpy.context.scene.render.engine = "RAYSPLATS"
            bpy.context.scene.raysplats.viewport_samples = 8
            for area in bpy.context.screen.areas:
                if area.type == "VIEW_3D":
                    area.spaces.active.shading.type = "RENDERED"
                    area.tag_redraw()
            return 1.0
        if viewport.last_draw["samples"] < 8 and state["tick"] < 60:
            return 0.5
        if viewport.last_draw["samples"] < 8:
            fail(f"the viewport stopped refining at {viewport.last_draw}")
        if viewport.last_draw["splats"] != 152746:
            fail(f"the viewport drew {viewport.last_draw['splats']} splats, expected 152746")
        bpy.ops.screen.screenshot(filepath=options["--out"])
        print(f"VIEWPORT TEST PASSED: {viewport.last_draw}", flush=True)
        os._exit(0)
    except Exception:
        traceback.print_exc()
        fail("exception")


bpy.app.timers.register(step, first_interval=1.0)
