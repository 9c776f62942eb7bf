# Where the memory of an import goes: Blender's resident memory empty (add-on registered, core loaded), its
# peak during an import with the default settings and after the depsgraph has evaluated the object (the evaluated
# copy), the bytes per Gaussian above the empty Blender, every layer of the imported mesh (vertices, edges, corners,
# faces, each attribute), and the .blend's size (saved uncompressed, Blender's default) against the splat file's.
#   blender -b --factory-startup --python examples/benchmark_import_memory.py -- [FILE] [--k K] [--max-count N]
#   ~/.cache/raysplats/bpy45-venv/bin/python examples/benchmark_import_memory.py -- [FILE]     (PyPI bpy)
# FILE defaults to showroom_1.5M.ply. Targets: at most 700 bytes per Gaussian above the empty Blender, .blend at most
# 5x the .ply.
import argparse
import os
import sys
import tempfile
import time

import bpy

HERE = os.path.dirname(os.path.abspath(__file__))
argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
parser = argparse.ArgumentParser()
parser.add_argument("file", nargs="?", default=os.path.join(HERE, "..", "..", "shared", "data", "showroom_1.5M.ply"))
parser.add_argument("--k", type=int, default=None, help="Polygon Vertices (default: the operator's default)")
parser.add_argument("--max-count", type=int, default=0)
parser.add_argument("--work", default=tempfile.gettempdir(), help="folder for the .blend")
parser.add_argument("--addon-dir", default=os.path.join(HERE, "..", "addon"),
                    help="the folder holding the raysplats package (default: this repository's)")
args = parser.parse_args(argv)

sys.path.insert(0, args.addon_dir)
import raysplats  # noqa: E402

raysplats.register()
from raysplats.blender import mesh_memory
from raysplats.objects import polygon_mesh
from raysplats import native  # noqa: E402

native.core()  # the core's libraries count as the empty Blender


def mb(n):
    return f"{n / 1e6:8.1f} MB"


context = bpy.context
empty = mesh_memory.process_memory_bytes("VmRSS")
peak_reset = mesh_memory.reset_peak_memory()
t = time.perf_counter()
options = {"filepath": args.file, "max_count": args.max_count}
if args.k is not None:
    options["vertices_per_polygon"] = args.k
bpy.ops.import_scene.gaussian_splats(**options)
seconds = time.perf_counter() - t
import_peak = mesh_memory.process_memory_bytes("VmHWM")
after_import = mesh_memory.process_memory_bytes("VmRSS")
obj = context.view_layer.objects.active
pieces = polygon_mesh.scene_pieces(obj.parent or obj)  # (a big scene is imported in pieces)
count = sum(len(piece.data.polygons) for piece in pieces)
context.view_layer.update()
context.evaluated_depsgraph_get()
evaluated_peak = mesh_memory.process_memory_bytes("VmHWM")
after_evaluation = mesh_memory.process_memory_bytes("VmRSS")

blend = os.path.join(args.work, "raysplats_import_memory.blend")
bpy.ops.wm.save_as_mainfile(filepath=blend, compress=False, copy=True)
blend_size, ply_size = os.path.getsize(blend), os.path.getsize(args.file)
os.remove(blend)

print(f"\nRaySplats import memory: {os.path.basename(args.file)}, {count:,} Gaussians as "
      f"{obj.raysplats.vertices_per_polygon}-gons, Blender {bpy.app.version_string} "
      f"({bpy.app.binary_path or 'PyPI bpy'}), import {seconds:.1f} s")
if not peak_reset:
    print("  (VmHWM could not be reset: the peaks below are the process's since it started)")
print(f"  empty Blender (add-on, core)  {mb(empty)}")
print(f"  peak during import            {mb(import_peak)}   {(import_peak - empty) / count:7.0f} B/Gaussian "
      "above empty")
print(f"  after import                  {mb(after_import)}   {(after_import - empty) / count:7.0f} B/Gaussian")
print(f"  peak with the evaluated copy  {mb(evaluated_peak)}   {(evaluated_peak - empty) / count:7.0f} B/Gaussian")
print(f"  after evaluation              {mb(after_evaluation)}   {(after_evaluation - empty) / count:7.0f} B/Gaussian")
sizes = {}
for piece in pieces:
    for name, (domain, size) in mesh_memory.layer_sizes(piece.data).items():
        sizes[name] = (domain, sizes.get(name, (domain, 0))[1] + size)
total = sum(size for _, size in sizes.values())
vertices, edges, corners = (sum(len(getattr(piece.data, key)) for piece in pieces)
                            for key in ("vertices", "edges", "loops"))
print(f"  mesh layers ({vertices:,} vertices, {edges:,} edges, {corners:,} corners, {count:,} faces, "
      f"{len(pieces)} object(s)):")
for name, (domain, size) in sorted(sizes.items(), key=lambda item: -item[1][1]):
    print(f"    {name:<22} {domain:<7} {mb(size)}   {size / count:6.1f} B/Gaussian")
print(f"    {'total':<22} {'':<7} {mb(total)}   {total / count:6.1f} B/Gaussian")
print(f"  .blend {mb(blend_size)} / .ply {mb(ply_size)} = {blend_size / ply_size:.2f}x")
print(f"  targets: <= 700 B/Gaussian above empty (peak during import: {(import_peak - empty) / count:.0f}), "
      f".blend <= 5x the .ply ({blend_size / ply_size:.2f}x)", flush=True)
raysplats.unregister()
if not os.path.basename(bpy.app.binary_path).startswith("blender"):
    # Blender as a Python module (PyPI bpy) can hang in its exit handlers after a big scene; nothing is left to do.
    sys.stdout.flush()
    os._exit(0)
