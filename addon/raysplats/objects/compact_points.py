# Compact splat objects: a whole scene as one point per Gaussian carrying its attributes, in Blender 5.3's
# own splat layout (blender_splats.py: a Gaussian-splat point cloud where Blender has one, else mesh vertices), for
# scenes too big to hold as editable polygons. About 56 bytes per Gaussian in Blender (degree 0) against ~1 KB as
# octagons.
# - Rendering (engine/sync.py) and export (io/export_splats.py) read the points' attributes and map each Gaussian by
#   the object's transform exactly (core transform_gaussians: centre, covariance A Σ Aᵀ, SH turned by the rotation).
# - Modifiers, shape keys and armatures that move points move the centres only: a Gaussian keeps its shape and
#   orientation (in object space), as Blender's own splats do. Scaling or bending a compact object through a modifier
#   does not stretch its Gaussians; edit such a region as polygons instead (tools/regions.py).
# - Points a region holds (tools/regions.py) stay in the object, marked by the point attribute REGION_MARK, and are
#   skipped by render, export and the next selection until the region is merged back.
import numpy as np

from .. import native
from ..blender import compat
from . import blender_splats


# Point attribute of a compact object: 0 for the points it shows, a region's id for the points that region holds,
# REMOVED_MARK for points a merge removed (skipped everywhere; reused by the next merge that gains Gaussians).
REGION_MARK = "raysplats_region"
REMOVED_MARK = -1
CLOUD_KEYS = ("positions", "rotations", "scales", "opacities", "sh")


def region_marks(data):
    """The REGION_MARK of each point (int32, a copy), or None when no region was ever taken from `data`."""
    attribute = data.attributes.get(REGION_MARK)
    if attribute is None or attribute.data_type != "INT" or attribute.domain != "POINT":
        return None
    marks = np.empty(compat.point_count(data), dtype=np.int32)
    attribute.data.foreach_get("value", marks)
    return marks


def shown_points(data):
    """Boolean mask of the points `data` shows (neither out in a region nor removed), or None for all of them."""
    marks = region_marks(data)
    if marks is None or not marks.any():
        return None
    return marks == 0


def gaussian_count(data):
    """The Gaussians a compact datablock shows (renders, exports): its points less those out in a region or
    removed."""
    shown = shown_points(data)
    return compat.point_count(data) if shown is None else int(shown.sum())


def object_cloud(obj, data=None):
    """The Gaussians a compact object shows (its own data, or `data`, e.g. the evaluated one) in object space: the
    points out in a region or removed left out. None when it shows none."""
    data = obj.data if data is None else data
    if compat.point_count(data) == 0:
        return None
    shown = shown_points(data)
    if shown is not None and not shown.any():
        return None
    cloud = blender_splats.read_blender_splats(data)
    if shown is not None:
        for key in CLOUD_KEYS:
            cloud[key] = np.ascontiguousarray(cloud[key][shown])
    return cloud


def evaluated_cloud(obj, depsgraph, apply_modifiers=True):
    """object_cloud of the object as the depsgraph evaluated it (modifiers moving the centres), Edit Mode included."""
    if obj.mode == "EDIT":
        obj.update_from_editmode()
    return object_cloud(obj, obj.evaluated_get(depsgraph).data if apply_modifiers else obj.data)


def transformed_cloud(cloud, matrix):
    """`cloud` mapped by a 4x4 matrix exactly (the identity: unchanged)."""
    mapped = native.core().transform_gaussians(*(cloud[key] for key in CLOUD_KEYS),
                                               np.ascontiguousarray(matrix, dtype=np.float64))
    return mapped


def bake_matrix_into_points(obj, matrix):
    """Rewrites every point of compact object `obj` as its Gaussian mapped by `matrix` (4x4, any affine map: centre,
    covariance A Σ Aᵀ as rotation and scales, SH turned by the rotation; transformed_cloud), the points out in a
    region too, so that Merge Back (which maps a region by the objects' matrices) still lands them where they are seen. The
    object's transform is left as it is. Returns the number of Gaussians it shows."""
    if obj.mode == "EDIT":
        raise ValueError(f"'{obj.name}' is in Edit Mode; apply transforms in Object Mode")
    data = obj.data
    if data.users > 1:
        raise ValueError(f"'{obj.name}': its data '{data.name}' is shared by {data.users} objects; make it single user "
                         "first (Object > Relations > Make Single User)")
    # Blender's importers also read SH degree 4 (radiance:sh_15 on), which the core does not turn: left as they are,
    # those bands would no longer fit the Gaussians.
    first_unsupported = blender_splats.sh_rest_name((blender_splats.MAX_SH_DEGREE + 1) ** 2 - 1)
    if data.attributes.get(first_unsupported) is not None:
        raise ValueError(f"'{obj.name}' has SH of degree 4 ({first_unsupported}, ...), which RaySplats cannot turn; "
                         "its transform is not applied")
    if compat.point_count(data):
        cloud = blender_splats.read_blender_splats(data)
        blender_splats.write_blender_splats(data, transformed_cloud(cloud, matrix))
    return gaussian_count(data)



def empty_cloud(sh_degree):
    coeffs = (sh_degree + 1) ** 2
    return {"positions": np.zeros((0, 3), np.float32), "rotations": np.zeros((0, 4), np.float32),
            "scales": np.zeros((0, 3), np.float32), "opacities": np.zeros(0, np.float32),
            "sh": np.zeros((0, coeffs, 3), np.float32), "sh_degree": sh_degree}


def selected_points(data):
    """Boolean mask of the selected points (Edit Mode's vertex selection, or a point cloud's selection)."""
    count = compat.point_count(data)
    mask = np.zeros(count, dtype=bool)
    if compat.points_are_vertices(data):
        # The vertex selection is the boolean attribute ".select_vert" (3.4 on), read in bulk; through the vertices'
        # "select" it goes one vertex at a time.
        attribute = data.attributes.get(".select_vert")
        if attribute is not None and attribute.data_type == "BOOLEAN" and attribute.domain == "POINT":
            attribute.data.foreach_get("value", mask)
        else:
            data.vertices.foreach_get("select", mask)
    else:
        # A point cloud keeps its Edit Mode selection in ".selection"; without it every point is selected (Blender's
        # convention for point clouds and curves: the attribute's default is True).
        # (Blender may also store it as a float, 0 to 1, as for curves' soft selection.)
        attribute = data.attributes.get(".selection")
        if attribute is not None and attribute.data_type == "BOOLEAN" and attribute.domain == "POINT":
            attribute.data.foreach_get("value", mask)
        elif attribute is not None and attribute.data_type == "FLOAT" and attribute.domain == "POINT":
            weights = np.empty(count, dtype=np.float32)
            attribute.data.foreach_get("value", weights)
            mask = weights > 0.0
        else:
            mask[:] = True
    return mask
