# The cost of the compositing features on a real scene: biker_v4.spz on a ground plane under a sun, with a blue cube
# moving across the view in front of it, 960 x 540, Blender's F12. For motion blur (shutter 1 frame) and the
# Cryptomatte Object pass, the CPU seconds per sample against the same render without them: (CPU s of a 16-sample F12
# - CPU s of a 4-sample F12) / 12, process time. Then two frames to look at: a 64-sample motion-blurred frame, and the
# matte the compositor's Cryptomatte node extracts for the cube and the biker by name.
#   blender -b --factory-startup --python examples/benchmark_compositing_features.py -- [--out DIR] [--frames-only]
import argparse
import os
import sys
import time

import bpy
import mathutils
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
parser = argparse.ArgumentParser()
parser.add_argument("--data", default=os.path.join(HERE, "..", "..", "shared", "data"))
parser.add_argument("--out", default=os.path.join(os.environ.get("TMPDIR", "/tmp"), "raysplats_compositing"))
parser.add_argument("--frames-only", action="store_true", help="only the two frames, no cost measurement")
args = parser.parse_args(argv)
os.makedirs(args.out, exist_ok=True)
out = args.out

sys.path.insert(0, os.path.join(HERE, "..", "addon"))
import raysplats  # noqa: E402

raysplats.register()
from raysplats.blender import compat  # noqa: E402
from raysplats.engine import final  # noqa: E402

for obj in list(bpy.data.objects):
    bpy.data.objects.remove(obj)
bpy.ops.import_scene.gaussian_splats(filepath=os.path.join(args.data, "biker_v4.spz"))
splats = bpy.context.object
splats.name = "Biker"
centres = np.empty(len(splats.data.polygons) * 3, dtype=np.float32)
splats.data.polygons.foreach_get("center", centres)
world = np.array(splats.matrix_world)
c = centres.reshape(-1, 3) @ world[:3, :3].T + world[:3, 3]
lo, hi = np.percentile(c, 5, axis=0), np.percentile(c, 95, axis=0)
median = np.median(c, axis=0)
size = float(np.max(hi - lo))
bpy.ops.mesh.primitive_plane_add(size=40 * size, location=(median[0], median[1], lo[2]))
plane = bpy.context.object
plane.name = "Ground"
material = bpy.data.materials.new("Ground")
material.use_nodes = True
material.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (0.5, 0.45, 0.4, 1)
plane.data.materials.append(material)
bpy.ops.object.light_add(type="SUN", rotation=(0.6, 0.2, 0.8))
cam_data = bpy.data.cameras.new("Camera")
camera = bpy.data.objects.new("Camera", cam_data)
bpy.context.scene.collection.objects.link(camera)
target = mathutils.Vector(median)
camera.location = target + mathutils.Vector((0.6 * size, -2.6 * size, 0.2 * size))
camera.rotation_euler = (target - camera.location).to_track_quat("-Z", "Y").to_euler()
cam_data.lens = 40.0
scene = bpy.context.scene
scene.camera = camera
scene.render.engine = "RAYSPLATS"
scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 960, 540, 100
scene.raysplats.use_adaptive_sampling = False
scene.view_settings.view_transform = "Standard"
scene.render.image_settings.file_format = "PNG"

# The cube crosses the view in front of the biker: a tenth of the scene's size per frame.
cube_at = target + mathutils.Vector((0.12 * size, -1.6 * size, -0.12 * size))
bpy.ops.mesh.primitive_cube_add(size=0.25 * size, location=tuple(cube_at))
cube = bpy.context.object
cube.name = "Cube"
cube_material = bpy.data.materials.new("Cube")
cube_material.use_nodes = True
cube_material.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (0.1, 0.3, 0.8, 1)
cube.data.materials.append(cube_material)
# Linear keys (5.x's layered actions have no Action.fcurves to change them after).
bpy.context.preferences.edit.keyframe_new_interpolation_type = "LINEAR"
for frame, dx in ((1, -0.05), (2, 0.05)):
    cube.location = cube_at + mathutils.Vector((dx * size, 0, 0))
    cube.keyframe_insert("location", frame=frame)
scene.frame_set(1)
scene.frame_current = 1


def f12(samples, name=None):
    scene.raysplats.samples = samples
    if name:
        scene.render.filepath = f"{out}/{name}.png"
    t0 = time.process_time()
    bpy.ops.render.render(write_still=bool(name))
    return time.process_time() - t0


def per_sample(label):
    if args.frames_only:
        return
    cpu4 = f12(4)
    cpu16 = f12(16)
    print(f"RESULT {label}: 4 spp {cpu4:.2f} CPU s, 16 spp {cpu16:.2f} CPU s -> {(cpu16 - cpu4) / 12:.3f} CPU s per sample;"
          f" notice {final.last_render.get('notice')!r}", flush=True)


f12(1)  # warm-up
per_sample("plain")
scene.render.use_motion_blur = True
scene.render.motion_blur_shutter = 1.0
per_sample("motion blur (shutter 1 frame)")
f12(64, "frame_motion_blur_64spp")
scene.render.use_motion_blur = False
view_layer = scene.view_layers[0]
view_layer.use_pass_cryptomatte_object = True
per_sample("Cryptomatte Object")
# The compositor picks the cube and the biker by name, as a user does with the Cryptomatte node.
tree, output = compat.new_compositor(scene)
layers = tree.nodes.new("CompositorNodeRLayers")
layers.scene = scene
crypto = tree.nodes.new("CompositorNodeCryptomatteV2")
crypto.source = "RENDER"
crypto.scene = scene
crypto.layer_name = f"{view_layer.name}.CryptoObject"
crypto.matte_id = "Cube,Biker"
tree.links.new(layers.outputs["Image"], crypto.inputs["Image"])
tree.links.new(crypto.outputs["Matte"], output)
f12(16, "frame_cryptomatte_matte")
print("frames written to", out)
raysplats.unregister()
