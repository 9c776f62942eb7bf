# Helpers of the mesh export tests: external checkers (Khronos glTF validator + draco3d through
# scripts/check_gltf.js, assimp), Blender's own importers across 3.x/4.x, and expected values computed
# independently from the splat file.
import json
import os
import re
import shutil
import subprocess

import addon_utils
import bpy
import numpy as np

import splat_testing as st

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CHECK_GLTF = os.path.join(REPO, "scripts", "check_gltf.js")
NPM_DIR = os.environ.get("RAYSPLATS_NPM_DIR", os.path.join(os.path.expanduser("~"), ".cache", "raysplats", "npm"))
RHO = 3.0  # the import's polygon radius


def gltf_tools_missing():
    """A reason to skip, or None when node and the npm tools (scripts/setup_test_tools.sh) are there."""
    if shutil.which("node") is None:
        return "node is not installed (scripts/install_deps.sh installs it)"
    for package in ("gltf-validator", "draco3d"):
        if not os.path.exists(os.path.join(NPM_DIR, "node_modules", package, "package.json")):
            return f"npm package {package} missing in {NPM_DIR}: scripts/setup_test_tools.sh could not install it " \
                   "(npm registry unreachable?)"
    return None


def check_gltf(path):
    """Validator report and Draco decoding of a .gltf/.glb (see scripts/check_gltf.js)."""
    env = dict(os.environ, RAYSPLATS_NPM_DIR=NPM_DIR)
    out = subprocess.run(["node", CHECK_GLTF, path], capture_output=True, text=True, env=env, timeout=600)
    if out.returncode != 0:
        raise AssertionError(f"check_gltf.js failed on {path}: {out.stderr}")
    return json.loads(out.stdout)


def assimp_info(path):
    """(meshes, vertices, faces) as `assimp info -r` reports them (raw: without the post-processing that
    joins identical vertices)."""
    out = subprocess.run(["assimp", "info", path, "-r"], capture_output=True, text=True, timeout=600)
    if out.returncode != 0:
        raise AssertionError(f"assimp info {path} failed: {out.stdout[-2000:]} {out.stderr[-2000:]}")

    def number(label):
        match = re.search(rf"^{label}:\s+(\d+)", out.stdout, re.MULTILINE)
        if match is None:
            raise AssertionError(f"assimp info {path}: no '{label}' line in\n{out.stdout[-3000:]}")
        return int(match.group(1))

    return number("Meshes"), number("Vertices"), number("Faces")


def assimp_mean_color(path, tmp_name):
    """Mean vertex colour (RGBA, as stored in the file: assimp does no colour management) over all meshes,
    from `assimp dump` (assxml)."""
    dump = st.tmp_file(tmp_name)
    out = subprocess.run(["assimp", "dump", path, dump], capture_output=True, text=True, timeout=600)
    if out.returncode != 0:
        raise AssertionError(f"assimp dump {path} failed: {out.stdout[-2000:]} {out.stderr[-2000:]}")
    with open(dump) as f:
        text = f.read()
    os.remove(dump)
    blocks = re.findall(r"<Colors[^>]*>(.*?)</Colors>", text, re.DOTALL)
    if not blocks:
        raise AssertionError(f"assimp found no vertex colours in {path}")
    values = np.concatenate([np.array(block.split(), dtype=np.float64) for block in blocks]).reshape(-1, 4)
    return values.mean(axis=0), len(values)


def enable_addon(module):
    if not addon_utils.check(module)[1]:
        addon_utils.enable(module, default_set=True)


def import_with_blender(path):
    """Imports with Blender's own importer for the extension; returns the new mesh objects."""
    before = set(bpy.data.objects)
    extension = os.path.splitext(path)[1].lower()
    if extension in (".gltf", ".glb"):
        enable_addon("io_scene_gltf2")
        if "bool" not in np.__dict__:
            # Blender 3.4's glTF importer uses np.bool, which numpy 1.24 removed (fixed in Blender 3.5).
            np.bool = bool
        bpy.ops.import_scene.gltf(filepath=path)
    elif extension == ".obj":
        bpy.ops.wm.obj_import(filepath=path)
    elif extension == ".ply":
        if bpy.app.version >= (3, 6, 0):  # the C++ importer; the Python add-on before
            bpy.ops.wm.ply_import(filepath=path)
        else:
            enable_addon("io_mesh_ply")
            bpy.ops.import_mesh.ply(filepath=path)
    return [obj for obj in bpy.data.objects if obj not in before and obj.type == "MESH"]


def blender_has_draco():
    try:
        from io_scene_gltf2.io.com import gltf2_io_draco_compression_extension as draco
        return draco.dll_exists(quiet=True)
    except Exception:
        return False


def mean_vertex_color(mesh):
    """Mean linear RGBA per vertex of a mesh's first colour attribute, or None if it has none."""
    if not len(mesh.color_attributes):
        return None
    attribute = mesh.color_attributes[0]
    values = np.empty(len(attribute.data) * 4, dtype=np.float32)
    attribute.data.foreach_get("color", values)
    values = values.reshape(-1, 4)
    if attribute.domain == "CORNER":
        corner_vertices = np.empty(len(mesh.loops), dtype=np.int32)
        mesh.loops.foreach_get("vertex_index", corner_vertices)
        per_vertex = np.zeros((len(mesh.vertices), 4))
        per_vertex[corner_vertices] = values
        values = per_vertex
    return values.mean(axis=0)


def srgb_to_linear(c):
    c = np.clip(c, 0.0, 1.0)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def visible_radius(alpha):
    """rho_i of docs/design.md §5: where a·exp(-r²/2) falls to 1/255, at most RHO (0 when a <= 1/255)."""
    return np.minimum(RHO, np.sqrt(2.0 * np.log(np.maximum(255.0 * alpha, 1.0))))


def expected_patch_colors(cloud):
    """Per Gaussian: linear RGB of the SH DC colour, and the mean alpha of its K + 1 = 9 patch vertices (the centre
    a, the rim a·exp(-rho_i²/2): 1/255 for a faint Gaussian)."""
    srgb = np.clip(0.5 + st.C0 * cloud["sh"][:, 0, :].astype(np.float64), 0.0, 1.0)
    alpha = np.clip(cloud["opacities"].astype(np.float64), 0, 1)
    rim = alpha * np.exp(-0.5 * visible_radius(alpha) ** 2)
    return srgb, srgb_to_linear(srgb), (alpha + 8 * rim) / 9


def add_red_cube(location=(1.0, 2.0, 3.0)):
    """A cube with a Principled material (base colour, metallic, roughness) at a known place."""
    bpy.ops.mesh.primitive_cube_add(size=2.0, location=location)
    cube = bpy.context.view_layer.objects.active
    material = bpy.data.materials.new("Red Metal")
    material.use_nodes = True
    bsdf = next(node for node in material.node_tree.nodes if node.type == "BSDF_PRINCIPLED")
    bsdf.inputs["Base Color"].default_value = (0.8, 0.1, 0.05, 1.0)
    bsdf.inputs["Metallic"].default_value = 0.25
    bsdf.inputs["Roughness"].default_value = 0.4
    cube.data.materials.append(material)
    return cube


def export_mesh(name, **options):
    path = st.tmp_file(name)
    stem, extension = os.path.splitext(path)
    stale = [path] + ([stem + ".bin"] if extension == ".gltf" else []) + ([stem + ".mtl"] if extension == ".obj" else [])
    for old in stale:
        if os.path.exists(old):
            os.remove(old)
    result = bpy.ops.export_scene.raysplats_mesh(filepath=path, **options)
    assert result == {"FINISHED"}, result
    return path


def gltf_json(path):
    with open(path, "rb") as f:
        data = f.read()
    if data[:4] == b"glTF":
        length = int.from_bytes(data[12:16], "little")
        return json.loads(data[20:20 + length])
    return json.loads(data)
