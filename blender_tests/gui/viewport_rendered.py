# GUI test (needs a display; ctest runs it under xvfb-run): a real splat scene in a 3D view set to Rendered
# shading with the RaySplats engine must draw progressively refined images without errors, and Blender must stay
# responsive meanwhile (the render runs on its own thread): no view_draw or view_update call may keep the UI thread
# MAX_UI_GAP_SECONDS, and the gaps between two ticks of a UI timer while the viewport refines are compared with
# Blender's own redraw of the view with nothing rendering, measured in the same run (which, in software GL on this
# shared 2-core machine, alone takes longer than MAX_UI_GAP_SECONDS). Then moving the object, editing its vertices
# in Object Mode and in Edit Mode must each update the image in place (no scene rebuild; in Edit Mode read in place
# from the BMesh) and refine again. Last, F12 must show at
# least two partial results before the render ends (the render window refines). Prints the time from each edit to
# its first image, the UI gap and the partial results' times.
#   xvfb-run blender --factory-startup --python viewport_rendered.py -- --addon-dir A --data-dir D --out PNG
#   [--scene showroom_1.5M.ply]   (the default is biker_v4.spz, 152,746 splats)
import os
import sys
import threading
import time
import traceback

import bpy

argv = sys.argv[sys.argv.index("--") + 1:]
options = dict(zip(argv[::2], argv[1::2]))
sys.path.insert(0, options["--addon-dir"])
import raysplats  # noqa: E402

raysplats.register()
from raysplats.blender import mesh_read  # noqa: E402
from raysplats.engine import final, viewport  # noqa: E402

state = {"tick": 0, "phase": "refine", "started": time.perf_counter()}
# A hang guard, not a verdict on speed: many times what the test takes alone or beside other builds
# (docs/benchmarks.md); ctest's TIMEOUT (blender_tests/CMakeLists.txt) is above it, so this message, naming the phase,
# comes first.
HANG_GUARD_SECONDS = 1500
MAX_UI_GAP_SECONDS = 0.1
REDRAW_BASELINE_SECONDS = 1.5
# Moving EDITED_FACES splats in Edit Mode: the time from the edit to the first updated image, Blender's own update and
# undo step included, is printed (docs/benchmarks.md, Editing big scenes, has the figures) and not bounded here (it
# swings with the machine's load); the verdict is on behaviour: every read of the moved mesh went in place through
# its BMesh (mesh_read.read_edit_mode_positions returned "read"), none converted the whole mesh.
EDITED_FACES = 100
edit_mode_reads = []  # what read_edit_mode_positions returned during the phase 'edit-mode vertices'
_read_edit_mode_positions = mesh_read.read_edit_mode_positions


def _counted_edit_mode_read(*args):
    result = _read_edit_mode_positions(*args)
    if state["phase"] == "edit-mode vertices":
        edit_mode_reads.append(result)
    return result


mesh_read.read_edit_mode_positions = _counted_edit_mode_read
# The UI timer: ticks every 10 ms when Blender's main loop is free; `gaps` are the intervals between two ticks while
# `measuring`, `gap` the longest.
# A gap counts the time the UI thread ran or waited for something (the GIL, a lock, the engine), not the time it was
# ready to run while other processes had the cores: that share is the thread's run-queue delay, which Linux reports
# in /proc/self/task/<tid>/schedstat (ctest runs Blender with LP_NUM_THREADS=0, so that software GL draws on the UI
# thread itself and its waits for starved rasterizer threads do not count either). Under other builds' load most of a
# wall-time gap is such a delay (docs/benchmarks.md, Rendering, has the figures).
ui_timer = {"last": None, "delay": 0.0, "gap": 0.0, "gaps": [], "measuring": False, "ticks": 0}


def run_queue_delay():
    """Seconds the calling thread has been ready to run but waiting for a core (0.0 where the kernel does not say)."""
    try:
        with open(f"/proc/self/task/{threading.get_native_id()}/schedstat") as schedstat:
            return int(schedstat.read().split()[1]) / 1e9
    except (OSError, ValueError, IndexError):
        return 0.0


def ui_tick():
    now, delay = time.perf_counter(), run_queue_delay()
    if ui_timer["measuring"]:
        if ui_timer["last"] is not None:
            gap = (now - ui_timer["last"]) - (delay - ui_timer["delay"])
            ui_timer["gap"] = max(ui_timer["gap"], gap)
            ui_timer["gaps"].append(gap)
        ui_timer["ticks"] += 1
    ui_timer["last"], ui_timer["delay"] = now, delay
    return 0.01
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
        # (select_in_edit_mode() entered Edit Mode and selected the splats earlier, as a user does before moving.)
        area, region = view3d()
        with bpy.context.temp_override(area=area, region=region, active_object=obj, object=obj):
            state["edit_time"] = time.perf_counter()
            result = bpy.ops.transform.translate(value=(0.0, 0.0, 0.25))
            # Blender's own share: the operator with the depsgraph updates it triggers (the engine's in-place updates
            # among them) and its undo step, a copy of the whole edit mesh.
            state["operator_seconds"] = time.perf_counter() - state["edit_time"]
            if result != {"FINISHED"}:
                fail(f"translate in Edit Mode returned {result}")
    area, _ = view3d()
    area.tag_redraw()


def select_in_edit_mode():
    """Tab (every selected object: all the pieces of a split scene) and a selection of EDITED_FACES splats of the
    active object, a user's steps before the move that edit("edit-mode vertices") times."""
    obj = bpy.data.objects[state["object"]]
    area, region = view3d()
    with bpy.context.temp_override(area=area, region=region, active_object=obj, object=obj):
        bpy.ops.object.mode_set(mode="EDIT")
        bpy.ops.mesh.select_all(action="DESELECT")
        import bmesh
        bm = bmesh.from_edit_mesh(obj.data)
        bm.faces.ensure_lookup_table()
        for face in list(bm.faces)[:EDITED_FACES]:
            face.select_set(True)
        bm.select_flush(True)
        # A selection change, as Blender's select operators report it (no geometry changed).
        bmesh.update_edit_mesh(obj.data, loop_triangles=False, destructive=False)
    state["edit_mode_objects"] = len(bpy.context.objects_in_mode)
    state.update(phase="select", draws=viewport.last_draw["draws"], selected_at=time.perf_counter())
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


def start_final_render():
    """F12 as a user starts it (a render window, the render on Blender's job thread)."""
    area, region = view3d()
    obj = bpy.data.objects[state["object"]]
    with bpy.context.temp_override(area=area, region=region, active_object=obj, object=obj):
        bpy.ops.object.mode_set(mode="OBJECT")
    area.spaces.active.shading.type = "SOLID"  # the viewport's render would share the two cores
    scene = bpy.context.scene
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    scene.collection.objects.link(camera)
    scene.camera = camera
    with bpy.context.temp_override(area=area, region=region):
        bpy.ops.view3d.camera_to_view_selected()
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 640, 360, 100
    scene.raysplats.samples = int(options.get("--final-samples", "24"))
    state.update(phase="final render", render_done=False)
    bpy.app.handlers.render_complete.append(lambda *args: state.update(render_done=True))
    bpy.app.handlers.render_cancel.append(lambda *args: state.update(render_done=True))
    result = bpy.ops.render.render("INVOKE_DEFAULT")
    if result != {"RUNNING_MODAL"}:
        fail(f"F12 returned {result}")
    return 0.2


def check_final_render():
    if not state["render_done"]:
        return 0.2
    shown = final.last_render["partial_results"]
    print(f"F12: {len(shown)} partial results before the end (s after start, samples): "
          + ", ".join(f"{t:.2f} s {n}" for t, n in shown) + f"; kept {final.last_render['samples']} samples",
          flush=True)
    if final.last_render["samples"] != bpy.context.scene.raysplats.samples:
        fail(f"F12 ended with {final.last_render}")
    if len(shown) < 2:
        fail(f"F12 showed {len(shown)} partial results before the end; at least 2 expected")
    gaps = [b[0] - a[0] for a, b in zip(shown, shown[1:])]
    if gaps and min(gaps) < final.UPDATE_SECONDS:
        fail(f"partial results came faster than one per {final.UPDATE_SECONDS} s: {gaps}")
    print(f"VIEWPORT TEST PASSED: {viewport.last_draw}", flush=True)
    os._exit(0)


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
            bpy.context.scene.view_settings.view_transform = "Standard"  # as the RaySplats Film panel advises
            for area in bpy.context.screen.areas:
                if area.type == "VIEW_3D":
                    area.spaces.active.shading.type = "RENDERED"
                    # Overlays make Blender draw every mesh's depth under an external engine's image (the external
                    # draw engine's depth pass), in software GL under Xvfb: long redraws of biker_v4 with no
                    # render running at all. The gap measured is the engine's, so they are off.
                    area.spaces.active.overlay.show_overlays = False
                    area.tag_redraw()
            return 1.0
        if time.perf_counter() - state["started"] > HANG_GUARD_SECONDS:
            fail(f"no end after {HANG_GUARD_SECONDS} s (a hang), in phase '{state['phase']}': {viewport.last_draw}")
        if state["phase"] == "refine":
            if viewport.last_draw["draws"] > 0 and not ui_timer["measuring"] and "gap_start" not in state:
                # The scene is synced (on the UI thread, once) and the render runs: measure from here.
                ui_timer.update(measuring=True, last=None, gap=0.0, gaps=[], ticks=0)
                viewport.last_draw["longest_ui_call"] = 0.0
                state["gap_start"] = time.perf_counter()
            if viewport.last_draw["samples"] < 8:
                return 0.05
            ui_timer["measuring"] = False
            state.update(refine_gap=ui_timer["gap"], refine_ticks=ui_timer["ticks"],
                         refine_gaps=sorted(ui_timer["gaps"], reverse=True),
                         refine_seconds=time.perf_counter() - state["gap_start"],
                         longest_ui_call=viewport.last_draw["longest_ui_call"])
            bpy.ops.screen.screenshot(filepath=options["--out"])
            # Blender's own cost of redrawing this view (software GL under Xvfb, on a shared machine), with nothing
            # rendering: the view redrawn at every tick for REDRAW_BASELINE_SECONDS.
            state.update(phase="redraw baseline", baseline_end=time.perf_counter() + REDRAW_BASELINE_SECONDS)
            ui_timer.update(measuring=True, last=None, gap=0.0, gaps=[], ticks=0)
            return 0.01
        if state["phase"] == "redraw baseline":
            if time.perf_counter() < state["baseline_end"]:
                view3d()[0].tag_redraw()
                return 0.01
            ui_timer["measuring"] = False
            baseline = ui_timer["gap"]
            print(f"VIEWPORT: refined to {viewport.last_draw['samples']} samples in {state['refine_seconds']:.2f} s; "
                  f"longest UI timer gap (less run-queue delay) meanwhile {1000 * state['refine_gap']:.1f} ms over "
                  f"{state['refine_ticks']} ticks; longest view_draw/view_update {1000 * state['longest_ui_call']:.1f} "
                  f"ms; Blender's redraw of the view with nothing rendering: longest gap {1000 * baseline:.1f} ms over "
                  f"{ui_timer['ticks']} ticks", flush=True)
            # A sample pass on the UI thread would hold it at least one pass; drawing the newest image (a texture
            # upload, software GL here) swings with the machine's load (several times longer beside another test),
            # so the bound is the larger of MAX_UI_GAP_SECONDS and half a pass as measured in this run.
            seconds_per_pass = state["refine_seconds"] / max(1, viewport.last_draw["samples"])
            max_ui_call = max(MAX_UI_GAP_SECONDS, 0.5 * seconds_per_pass)
            if state["longest_ui_call"] >= max_ui_call:
                fail(f"the engine kept the UI thread {1000 * state['longest_ui_call']:.0f} ms in one call (bound "
                     f"{1000 * max_ui_call:.0f} ms: half a sample pass, {1000 * seconds_per_pass:.0f} ms here)")
            # The render shares the cores with Blender's drawing (software GL here), so a redraw while it refines
            # may take longer than a plain one even net of run-queue delays (memory bandwidth, shared caches); a
            # sample on the UI thread (the old viewport) made a gap of at least a pass at every pass. Bound: twice a
            # plain redraw + 100 ms, or half a sample pass where that is longer (as for the UI calls above).
            gap_bound = max(MAX_UI_GAP_SECONDS + 2 * baseline, 0.5 * seconds_per_pass)
            print(f"VIEWPORT: the longest UI timer gaps while refining, less run-queue delays: "
                  + ", ".join(f"{1000 * gap:.0f} ms" for gap in state["refine_gaps"][:3])
                  + f" (bound {1000 * gap_bound:.0f} ms)", flush=True)
            if state["refine_gap"] >= gap_bound:
                fail(f"the UI timer waited {1000 * state['refine_gap']:.0f} ms (less run-queue delays) while the "
                     f"viewport refined: more than {1000 * gap_bound:.0f} ms (twice a plain redraw, "
                     f"{1000 * baseline:.0f} ms, + {1000 * MAX_UI_GAP_SECONDS:.0f} ms, or half a pass, "
                     f"{500 * seconds_per_pass:.0f} ms)")
            expected = EXPECTED_SPLATS.get(scene_file)
            if expected and viewport.last_draw["splats"] != expected:
                fail(f"the viewport drew {viewport.last_draw['splats']} splats, expected {expected}")
            edit("move")
            return 0.1
        if state["phase"] == "final render":
            return check_final_render()
        if state["phase"] == "select":
            # The selection drawn and the view refined again (or 5 s passed) before the move.
            draw = viewport.last_draw
            if (draw["draws"] <= state["draws"] or draw["samples"] < 8) and \
                    time.perf_counter() - state["selected_at"] < 5.0:
                return 0.1
            edit("edit-mode vertices")
            return 0.1
        if not check_updated():
            return 0.1
        first_image = state.pop("first_image")
        print(f"VIEWPORT: '{state['phase']}' updated in place; first image {first_image:.3f} s after the edit"
              + (f" (the operator itself {state['operator_seconds']:.3f} s, {state['edit_mode_objects']} objects in "
                 "Edit Mode)" if "operator_seconds" in state else ""), flush=True)
        if state["phase"] == "edit-mode vertices" and (not edit_mode_reads or set(edit_mode_reads) != {"read"}):
            fail(f"moving {EDITED_FACES} splats in Edit Mode was not read in place from the BMesh: "
                 f"read_edit_mode_positions returned {edit_mode_reads}")
        if state["phase"] == "move":
            edit("object-mode vertices")
            return 0.1
        if state["phase"] == "object-mode vertices":
            select_in_edit_mode()
            return 0.1
        return start_final_render()
    except Exception:
        traceback.print_exc()
        fail("exception")


bpy.app.timers.register(step, first_interval=1.0)
bpy.app.timers.register(ui_tick, first_interval=1.0)
