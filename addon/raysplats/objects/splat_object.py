# What a splat object is, whatever its kind: the one interface the render sync, both exporters, the panels and the
# tools ask, so that none of them branches on how the Gaussians are held.
# - POLYGONS: our polygon Gaussian object, one polygon per Gaussian (polygon_mesh.py); pieces of a split scene too.
# - POINTS: compact points, one point per Gaussian in Blender 5.3's splat layout (compact_points.py,
#   blender_splats.py): ours, or the splat point clouds Blender's own importers make.
# The up axis of the file an object's coordinates follow is stored one way for both kinds, as Object.raysplats.up_axis.
import numpy as np

from .. import native
from . import axes, blender_splats, compact_points, modifier_checks, polygon_mesh

POLYGONS = "POLYGONS"
POINTS = "POINTS"

# Files saved before the up axis of point objects moved into Object.raysplats kept it in this custom property.
_LEGACY_POINTS_UP_AXIS = "raysplats_up_axis"


def kind_of(obj):
    """POLYGONS, POINTS, or None for an object that holds no Gaussians (or None)."""
    if polygon_mesh.is_gaussian_object(obj):
        return POLYGONS
    if blender_splats.is_blender_splat_object(obj):
        return POINTS
    return None


def is_splat_object(obj):
    return kind_of(obj) is not None


def up_axis_of(obj):
    """The up axis of the file the object's coordinates follow (export undoes it). A point object the add-on did not
    make has its importer's axes as object space: blender_splats.BLENDER_MADE_UP_AXIS, never a guess."""
    settings = obj.raysplats
    if kind_of(obj) == POLYGONS or settings.is_property_set("up_axis"):
        return settings.up_axis
    legacy = obj.get(_LEGACY_POINTS_UP_AXIS)
    return legacy if legacy in {item[0] for item in axes.UP_AXIS_ITEMS} else blender_splats.BLENDER_MADE_UP_AXIS


def set_up_axis(obj, up_axis):
    obj.raysplats.up_axis = up_axis


def shown_count(obj):
    """The Gaussians the object renders and exports (a point object's points out in a region or removed left out)."""
    kind = kind_of(obj)
    if kind == POLYGONS:
        return len(obj.data.polygons)
    return compact_points.gaussian_count(obj.data) if kind == POINTS else 0


def gaussians_of(obj, depsgraph, matrix=None, apply_modifiers=True):
    """The object's Gaussians as the depsgraph evaluated it (modifiers, when `apply_modifiers`, and Edit Mode edits
    included), mapped exactly by the 4x4 `matrix` from object space (None: object space), as the core's cloud dict
    with "stats", the polygon recovery's counters ({} for points)."""
    matrix = np.eye(4) if matrix is None else matrix
    if kind_of(obj) == POLYGONS:
        return polygon_mesh.recover_object_gaussians(native.core(), obj, depsgraph, matrix, apply_modifiers)
    cloud = compact_points.evaluated_cloud(obj, depsgraph, apply_modifiers)
    if cloud is None:
        return dict(compact_points.empty_cloud(0), stats={})
    part = compact_points.transformed_cloud(cloud, matrix)
    part["stats"] = {}
    return part


def fidelity_warnings(obj, for_render, modifiers=True):
    """Everything that keeps the object from rendering and exporting exactly as imported and edited, one message
    each: modifiers that change a polygon object's faces or move only a point object's centres (enabled in renders,
    `for_render`, or in the viewport; none when `modifiers` is False: an export without them), and Blender's own
    Apply Transform under a non-uniform map."""
    kind = kind_of(obj)
    if kind is None:
        return []
    messages = []
    if modifiers:
        messages += (modifier_checks.topology_warnings(obj, for_render) if kind == POLYGONS
                     else modifier_checks.compact_warnings(obj, for_render))
    return messages + modifier_checks.corner_only_apply_warnings(obj)


def export_warnings(objects, apply_modifiers):
    """fidelity_warnings() of the splat objects an export writes (the viewport's modifiers, when it applies them)."""
    return [message for obj in objects for message in fidelity_warnings(obj, False, apply_modifiers)]
