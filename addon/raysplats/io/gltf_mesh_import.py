# The meshes of a glTF file whose splats the splat import reads (io/import_splats.py): they go through Blender's own
# glTF importer, and the point-cloud objects it makes of the KHR_gaussian_splatting primitives are removed again (the
# splats are the Gaussian object already; Blender's importer shows them as bare points).
import os
import re

import bpy

from .. import native
from ..blender import compat


class GltfMeshImportFailed(OSError):
    """Blender's glTF importer is not enabled or refused the file's meshes (a file or setup problem: reported to the
    user as such, errors.user_error_types())."""


def _base_name(name):
    """A data-block name without Blender's ".001" suffix."""
    return re.sub(r"\.\d{3}$", "", name)


def import_gltf_meshes(context, filepath):
    """Imports the non-splat meshes of a glTF file with bpy.ops.import_scene.gltf. Returns the objects kept (none
    when the file holds only splats). The importer's objects for meshes that hold only KHR_gaussian_splatting
    primitives (point clouds without edges or faces) are removed, with their meshes."""
    contents = native.core().gltf_contents(filepath)
    if contents["other_primitives"] == 0:
        return []
    compat.prepare_gltf_importer()
    before = set(bpy.data.objects)
    try:
        result = bpy.ops.import_scene.gltf(filepath=filepath)
    except AttributeError as error:  # bpy.ops has no such operator: the add-on is disabled
        raise GltfMeshImportFailed(f"'{filepath}': the file also has meshes, but Blender's glTF importer is not enabled "
                                   "(Preferences > Add-ons > Import-Export: glTF 2.0 format)") from error
    except RuntimeError as error:  # the importer reported an error
        raise GltfMeshImportFailed(f"'{filepath}': Blender's glTF importer could not import the file's meshes: "
                                   f"{error}") from error
    if "FINISHED" not in result:
        raise GltfMeshImportFailed(f"'{filepath}': Blender's glTF importer did not import the file's meshes ({result})")
    new_objects = [obj for obj in bpy.data.objects if obj not in before]
    splat_meshes = set(contents["splat_only_meshes"])
    kept = []
    for obj in new_objects:
        mesh = obj.data if obj.type == "MESH" else None
        if (mesh is not None and len(mesh.polygons) == 0 and len(mesh.edges) == 0
                and _base_name(mesh.name) in splat_meshes):
            bpy.data.objects.remove(obj)
            if mesh.users == 0:
                bpy.data.meshes.remove(mesh)
        else:
            kept.append(obj)
    print(f"RaySplats: {os.path.basename(filepath)}: {len(kept)} object(s) imported by Blender's glTF importer")
    return kept
