# Compact splat objects (issue 17): a whole scene as one point per Gaussian carrying its attributes, in Blender 5.3's
# own splat layout (native_splats.py: a Gaussian-splat point cloud where Blender has one, else mesh vertices), for
# scenes too big to hold as editable polygons. About 56 bytes per Gaussian in Blender (degree 0) against ~1 KB as
# octagons.
# - Rendering (engine/sync.py) and export (io_export.py) read the points' attributes and map each Gaussian by the
#   object's transform exactly (core transform_gaussians: centre, covariance A Σ Aᵀ, SH turned by the rotation).
# - Modifiers, shape keys and armatures that move points move the centres only: a Gaussian keeps its shape and
#   orientation (in object space), as Blender's own splats do. Scaling or bending a compact object through a modifier
#   does not stretch its Gaussians; edit such a region as polygons instead.
# - To edit Gaussians as polygons, select a region's points (Edit Mode: box, lasso, ...) and run Edit Selected as
#   Polygons: those Gaussians move into a new polygon object in the same place, editable with every Blender tool;
#   Merge Polygons Back returns them (with their edits) to the compact object.
import bpy
import numpy as np

from . import errors, gaussian_mesh, native, native_splats
from .io_import import add_gaussian_object, link_as_only_selected, remove_gaussian_object

# On a region's polygon object: the name of the compact object it was taken from (where Merge Back returns it).
REGION_OF_PROPERTY = "raysplats_region_of"
CLOUD_KEYS = ("positions", "rotations", "scales", "opacities", "sh")


def is_compact_object(obj):
    """A splat object of points (ours, or Blender 5.3's own splats)."""
    return native_splats.is_native_splat_object(obj)


def point_count(data):
    return len(data.points) if hasattr(data, "points") else len(data.vertices)


def add_compact_object(context, name, cloud, up_axis, source_file=""):
    """A new compact splat object holding `cloud` (the core's dict) in object space, in the active collection,
    selected and active; its transform is left as identity for the caller. A failure leaves nothing behind."""
    data = native_splats.new_native_splat_data(name, cloud)
    obj = None
    try:
        obj = bpy.data.objects.new(name, data)
        obj[native_splats.UP_AXIS_PROPERTY] = up_axis
        obj.raysplats.source_file = source_file
        if not hasattr(data, "points"):
            # Blender draws a mesh's loose vertices only in Edit Mode: the bounds show where the scene is in Solid
            # view (Rendered view shows the splats; Edit Mode shows every point, to select a region).
            obj.display_type = "BOUNDS"
        link_as_only_selected(context, obj)
    except BaseException:
        if obj is not None:
            bpy.data.objects.remove(obj)
        _remove_data(data)
        raise
    return obj


def _remove_data(data):
    if data is not None and data.users == 0:
        (bpy.data.meshes if isinstance(data, bpy.types.Mesh) else bpy.data.pointclouds).remove(data)


def object_cloud(obj, data=None):
    """The Gaussians of a compact object (its own data, or `data`, e.g. the evaluated one) in object space; None when
    it has no points."""
    data = obj.data if data is None else data
    if point_count(data) == 0:
        return None
    return native_splats.read_native_splats(data)


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


def _take(cloud, rows):
    part = {key: np.ascontiguousarray(cloud[key][rows]) for key in CLOUD_KEYS}
    part["sh_degree"] = cloud["sh_degree"]
    return part


def _concatenate(first, second):
    coeffs = max(first["sh"].shape[1], second["sh"].shape[1])

    def padded(sh):
        out = np.zeros((sh.shape[0], coeffs, 3), dtype=np.float32)
        out[:, :sh.shape[1], :] = sh
        return out

    merged = {key: np.concatenate([first[key], second[key]]) for key in CLOUD_KEYS[:4]}
    merged["sh"] = np.concatenate([padded(first["sh"]), padded(second["sh"])])
    merged["sh_degree"] = int(round(np.sqrt(coeffs))) - 1
    return merged


def empty_cloud(sh_degree):
    coeffs = (sh_degree + 1) ** 2
    return {"positions": np.zeros((0, 3), np.float32), "rotations": np.zeros((0, 4), np.float32),
            "scales": np.zeros((0, 3), np.float32), "opacities": np.zeros(0, np.float32),
            "sh": np.zeros((0, coeffs, 3), np.float32), "sh_degree": sh_degree}


def _replace_points(obj, cloud):
    """Gives `obj` new point data holding `cloud` (the old data goes when nothing else uses it)."""
    old = obj.data
    obj.data = native_splats.new_native_splat_data(old.name, cloud)
    _remove_data(old)


def selected_points(data):
    """Boolean mask of the selected points (Edit Mode's vertex selection, or a point cloud's selection)."""
    count = point_count(data)
    mask = np.zeros(count, dtype=bool)
    if hasattr(data, "vertices"):
        data.vertices.foreach_get("select", mask)
    else:
        attribute = data.attributes.get(".selection")
        if attribute is not None:
            attribute.data.foreach_get("value", mask)
    return mask


def edit_region_as_polygons(context, obj, mask=None, vertices_per_polygon=8, radius=3.0):
    """Moves the Gaussians of compact object `obj` selected by `mask` (default: its selected points) into a new
    polygon object in the same place, named after it and remembering it (REGION_OF_PROPERTY). Returns
    (region object, warnings)."""
    if obj.mode == "EDIT":
        bpy.ops.object.mode_set(mode="OBJECT")
    data = obj.data
    if data.users > 1:
        raise ValueError(f"'{obj.name}': its data '{data.name}' is shared by {data.users} objects; make it single "
                         "user first (Object > Relations > Make Single User)")
    mask = selected_points(data) if mask is None else np.asarray(mask, dtype=bool)
    if not mask.any():
        raise ValueError(f"'{obj.name}': no splats selected; select the region to edit in Edit Mode (its points) "
                         "first")
    cloud = object_cloud(obj)
    region_cloud = _take(cloud, mask)
    rest = _take(cloud, ~mask)
    del cloud
    up_axis = obj.get(native_splats.UP_AXIS_PROPERTY, "-Y")
    region, warnings = add_gaussian_object(context, f"{obj.name} region", region_cloud, vertices_per_polygon, radius,
                                           up_axis, obj.raysplats.source_file)
    try:
        _copy_placement(obj, region)
        region[REGION_OF_PROPERTY] = obj.name
        _replace_points(obj, rest)
    except BaseException:
        remove_gaussian_object(region)
        raise
    return region, warnings


# The transform channels an object's placement is evaluated from. Copied one by one: assigning matrix_world instead
# decomposes it, and the depsgraph's recomposition then differs from the source's matrix in the last bits.
_PLACEMENT_CHANNELS = ("rotation_mode", "location", "rotation_euler", "rotation_quaternion", "rotation_axis_angle",
                       "scale", "delta_location", "delta_rotation_euler", "delta_rotation_quaternion", "delta_scale")


def _copy_placement(source, target):
    target.parent = source.parent
    target.matrix_parent_inverse = source.matrix_parent_inverse.copy()
    for channel in _PLACEMENT_CHANNELS:
        value = getattr(source, channel)
        setattr(target, channel, value if isinstance(value, str) else tuple(value))


def region_target(region):
    """The compact object a region's polygon object was taken from, or None."""
    target = bpy.data.objects.get(region.get(REGION_OF_PROPERTY, ""))
    return target if is_compact_object(target) else None


def merge_region_back(context, region, target=None):
    """Returns the Gaussians of polygon object `region` (with every edit, modifiers applied) to compact object
    `target` (default: the one it was taken from), exactly where they are seen now, and removes `region`. Returns
    how many Gaussians were merged."""
    target = target or region_target(region)
    if target is None:
        raise ValueError(f"'{region.name}': the compact splat object it was taken from "
                         f"('{region.get(REGION_OF_PROPERTY, '')}') is gone; select a compact splat object too")
    if target.data.users > 1:
        raise ValueError(f"'{target.name}': its data is shared by {target.data.users} objects; make it single user "
                         "first (Object > Relations > Make Single User)")
    if region.mode == "EDIT" or target.mode == "EDIT":
        bpy.ops.object.mode_set(mode="OBJECT")
    depsgraph = context.evaluated_depsgraph_get()
    target_matrix = np.array(target.matrix_world, dtype=np.float64)
    region_matrix = np.array(region.matrix_world, dtype=np.float64)
    # The same placement (to Blender's float precision) maps by the exact identity: the unedited polygons then give
    # back their stored Gaussians bit for bit (an inverse of Blender's float matrix would not be exact).
    same_place = np.allclose(region_matrix, target_matrix, rtol=0.0,
                             atol=4 * np.finfo(np.float32).eps * max(1.0, float(np.abs(target_matrix).max())))
    region_to_target = np.eye(4) if same_place else np.linalg.inv(target_matrix) @ region_matrix
    part = gaussian_mesh.recover_object_gaussians(native.core(), region, depsgraph, region_to_target)
    current = object_cloud(target) or empty_cloud(part["sh_degree"])
    _replace_points(target, _concatenate(current, part))
    mesh = region.data
    bpy.data.objects.remove(region)
    if mesh.users == 0:
        bpy.data.meshes.remove(mesh)
    return len(part["opacities"])


class OBJECT_OT_raysplats_edit_region(bpy.types.Operator):
    """Move the selected splats of a compact splat object into a new polygon object, editable with every Blender
    tool (Merge Polygons Back returns them)"""

    bl_idname = "object.raysplats_edit_region"
    bl_label = "Edit Selected as Polygons"
    bl_options = {"REGISTER", "UNDO"}

    vertices_per_polygon: bpy.props.IntProperty(
        name="Polygon Vertices", default=8, min=3, max=64,
        description="Vertices of the polygon each Gaussian becomes (more: smoother outline, heavier mesh)")
    radius: bpy.props.FloatProperty(
        name="Polygon Radius", default=3.0, min=0.5, max=6.0,
        description="Mahalanobis radius of the polygons: 3 covers the Gaussian's 3-sigma support")

    @classmethod
    def poll(cls, context):
        return is_compact_object(context.active_object)

    @errors.reports_failures("Edit region failed: ")
    def execute(self, context):
        obj = context.active_object
        region, warnings = edit_region_as_polygons(context, obj, None, self.vertices_per_polygon, self.radius)
        for warning in warnings:
            self.report({"WARNING"}, warning)
        self.report({"INFO"}, f"{len(region.data.polygons):,} Gaussians of '{obj.name}' are now polygons in "
                              f"'{region.name}'")
        return {"FINISHED"}


class OBJECT_OT_raysplats_merge_region(bpy.types.Operator):
    """Return the Gaussians of this polygon object, with their edits, to the compact splat object they were taken
    from (or the selected compact splat object), and remove it"""

    bl_idname = "object.raysplats_merge_region"
    bl_label = "Merge Polygons Back"
    bl_options = {"REGISTER", "UNDO"}

    @staticmethod
    def _target(context):
        region = context.active_object
        others = [obj for obj in context.selected_objects if obj is not region and is_compact_object(obj)]
        return others[0] if len(others) == 1 else region_target(region)

    @classmethod
    def poll(cls, context):
        return gaussian_mesh.is_gaussian_object(context.active_object) and cls._target(context) is not None

    @errors.reports_failures("Merge failed: ")
    def execute(self, context):
        region, target = context.active_object, self._target(context)
        name = region.name
        count = merge_region_back(context, region, target)
        target.select_set(True)
        context.view_layer.objects.active = target
        self.report({"INFO"}, f"Merged {count:,} Gaussians of '{name}' back into '{target.name}'")
        return {"FINISHED"}


CLASSES = (OBJECT_OT_raysplats_edit_region, OBJECT_OT_raysplats_merge_region)


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)


def unregister():
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
