# Benchmark of the Blender side: import (file -> editable mesh), recovery (mesh -> Gaussians, as every
# render and export does) and export (-> .ply), on the 1.5 M-splat scene by default. Prints each stage.
#   blender -b --factory-startup --python examples/benchmark_import_export.py -- [--scene FILE] [--k 8]
import argparse
import os
import sys
import tempfile
import time

import bpy

HERE = os.path.dirname(os.path.abspath(__file__))
argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
parser = argparse.ArgumentParser()
parser.add_argument("--scene", default=os.path.join(HERE, "..", "..", "shared", "data", "showroom_1.5M.ply"))
parser.add_argument("--k", type=int, default=8)
args = parser.parse_args(argv)

sys.path.insert(0, os.path.join(HERE, "..", "addon"))
import raysplats  # noqa: E402

raysplats.register()
from raysplats.io import export_splats, import_splats
from raysplats.objects import polygon_mesh
from raysplats import native  # noqa: E402

context = bpy.context
t = time.perf_counter()
# One object (not Auto's pieces for big scenes): the reading and recovery below are timed on one whole mesh.
obj, _, import_times = import_splats.import_gaussian_splats(context, args.scene, vertices_per_polygon=args.k,
                                                       objects="ONE")
context.view_layer.update()
t_import = time.perf_counter() - t
n = len(obj.data.polygons)

depsgraph = context.evaluated_depsgraph_get()
t = time.perf_counter()
mesh = obj.evaluated_get(depsgraph).data
arrays = polygon_mesh.mesh_arrays(mesh)
attributes = polygon_mesh.face_attributes(mesh, obj.raysplats.sh_degree)
t_read = time.perf_counter() - t
import numpy as np  # noqa: E402

t = time.perf_counter()
native.core().recover_gaussians(*arrays, args.k, 3.0, np.eye(4), **attributes)
t_recover = time.perf_counter() - t
# An edited mesh: every vertex moved, so every face goes through the moments recovery.
attributes_edited = dict(attributes, rest_centers=None, rest_rotations=None, rest_scales=None)
t = time.perf_counter()
native.core().recover_gaussians(*arrays, args.k, 3.0, np.eye(4), **attributes_edited)
t_recover_moments = time.perf_counter() - t

out = os.path.join(tempfile.mkdtemp(), "benchmark.ply")
t = time.perf_counter()
export_splats.export_gaussian_splats(context, out)
t_export = time.perf_counter() - t
os.remove(out)

print(f"\nRaySplats import/export benchmark: {os.path.basename(args.scene)}, {n:,} splats, K = {args.k}")
print(f"  import (ready to edit)             {t_import:7.2f} s   " +
      ", ".join(f"{k} {v:.2f} s" for k, v in import_times.items()))
print(f"  read mesh arrays (foreach_get)      {t_read:7.2f} s")
print(f"  recovery, unedited faces           {t_recover:7.2f} s   {n / t_recover / 1e6:.1f} M splats/s")
print(f"  recovery, all faces by moments     {t_recover_moments:7.2f} s   {n / t_recover_moments / 1e6:.1f} M splats/s")
print(f"  export to .ply (read + recover + write) {t_export:7.2f} s")
