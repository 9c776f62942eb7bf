# GUI test (needs a window; ctest runs it under xvfb-run): the splat tools' interface draws without errors. With a
# splat object imported, Ctrl+A in Object Mode is the add-on's Apply menu (its key map item), and every menu and panel
# of the tools is drawn: the Apply menu, Edit Mode's Select and Mesh menus with their Gaussian Splats submenus, Shift+A,
# and the Object Properties and sidebar panels. ctest fails it on a draw error: a Python traceback or a layout warning
# ("property not found", "unknown operator") in the console.
#   xvfb-run blender --factory-startup --python panels.py -- --addon-dir A --data-dir D
import os
import sys
import traceback
import types

import bpy

argv = sys.argv[sys.argv.index("--") + 1:]
options = dict(zip(argv[::2], argv[1::2]))
sys.path.insert(0, options["--addon-dir"])
import raysplats  # noqa: E402

raysplats.register()
from raysplats.ui import panels  # noqa: E402

MENUS_IN_OBJECT_MODE = ("VIEW3D_MT_raysplats_apply", "VIEW3D_MT_object_apply", "VIEW3D_MT_add")
MENUS_IN_EDIT_MODE = ("VIEW3D_MT_select_edit_mesh", "VIEW3D_MT_edit_mesh", "VIEW3D_MT_raysplats_select",
                      "VIEW3D_MT_raysplats_mesh")
PANELS = (panels.OBJECT_PT_raysplats, panels.OBJECT_PT_raysplats_colors, panels.VIEW3D_PT_raysplats,
          panels.VIEW3D_PT_raysplats_select, panels.VIEW3D_PT_raysplats_clean_up, panels.VIEW3D_PT_raysplats_colors)
drawn = []


def fail(message):
    print(f"SPLAT UI TEST FAILED: {message}")
    sys.stdout.flush()
    os._exit(1)


def draw_panels(menu, context):
    # A popup's layout stands in for each panel's: the panels' draw code runs exactly as in their regions.
    for panel in PANELS:
        if not panel.poll(context):
            fail(f"{panel.__name__} is not shown for a splat object")
        panel.draw(types.SimpleNamespace(layout=menu.layout.column()), context)
        drawn.append(panel.__name__)


def run():
    try:
        bpy.ops.import_scene.gaussian_splats(filepath=os.path.join(options["--data-dir"], "small.splat"))
        items = [item for keymap in bpy.context.window_manager.keyconfigs.addon.keymaps
                 if keymap.name == "Object Mode" for item in keymap.keymap_items
                 if item.idname == "wm.call_menu" and item.type == "A" and item.ctrl]
        if [item.properties.name for item in items] != ["VIEW3D_MT_raysplats_apply"]:
            fail(f"Ctrl+A is not the add-on's Apply menu: {[item.properties.name for item in items]}")
        window = bpy.context.window_manager.windows[0]
        area = next(a for a in window.screen.areas if a.type == "VIEW_3D")
        region = next(r for r in area.regions if r.type == "WINDOW")
        with bpy.context.temp_override(window=window, area=area, region=region):
            for name in MENUS_IN_OBJECT_MODE:
                if bpy.ops.wm.call_menu(name=name) != {"INTERFACE"}:
                    fail(f"menu {name} did not open")
            bpy.context.window_manager.popup_menu(draw_panels, title="panels")
            bpy.ops.object.mode_set(mode="EDIT")
            for name in MENUS_IN_EDIT_MODE:
                if bpy.ops.wm.call_menu(name=name) != {"INTERFACE"}:
                    fail(f"menu {name} did not open")
            bpy.ops.object.mode_set(mode="OBJECT")
    except Exception:
        traceback.print_exc()
        fail("exception")
    bpy.app.timers.register(finish, first_interval=1.0)


def finish():
    if len(drawn) != len(PANELS):
        fail(f"panels drawn: {drawn}")
    print("SPLAT UI TEST PASSED")
    sys.stdout.flush()
    os._exit(0)


bpy.app.timers.register(run, first_interval=1.0)
