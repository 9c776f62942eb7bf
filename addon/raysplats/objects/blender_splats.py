# Blender's own Gaussian splats (Blender 5.3) <-> our Gaussian objects: Object > Convert > "Blender Gaussian Splats"
# and "RaySplats Gaussians", so that splats pass between Blender's renderers (which draw its splat point clouds) and
# ours (which edits, exports and ray traces our objects).
#
# The layout, as Blender 5.3's PLY/SPZ/USD importers write it (source/blender/io/common/IO_gsplat.*, ply_import_*):
# one point per Gaussian, in the file's own coordinates (the importers convert no axes: the object's matrix is the
# identity), with these point attributes (in this order, on 5.3.0: position, radiance:base, scale, rotation, sh_k):
#   position        float3      the centre
#   scale           float3      the three standard deviations, LINEAR (the importer applies exp to the PLY's log
#                               scales), as ours are
#   rotation        Quaternion  unit quaternion, w x y z order (Blender's math::Quaternion), as ours
#   radiance:base   float4      r, g, b: the SH DC COEFFICIENT (the PLY's f_dc_0..2 as they are, not a colour),
#                               a: the opacity in 0..1 (the importer applies the sigmoid), as ours
#   radiance:sh_k   float3      SH coefficient k + 1 (k = 0 .. 14 for degree 3) for r, g, b, in the reference 3DGS
#                               basis order (the PLY's f_rest_* regrouped per coefficient), as our sh[:, k + 1, :]
# So no value is converted, only moved. The 5.3 release notes call the rotation attribute "quaternion" in places;
# the importers' code names it "rotation", which is what is written here and read first ("quaternion" is read too).
# Where the running Blender has no splat point cloud (5.2 and older: no PointCloud type; before 5.2 no way to add
# points from Python and no float4 attribute type) the same attributes go on the vertices of a mesh, the four-float
# ones as FLOAT_COLOR where FLOAT4 is missing (compat has these facts).
import bpy
import numpy as np

from .. import errors
from ..blender import compat
from ..blender.mesh_read import read_vertex_positions
from . import polygon_mesh

ATTR_SCALE = "scale"
ATTR_ROTATION = "rotation"
ROTATION_NAMES = (ATTR_ROTATION, "quaternion")
ATTR_RADIANCE_BASE = "radiance:base"
SH_REST_PREFIX = "radiance:sh_"
# The up axis of a splat object Blender made (its PLY/SPZ importers): they keep the file's coordinates as object space
# and put any placement in the object's matrix (identity: as in the file), so the file's axes are the object's and
# export converts nothing ("Z": Blender's own convention).
BLENDER_MADE_UP_AXIS = "Z"
MAX_SH_DEGREE = 3  # what the core supports (the reference 3DGS); Blender's importers also read degree 4


def sh_rest_name(k):
    return f"{SH_REST_PREFIX}{k}"


def point_attribute(data, names, widths):
    """The first point-domain attribute of `data` named in `names` with a value width in `widths`, or None."""
    for name in names:
        attribute = data.attributes.get(name)
        if attribute is not None and attribute.domain == "POINT" and attribute_width(attribute.data_type) in widths:
            return attribute
    return None


def attribute_width(data_type):
    return {"FLOAT": 1, "FLOAT_VECTOR": 3, "FLOAT_COLOR": 4, "QUATERNION": 4, "FLOAT4": 4}.get(data_type)


def _read(attribute, count):
    width = attribute_width(attribute.data_type)
    values = np.empty(count * width, dtype=np.float32)
    attribute.data.foreach_get(compat.ATTRIBUTE_VALUE_KEY[attribute.data_type], values)
    return values.reshape((count, width))


def _write(data, name, data_type, values):
    attribute = data.attributes.new(name, data_type, "POINT")
    attribute.data.foreach_set(compat.ATTRIBUTE_VALUE_KEY[data_type],
                               np.ascontiguousarray(values, dtype=np.float32).ravel())


def is_blender_splat_object(obj):
    """True for a point cloud (or mesh) carrying Blender's splat attributes, other than our own Gaussian objects."""
    if obj is None or obj.type not in {"POINTCLOUD", "MESH"} or polygon_mesh.is_gaussian_object(obj):
        return False
    data = obj.data
    return (point_attribute(data, (ATTR_SCALE,), (3,)) is not None
            and point_attribute(data, ROTATION_NAMES, (4,)) is not None
            and point_attribute(data, (ATTR_RADIANCE_BASE,), (4,)) is not None)


def read_blender_splats(data):
    """The Gaussians of a splat point cloud (or mesh) datablock in its object space, as the core's cloud dict."""
    count = compat.point_count(data)
    if count == 0:
        raise ValueError(f"'{data.name}' has no points")
    if compat.points_are_vertices(data):
        positions = np.empty(count * 3, dtype=np.float32)
        read_vertex_positions(data, positions)
        positions = positions.reshape((count, 3))
    else:
        positions = _read(data.attributes["position"], count)
    missing = [name for name, names, width in ((ATTR_SCALE, (ATTR_SCALE,), 3), (ATTR_ROTATION, ROTATION_NAMES, 4),
                                               (ATTR_RADIANCE_BASE, (ATTR_RADIANCE_BASE,), 4))
               if point_attribute(data, names, (width,)) is None]
    if missing:
        raise ValueError(f"'{data.name}' is not a Gaussian splat point cloud: no point attribute {', '.join(missing)}")
    scales = _read(point_attribute(data, (ATTR_SCALE,), (3,)), count)
    rotations = _read(point_attribute(data, ROTATION_NAMES, (4,)), count)
    base = _read(point_attribute(data, (ATTR_RADIANCE_BASE,), (4,)), count)
    # Degree d has (d + 1)^2 - 1 coefficients beyond the DC term; a band only part there is left out, as Blender's
    # own importer does with an incomplete band.
    rest = 0
    while rest < (MAX_SH_DEGREE + 1) ** 2 - 1 and point_attribute(data, (sh_rest_name(rest),), (3,)) is not None:
        rest += 1
    degree = max(d for d in range(MAX_SH_DEGREE + 1) if (d + 1) ** 2 - 1 <= rest)
    sh = np.empty((count, (degree + 1) ** 2, 3), dtype=np.float32)
    sh[:, 0, :] = base[:, :3]
    for k in range(1, (degree + 1) ** 2):
        sh[:, k, :] = _read(data.attributes[sh_rest_name(k - 1)], count)
    return {"positions": positions, "rotations": rotations, "scales": scales,
            "opacities": np.ascontiguousarray(base[:, 3]), "sh": sh, "sh_degree": degree}


def new_blender_splat_data(name, gaussians):
    """A datablock with the splat layout holding `gaussians` (the core's dict): a Gaussian-splat PointCloud where the
    running Blender has one, else a mesh whose vertices carry the attributes."""
    count = len(gaussians["opacities"])
    if compat.SPLATS_AS_POINT_CLOUD:
        data = bpy.data.pointclouds.new(name)
        data.resize(count)
        data.type = compat.NATIVE_GAUSSIAN_SPLAT_TYPE
        data.attributes["position"].data.foreach_set("vector", np.ascontiguousarray(gaussians["positions"]).ravel())
    else:
        data = bpy.data.meshes.new(name)
        data.vertices.add(count)
        polygon_mesh.write_mesh_array(data, "vertices", "co",
                                       np.ascontiguousarray(gaussians["positions"], dtype=np.float32).ravel())
    # (In the order 5.3's importers add them.)
    sh = gaussians["sh"]
    _write(data, ATTR_RADIANCE_BASE, compat.FLOAT4_ATTRIBUTE_TYPE, _radiance_base(gaussians))
    _write(data, ATTR_SCALE, "FLOAT_VECTOR", gaussians["scales"])
    _write(data, ATTR_ROTATION, compat.QUATERNION_ATTRIBUTE_TYPE, gaussians["rotations"])
    for k in range(1, sh.shape[1]):
        _write(data, sh_rest_name(k - 1), "FLOAT_VECTOR", sh[:, k, :])
    compat.tag_points_changed(data)
    return data


def _radiance_base(gaussians):
    """radiance:base of each Gaussian: its SH DC coefficient (r, g, b) and opacity."""
    base = np.empty((len(gaussians["opacities"]), 4), dtype=np.float32)
    base[:, :3] = gaussians["sh"][:, 0, :]
    base[:, 3] = gaussians["opacities"]
    return base


def write_blender_splats(data, gaussians):
    """Overwrites every point of a splat datablock with `gaussians` (the core's dict, one Gaussian per point, SH of
    the datablock's degree as read_blender_splats gives it), in the attributes it already has."""
    count = compat.point_count(data)
    if len(gaussians["opacities"]) != count:
        raise errors.InternalError(f"'{data.name}': {len(gaussians['opacities'])} Gaussians for {count} points")
    positions = np.ascontiguousarray(gaussians["positions"], dtype=np.float32).ravel()
    if compat.points_are_vertices(data):
        polygon_mesh.write_mesh_array(data, "vertices", "co", positions)
    else:
        data.attributes["position"].data.foreach_set("vector", positions)
    sh = gaussians["sh"]
    for names, width, values in (((ATTR_SCALE,), 3, gaussians["scales"]), (ROTATION_NAMES, 4, gaussians["rotations"]),
                                 ((ATTR_RADIANCE_BASE,), 4, _radiance_base(gaussians)),
                                 *(((sh_rest_name(k - 1),), 3, sh[:, k, :]) for k in range(1, sh.shape[1]))):
        attribute = point_attribute(data, names, (width,))
        attribute.data.foreach_set(compat.ATTRIBUTE_VALUE_KEY[attribute.data_type],
                                   np.ascontiguousarray(values, dtype=np.float32).ravel())
    compat.tag_points_changed(data)
