# GUI test (needs a display; ctest runs it under xvfb-run): a real splat scene in a 3D view set to Rendered
# shading with the RaySplats engine must draw progressively refined images without errors; then moving the object,
# editing its vertices in Object Mode and in Edit Mode must each update the image in place (no scene rebuild) and
# refine again. Prints the time from each edit to its first image.
#   xvfb-run blender --factory-startup --python viewport_rendered.py -- --addon-dir A --data-dir D --out PNG
#   [--scene showroom_1.5M.ply]   (the default is biker_v4.spz, 152,746 splats)
import os
import sys
import time
import traceback

import bpy

argv = sys.argv[sys.argv.index("--") + 1:]
options = dict(zip(argv[::2], argv[1::2]))
sys.path.insert(0, options["--addon-dir"])
import raysplats  # noqa: E402

raysplats.register()
from raysplats.engine import viewport  # noqa: E402

state = {"tick": 0, "phase": "refine"}
scene_file = options.get("--scene", "biker_v4.spz")
EXPECTED_SPLATS = {"biker_v4.spz": 152746}


def view3d():
    for area in bpy.context.screen.areas:
        if area.type == "VIEW_3D":
            return area, next(r for r in area.regions if r.type == "WINDOW")
    fail("no 3D view")


def edit(phase):
    """Starts the next edit and remembers the counters it must change."""
    obj = bpy.data.objects[state["object"]]
    state.update(phase=phase, edit_time=time.perf_counter(), updates=viewport.last_draw.get("updates", 0),
                 rebuilds=viewport.last_draw.get("rebuilds", 0), draws=viewport.last_draw["draws"])
    if phase == "move":
        obj.location.x += 0.3
    elif phase == "object-mode vertices":
        mesh = obj.data
        co = [0.0] * (len(mesh.vertices) * 3)
        mesh.vertices.foreach_get("co", co)
        for i in range(0, 3 * 64, 3):  # the first 8 faces move up
            co[i + 2] += 0.2
        mesh.vertices.foreach_set("co", co)
        mesh.update()
    elif phase == "edit-mode vertices":
        area, region = view3d()
        with bpy.context.temp_override(area=area, region=region, active_object=obj, object=obj):
            bpy.ops.object.mode_set(mode="EDIT")
            bpy.ops.mesh.select_all(action="DESELECT")
            import bmesh
            bm = bmesh.from_edit_mesh(obj.data)
            bm.faces.ensure_lookup_table()
            for face in list(bm.faces)[:100]:
                face.select_set(True)
            bm.select_flush(True)
            bmesh.update_edit_mesh(obj.data)
            state["edit_time"] = time.perf_counter()
            result = bpy.ops.transform.translate(value=(0.0, 0.0, 0.25))
            if result != {"FINISHED"}:
                fail(f"translate in Edit Mode returned {result}")
    area, _ = view3d()
    area.tag_redraw()


def check_updated():
    """True once the edit has been applied in place and the image refined again."""
    draw = viewport.last_draw
    if draw.get("rebuilds", 0) != state["rebuilds"]:
        fail(f"'{state['phase']}' rebuilt the whole scene instead of updating it: {draw}")
    if draw.get("updates", 0) <= state["updates"] or draw["draws"] <= state["draws"]:
        return False
    if "first_image" not in state:
        state["first_image"] = draw["time"] - state["edit_time"]
    return draw["samples"] >= 8


def fail(message):
    print(f"VIEWPORT TEST FAILED: {message}", flush=True)
    os._exit(1)


def step():
    try:
        state["tick"] += 1
        if state["tick"] == 1:
            bpy.context.preferences.view.show_splash = False
            bpy.ops.import_scene.gaussian_splats(filepath=os.path.join(options["--data-dir"], scene_file))
            state["object"] = bpy.context.active_object.name
            bpy.context.scene.render.engine = "RAYSPLATS"
            bpy.context.scene.raysplats.viewport_samples = 8
            for area in bpy.context.screen.areas:
                if area.type == "VIEW_3D":
                    area.spaces.active.shading.type = "RENDERED"
                    area.tag_redraw()
            return 1.0
        if state["tick"] > 240:
            fail(f"timed out in phase '{state['phase']}': {viewport.last_draw}")
        if state["phase"] == "refine":
            if viewport.last_draw["samples"] < 8:
                return 0.5
            expected = EXPECTED_SPLATS.get(scene_file)
            if expected and viewport.last_draw["splats"] != expected:
                fail(f"the viewport drew {viewport.last_draw['splats']} splats, expected {expected}")
            bpy.ops.screen.screenshot(filepath=options["--out"])
            edit("move")
            return 0.1
        if not check_updated():
            return 0.1
        print(f"VIEWPORT: '{state['phase']}' updated in place; first image {state.pop('first_image'):.3f} s "
              f"after the edit", flush=True)
        next_phase = {"move": "object-mode vertices", "object-mode vertices": "edit-mode vertices"}.get(state["phase"])
        if next_phase:
            edit(next_phase)
            return 0.1
        print(f"VIEWPORT TEST PASSED: {viewport.last_draw}", flush=True)
        os._exit(0)
    except Exception:
        traceback.print_exc()
        fail("exception")


bpy.app.timers.register(step, first_interval=1.0)
