# Shared helpers of the farm tests that run inside Blender (through blender_tests/run_blender_test.py): a small
# animated RaySplats shot, a headless worker render in another process, and image comparison.
import os
import subprocess
import sys

import bpy
import numpy as np
from mathutils import Vector

HERE = os.path.dirname(os.path.abspath(__file__))
FARM = os.path.dirname(HERE)
REPO = os.path.dirname(FARM)
sys.path.insert(0, os.path.join(REPO, "blender_tests"))
import splat_testing as st  # noqa: E402

ADDON_DIR = os.path.join(REPO, "addon")
SCENE = "small_sh3_inria.ply"  # 9,080 real Gaussians with SH degree 3: quick to import and render
# Blender binary (Debian's 3.4) or Blender as a Python module (an official build from PyPI): a worker process of
# the same Blender is `blender -b ... --python script -- args` or `python script args`.
AS_MODULE = not bpy.app.binary_path or os.path.basename(bpy.app.binary_path).startswith("python")


def build_shot(blend_path, splat_path=None, frames=(1, 6), width=64, height=36, samples=2, blender_import=False,
               **import_options):
    """A turntable of a real splat scene: the camera circles it from frames[0] to frames[1] (30 degrees), RaySplats
    at width x height with `samples` samples, Animate Seed on, a transparent film, PNG output; saved to blend_path.
    Returns the imported object (an empty with pieces, a polygon object or a compact object, by import_options; with
    blender_import, the Gaussian-splat point cloud Blender's own PLY importer makes, 5.3+)."""
    st.reset_render_scene(width, height, samples)
    scene = bpy.context.scene
    if blender_import:
        bpy.ops.wm.ply_import(filepath=splat_path or st.data_file(SCENE))
        obj = bpy.context.view_layer.objects.active
    else:
        from raysplats.io import import_splats
        obj, _, _ = import_splats.import_gaussian_splats(bpy.context, splat_path or st.data_file(SCENE),
                                                         **import_options)
    meshes = [o for o in scene.objects if o.type in {"MESH", "POINTCLOUD"}]
    corners = [o.matrix_world @ Vector(corner) for o in meshes for corner in o.bound_box]
    centre = sum(corners, Vector()) / len(corners)
    radius = max((corner - centre).length for corner in corners)
    pivot = bpy.data.objects.new("turntable", None)
    pivot.location = centre
    scene.collection.objects.link(pivot)
    camera = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
    scene.collection.objects.link(camera)
    camera.parent = pivot
    camera.location = Vector((0.0, -1.6 * radius, 0.5 * radius))
    camera.rotation_euler = (-camera.location).to_track_quat("-Z", "Y").to_euler()
    camera.data.clip_end = 10 * radius
    scene.camera = camera
    scene.frame_start, scene.frame_end = frames
    for frame, angle in ((frames[0], 0.0), (frames[1], np.radians(30.0))):
        pivot.rotation_euler = (0.0, 0.0, angle)
        pivot.keyframe_insert("rotation_euler", frame=frame)
    scene.frame_set(frames[0])
    scene.raysplats.use_animated_seed = True
    scene.render.film_transparent = True
    scene.view_settings.view_transform = "Standard"
    scene.render.image_settings.file_format = "PNG"
    scene.render.image_settings.color_mode = "RGBA"
    os.makedirs(os.path.dirname(blend_path), exist_ok=True)
    bpy.ops.wm.save_as_mainfile(filepath=blend_path, compress=False)
    return obj


def worker_command(blend, output, frames, threads=0):
    """The command line of a worker rendering `frames` (first, last) of `blend` to `output` (Blender's path with #)
    with the add-on of this source tree (farm/tests/render_worker.py)."""
    script = os.path.join(HERE, "render_worker.py")
    args = ["--addon-dir", ADDON_DIR, "--blend", blend, "--output", output, "--frames", str(frames[0]),
            str(frames[1]), "--threads", str(threads)]
    if AS_MODULE:
        return [sys.executable, script] + args
    return [bpy.app.binary_path, "-b", "-noaudio", "--factory-startup", "--python-exit-code", "1", "--python", script,
            "--"] + args


def run(command, **options):
    """Runs a command; raises with its output when it fails."""
    result = subprocess.run(command, capture_output=True, text=True, timeout=600, **options)
    if result.returncode != 0:
        raise AssertionError(f"{' '.join(command)} failed ({result.returncode}):\n{result.stdout}\n{result.stderr}")
    return result


def frame_path(pattern, frame):
    """Blender's file name for `frame` of an output path with #### (PNG)."""
    return pattern.replace("####", f"{frame:04d}") + ".png"


def load_pixels(path):
    return st.load_image(path)
