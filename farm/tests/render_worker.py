# A render-farm worker in the farm tests: opens a .blend, renders frames with RaySplats, exits. The add-on comes from
# --addon-dir (the source tree), so that any Blender can play a worker without an install.
#   blender -b -noaudio --factory-startup --python render_worker.py -- ARGS      (a Blender binary)
#   python render_worker.py ARGS                                               (Blender as a Python module)
# ARGS: --addon-dir DIR --blend FILE --output PATH_WITH_#### --frames FIRST LAST [--threads N]
import argparse
import os
import sys

import bpy


def main():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    parser = argparse.ArgumentParser()
    parser.add_argument("--addon-dir", required=True)
    parser.add_argument("--blend", required=True)
    parser.add_argument("--output", required=True)
    parser.add_argument("--frames", type=int, nargs=2, required=True)
    parser.add_argument("--threads", type=int, default=0, help="render threads (0: Blender's Auto, every core)")
    args = parser.parse_args(argv)
    sys.path.insert(0, os.path.abspath(args.addon_dir))
    import raysplats
    raysplats.register()
    try:
        bpy.ops.wm.open_mainfile(filepath=args.blend, load_ui=False)
        scene = bpy.context.scene
        scene.render.engine = "RAYSPLATS"
        if args.threads:
            scene.render.threads_mode, scene.render.threads = "FIXED", args.threads
        scene.render.filepath = args.output
        scene.frame_start, scene.frame_end = args.frames
        result = bpy.ops.render.render(animation=True)
        if result != {"FINISHED"}:
            raise RuntimeError(f"render: {result}")
    finally:
        raysplats.unregister()  # Blender as a module crashes at exit while add-on classes are registered


main()
