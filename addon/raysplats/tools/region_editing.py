# Editing a region of a compact splat object as polygons, and merging it back in place.
# - Select a region's points (Edit Mode: box, lasso, ...) and run Edit Selected as Polygons: those Gaussians move
#   into a new polygon object in the same place, editable with every Blender tool; Merge Polygons Back returns them
#   (with their edits) to the compact object.
# - A region is taken and returned in place, in time and memory that follow the region, not the scene: its points
#   stay in the compact object, marked as taken (the point attribute REGION_MARK: the region's id), and render, export
#   and the next selection skip them; Merge Back writes the edited Gaussians into those very rows (faces carry their
#   row as REGION_SLOT), puts what the region gained into rows freed earlier or appends it, and marks what it lost as
#   removed (REMOVED_MARK, reused by later merges). The points' values are read and written in place in Blender's
#   arrays (_PointViews), never as a whole cloud. A region object deleted without merging leaves its points taken:
#   the compact object's panel lists it and Restore Regions returns them as they were.
import ctypes
import random

import bpy
import numpy as np

from .. import errors, native
from ..blender import blender_memory, compat
from ..objects import blender_splats, polygon_mesh, splat_object
from ..objects.compact_points import REGION_MARK, REMOVED_MARK, region_marks, selected_points
from ..objects.creation import add_gaussian_object, remove_gaussian_object


# On a region's polygon object: the name of the compact object it was taken from (where Merge Back returns it).
REGION_OF_PROPERTY = "raysplats_region_of"
# On a region's polygon object: the id its points carry in the compact object's REGION_MARK, and how many they are.
REGION_ID_PROPERTY = "raysplats_region_id"
REGION_SIZE_PROPERTY = "raysplats_region_size"
# On a compact object: {str(region id): name of the region object} for each region taken from it and not merged back.
OPEN_REGIONS_PROPERTY = "raysplats_open_regions"
# Face attribute of a region object: 1 + the index (among the region's points, in order) of the point each face was
# made from; 0 for faces that came from elsewhere (joined objects).
REGION_SLOT = "raysplats_region_slot"
# Polygon vertices of a region (Edit Selected as Polygons' default). Blender's Edit Mode entry costs per polygon
# corner (a vertex, an edge and a corner each, with their layers), about 400 bytes a corner, so K = 4 enters in half
# the time and memory of K = 8 (examples/benchmark_big_scene.py; docs/benchmarks.md, Editing big scenes).
REGION_VERTICES_PER_POLYGON = 4


def visible_gaussians(opacities):
    """The Gaussians that get a polygon (the core's gaussians_to_polygons: opacity above 1/255, in double precision,
    as polygon_bridge.cpp's visibility_ratio): the others have nothing to edit and stay where they are."""
    return np.asarray(opacities, dtype=np.float64) / (1.0 / 255.0) > 1.0


class _PointViews:
    """The values of a compact datablock's points where Blender keeps them: one numpy array per attribute that reads
    and writes Blender's own array in place (as_pointer(); through RNA, which first makes a shared array the
    datablock's own, so an undo step or the evaluated copy never sees the writes). Taking and merging a region reads
    and writes its rows only. Where the layout checks fail, full copies through foreach_get instead, written back by
    commit(). Valid while the datablock keeps its point count."""

    def __init__(self, data):
        self.data = data
        self.count = compat.point_count(data)
        self.copies = []  # (attribute or collection, key, array) read through foreach_get: commit() writes them
        if data.attributes.get(REGION_MARK) is None:
            data.attributes.new(REGION_MARK, "INT", "POINT")
        mesh_positions = compat.points_are_vertices(data) and data.attributes.get("position") is None
        if mesh_positions:  # a mesh before 3.5: the positions are the vertices' "co"
            self.positions = self._view(data.vertices, "co", 3, np.float32)
        else:
            self.positions = self._attribute_view(data.attributes["position"])
        self.scales = self._attribute_view(blender_splats.point_attribute(data, (blender_splats.ATTR_SCALE,), (3,)))
        self.rotations = self._attribute_view(blender_splats.point_attribute(data, blender_splats.ROTATION_NAMES,
                                                                             (4,)))
        self.base = self._attribute_view(blender_splats.point_attribute(data, (blender_splats.ATTR_RADIANCE_BASE,),
                                                                         (4,)))
        self.sh_rest = []
        while len(self.sh_rest) < (blender_splats.MAX_SH_DEGREE + 1) ** 2 - 1:
            attribute = blender_splats.point_attribute(data, (blender_splats.sh_rest_name(len(self.sh_rest)),), (3,))
            if attribute is None:
                break
            self.sh_rest.append(self._attribute_view(attribute))
        self.sh_degree = max(d for d in range(blender_splats.MAX_SH_DEGREE + 1)
                             if (d + 1) ** 2 - 1 <= len(self.sh_rest))
        del self.sh_rest[(self.sh_degree + 1) ** 2 - 1:]
        self.marks = self._attribute_view(data.attributes[REGION_MARK])

    def hide(self, rows, hidden):
        """Hides (or reveals) points `rows` in Edit Mode (a mesh's ".hide_vert"; point clouds have no hiding): the
        points out in a region or removed are not shown there."""
        if not compat.points_are_vertices(self.data) or not len(rows):
            return
        attribute = self.data.attributes.get(".hide_vert")
        if attribute is None:
            if not hidden:
                return
            try:
                attribute = self.data.attributes.new(".hide_vert", "BOOLEAN", "POINT")
            except (RuntimeError, TypeError, ValueError):  # a Blender that keeps the flags elsewhere: only cosmetic
                return
        if attribute.data_type != "BOOLEAN" or attribute.domain != "POINT":
            return
        self._attribute_view(attribute)[rows] = hidden

    def _attribute_view(self, attribute):
        width = blender_splats.attribute_width(attribute.data_type) or 1
        dtype = {"INT": np.int32, "BOOLEAN": np.bool_}.get(attribute.data_type, np.float32)
        return self._view(attribute.data, compat.ATTRIBUTE_VALUE_KEY.get(attribute.data_type, "value"),
                          width, dtype)

    def _view(self, elements, key, width, dtype):
        count = self.count
        shape = (count, width) if width > 1 else (count,)
        try:
            view = self._in_place(elements, key, width, dtype) if count > 1 else None
        except Exception:  # the fast path is only an optimisation: foreach_get always reads
            view = None
        if view is not None:
            return view.reshape(shape)
        values = np.empty(count * width, dtype=dtype)
        elements.foreach_get(key, values)
        self.copies.append((elements, key, values))
        return values.reshape(shape)

    def _in_place(self, elements, key, width, dtype):
        count = self.count
        item = np.dtype(dtype).itemsize
        first = elements[0].as_pointer()
        stride = elements[1].as_pointer() - first
        if stride < width * item or stride % item or elements[count - 1].as_pointer() - first != (count - 1) * stride:
            return None
        # Spot checks against RNA, read safely (blender_memory: a wrong address is an error, not a crash) before the
        # view below touches the array; the first and the last element among them, so the view spans checked memory.
        for i in np.linspace(0, count - 1, 8).astype(np.int64):
            value = getattr(elements[int(i)], key)
            expected = np.array(value if width > 1 else [value], dtype=dtype)
            found = np.frombuffer(blender_memory.read(first + int(i) * stride, width * item), dtype=dtype)
            if not np.array_equal(found, expected, equal_nan=dtype == np.float32):
                return None
        size = (count - 1) * stride + width * item
        buffer = (ctypes.c_char * size).from_address(first)
        return np.ndarray((count, width), dtype=dtype, buffer=buffer, strides=(stride, item))

    def gather(self, rows):
        """The Gaussians of points `rows`, as the core's cloud dict."""
        coeffs = (self.sh_degree + 1) ** 2
        sh = np.empty((len(rows), coeffs, 3), dtype=np.float32)
        base = self.base[rows]
        sh[:, 0, :] = base[:, :3]
        for k, view in enumerate(self.sh_rest):
            sh[:, k + 1, :] = view[rows]
        return {"positions": np.ascontiguousarray(self.positions[rows]),
                "rotations": np.ascontiguousarray(self.rotations[rows]),
                "scales": np.ascontiguousarray(self.scales[rows]), "opacities": np.ascontiguousarray(base[:, 3]),
                "sh": sh, "sh_degree": self.sh_degree}

    def scatter(self, rows, cloud, order):
        """Writes Gaussian order[j] of `cloud` into point rows[j] (SH beyond the datablock's degree left out, missing
        coefficients zero)."""
        self.positions[rows] = cloud["positions"][order]
        self.rotations[rows] = cloud["rotations"][order]
        self.scales[rows] = cloud["scales"][order]
        sh = cloud["sh"]
        base = np.empty((len(rows), 4), dtype=np.float32)
        base[:, :3] = sh[order, 0, :]
        base[:, 3] = cloud["opacities"][order]
        self.base[rows] = base
        for k, view in enumerate(self.sh_rest):
            view[rows] = sh[order, k + 1, :] if k + 1 < sh.shape[1] else 0.0

    def commit(self):
        """Writes back what was read as copies, and tells Blender the points changed."""
        for elements, key, values in self.copies:
            elements.foreach_set(key, values)
        compat.tag_points_changed(self.data)


def open_regions(obj):
    """{region id: name of its region object} of the regions taken from compact object `obj` and not merged back."""
    regions = obj.get(OPEN_REGIONS_PROPERTY)
    return {int(key): str(value) for key, value in regions.items()} if regions is not None else {}


def _set_open_regions(obj, regions):
    if regions:
        obj[OPEN_REGIONS_PROPERTY] = {str(key): value for key, value in regions.items()}
    elif OPEN_REGIONS_PROPERTY in obj:
        del obj[OPEN_REGIONS_PROPERTY]


def region_object(obj, region_id):
    """The region object holding region `region_id` of compact object `obj` (in a scene), or None when it is gone."""
    name = open_regions(obj).get(region_id)
    candidates = [bpy.data.objects.get(name)] if name else []
    candidates += [other for other in bpy.data.objects if other.get(REGION_ID_PROPERTY) == region_id]
    for other in candidates:
        if other is not None and other.get(REGION_ID_PROPERTY) == region_id and other.users_scene:
            return other
    return None


def orphaned_regions(obj):
    """The ids of the regions taken from compact object `obj` whose region object is gone (deleted without merging
    back): their Gaussians are out of the compact object until restore_regions()."""
    return [region_id for region_id in open_regions(obj) if region_object(obj, region_id) is None]


def restore_regions(obj, region_ids):
    """Returns the points regions `region_ids` of compact object `obj` hold, as they were taken, to the Gaussians it
    shows (for regions whose object is gone). Returns how many points came back."""
    regions = open_regions(obj)
    marks = region_marks(obj.data)
    restored = 0
    if marks is not None:
        rows = np.flatnonzero(np.isin(marks, np.asarray(list(region_ids), dtype=np.int32)))
        if len(rows):
            views = _PointViews(obj.data)
            views.marks[rows] = 0
            views.hide(rows, False)
            views.commit()
            restored = len(rows)
    for region_id in region_ids:
        regions.pop(region_id, None)
    _set_open_regions(obj, regions)
    return restored


def edit_region_as_polygons(context, obj, mask=None, vertices_per_polygon=REGION_VERTICES_PER_POLYGON, radius=3.0):
    """Moves the Gaussians of compact object `obj` selected by `mask` (default: its selected points) into a new
    polygon object in the same place, named after it and remembering it (REGION_OF_PROPERTY, REGION_ID_PROPERTY).
    The points stay in `obj`, marked as the region's (REGION_MARK), skipped by render and export until Merge Back;
    points already out in a region and invisible Gaussians (which get no polygon) are not taken. Reads and writes the
    region's points only. Returns (region object, warnings)."""
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
    views = _PointViews(data)
    rows = np.flatnonzero(mask & (views.marks == 0))
    rows = rows[visible_gaussians(views.base[rows, 3])]
    if not len(rows):
        raise ValueError(f"'{obj.name}': the selected splats are out in a region already or invisible")
    region_cloud = views.gather(rows)
    regions = open_regions(obj)
    region_id = random.randrange(1, 2 ** 31 - 1)  # unique across compact objects, so that no merge mistakes one
    while region_id in regions:
        region_id = random.randrange(1, 2 ** 31 - 1)
    up_axis = splat_object.up_axis_of(obj)
    region, warnings = add_gaussian_object(context, f"{obj.name} region", region_cloud, vertices_per_polygon, radius,
                                           up_axis, obj.raysplats.source_file)
    del region_cloud
    try:
        if len(region.data.polygons) != len(rows):
            raise errors.InternalError(f"a region of {len(rows)} visible Gaussians became "
                                       f"{len(region.data.polygons)} polygons")
        slot = region.data.attributes.new(REGION_SLOT, "INT", "FACE")
        slot.data.foreach_set("value", np.arange(1, len(rows) + 1, dtype=np.int32))
        _copy_placement(obj, region)
        region[REGION_OF_PROPERTY] = obj.name
        region[REGION_ID_PROPERTY] = region_id
        region[REGION_SIZE_PROPERTY] = len(rows)
        views.marks[rows] = region_id
        views.hide(rows, True)
        views.commit()
        regions[region_id] = region.name
        _set_open_regions(obj, regions)
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
    return target if splat_object.kind_of(target) == splat_object.POINTS else None


def _region_slots(region, depsgraph):
    """REGION_SLOT of each face of the evaluated region object (0 where it has none)."""
    mesh = region.evaluated_get(depsgraph).data
    slots = np.zeros(len(mesh.polygons), dtype=np.int32)
    attribute = mesh.attributes.get(REGION_SLOT)
    if attribute is not None and attribute.domain == "FACE" and attribute.data_type == "INT":
        attribute.data.foreach_get("value", slots)
    return slots


def merge_region_back(context, region, target=None):
    """Returns the Gaussians of polygon object `region` (with every edit, modifiers applied) to compact object
    `target` (default: the one it was taken from), exactly where they are seen now, and removes `region`. Taken from
    `target`, each face goes back into the point it was made from (an unedited region comes back bit for bit); what
    the region gained (duplicated, joined faces) fills points removed earlier or is appended; the points of faces it
    lost are marked removed. Reads and writes the region's points only. Returns how many Gaussians were merged."""
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
    part = polygon_mesh.recover_object_gaussians(native.core(), region, depsgraph, region_to_target)
    slots = _region_slots(region, depsgraph)
    if len(slots) != len(part["opacities"]):
        raise errors.InternalError(f"'{region.name}': {len(part['opacities'])} Gaussians from {len(slots)} faces")
    region_id = region.get(REGION_ID_PROPERTY, 0)
    source = region_target(region)
    if source is not None and source is not target and region_id:
        # Merged into another compact object: the points it was taken from are gone from the source for good.
        _forget_region(source, region_id)
    data = target.data
    views = _PointViews(data)
    rows = np.flatnonzero(views.marks == region_id) if region_id else np.zeros(0, dtype=np.int64)
    if len(rows) != region.get(REGION_SIZE_PROPERTY, -1):
        slots[:] = 0  # the points are not the region's as it was taken (edited meanwhile): append every face
    # Each face whose slot is a point of the region goes back into that point, the first of duplicates only.
    slot = slots.astype(np.int64) - 1
    valid = np.flatnonzero((slot >= 0) & (slot < len(rows)))
    _, first = np.unique(slot[valid], return_index=True)
    in_place = valid[first]
    extra = np.setdiff1d(np.arange(len(slots)), in_place, assume_unique=True)
    written = np.zeros(len(rows), dtype=bool)
    written[slot[in_place]] = True
    lost = rows[~written]
    free = np.concatenate([lost, np.flatnonzero(views.marks == REMOVED_MARK)])
    fill = free[:len(extra)]
    appended = len(extra) - len(fill)
    if appended > 0:
        old_count = views.count
        views.commit()
        compat.add_points(data, appended)
        views = _PointViews(data)
        fill = np.concatenate([fill, np.arange(old_count, old_count + appended)])
    destination = np.concatenate([rows[slot[in_place]], fill]).astype(np.int64)
    order = np.concatenate([in_place, extra]).astype(np.int64)
    if part["sh"].shape[1] > (views.sh_degree + 1) ** 2:
        _raise_sh_degree(data, part["sh_degree"])
        views = _PointViews(data)
    # Faces given back as they were taken leave their points as they are: bit for bit the Gaussians taken (the
    # recovery returns centre, rotation, scale and opacity exactly, the view-dependent colour to float round-off).
    unchanged = _unchanged(views, rows[slot[in_place]], part, in_place)
    keep = np.ones(len(destination), dtype=bool)
    keep[:len(in_place)] = ~unchanged
    views.scatter(destination[keep], part, order[keep])
    views.marks[destination] = 0
    views.marks[free[len(extra):]] = REMOVED_MARK  # lost points no gained Gaussian took
    views.hide(destination, False)
    views.hide(free[len(extra):], True)
    views.commit()
    regions = open_regions(target)
    regions.pop(region_id, None)
    _set_open_regions(target, regions)
    mesh = region.data
    bpy.data.objects.remove(region)
    if mesh.users == 0:
        bpy.data.meshes.remove(mesh)
    # Removing an object leaves the view layer's base of it until the next sync (4.x): code iterating the view
    # layer's objects before then (the next Edit Selected as Polygons) would read the freed object.
    context.view_layer.update()
    return len(part["opacities"])


def _unchanged(views, rows, part, faces):
    """For each point rows[j]: True when Gaussian faces[j] of `part` is its value again, the centre, rotation, scale
    and opacity to the bit, the SH to float round-off (1e-6 of the row's largest
    coefficient)."""
    if not len(rows):
        return np.zeros(0, dtype=bool)
    stored = views.gather(rows)
    same = np.ones(len(rows), dtype=bool)
    for key in ("positions", "rotations", "scales"):
        same &= (stored[key] == part[key][faces]).all(axis=1)
    same &= stored["opacities"] == part["opacities"][faces]
    coeffs = min(stored["sh"].shape[1], part["sh"].shape[1])
    new_sh, old_sh = part["sh"][faces, :coeffs], stored["sh"][:, :coeffs]
    # (SH of degree >= 1 go through the face's frame and back: the round-off follows the row's largest coefficient.)
    scale = np.abs(old_sh).max(axis=(1, 2))[:, None, None]
    same &= (np.abs(new_sh - old_sh) <= 1e-6 * scale).all(axis=(1, 2))
    same &= ~part["sh"][faces, coeffs:].any(axis=(1, 2))
    return same


def _forget_region(obj, region_id):
    """The points region `region_id` of compact object `obj` holds are removed (their Gaussians went elsewhere)."""
    marks = region_marks(obj.data)
    if marks is not None and (marks == region_id).any():
        views = _PointViews(obj.data)
        views.marks[marks == region_id] = REMOVED_MARK
        views.commit()
    regions = open_regions(obj)
    regions.pop(region_id, None)
    _set_open_regions(obj, regions)


def _raise_sh_degree(data, degree):
    """Adds the SH coefficient attributes (zero) a compact datablock lacks up to `degree`."""
    for k in range((degree + 1) ** 2 - 1):
        name = blender_splats.sh_rest_name(k)
        if data.attributes.get(name) is None:
            data.attributes.new(name, "FLOAT_VECTOR", "POINT")


class OBJECT_OT_raysplats_edit_region(bpy.types.Operator):
    """Move the selected splats of a compact splat object into a new polygon object (4 vertices per Gaussian by
    default), editable with every Blender tool; Merge Polygons Back returns them into the same points"""

    bl_idname = "object.raysplats_edit_region"
    bl_label = "Edit Selected as Polygons"
    bl_options = {"REGISTER", "UNDO"}

    vertices_per_polygon: bpy.props.IntProperty(
        name="Polygon Vertices", default=REGION_VERTICES_PER_POLYGON, min=3, max=64,
        description="Vertices of the polygon each Gaussian becomes: 4 (the default) keeps Edit Mode quick on big "
                    "regions (200,000 Gaussians enter it in about a second); more: smoother outline, heavier mesh")
    radius: bpy.props.FloatProperty(
        name="Polygon Radius", default=3.0, min=0.5, max=6.0,
        description="Mahalanobis radius of the polygons: 3 covers the Gaussian's 3-sigma support")

    @classmethod
    def poll(cls, context):
        return splat_object.kind_of(context.active_object) == splat_object.POINTS

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
        others = [obj for obj in context.selected_objects
                  if obj is not region and splat_object.kind_of(obj) == splat_object.POINTS]
        return others[0] if len(others) == 1 else region_target(region)

    @classmethod
    def poll(cls, context):
        return polygon_mesh.is_gaussian_object(context.active_object) and cls._target(context) is not None

    @errors.reports_failures("Merge failed: ")
    def execute(self, context):
        region, target = context.active_object, self._target(context)
        name = region.name
        count = merge_region_back(context, region, target)
        target.select_set(True)
        context.view_layer.objects.active = target
        self.report({"INFO"}, f"Merged {count:,} Gaussians of '{name}' back into '{target.name}'")
        return {"FINISHED"}


class OBJECT_OT_raysplats_restore_regions(bpy.types.Operator):
    """Return the Gaussians of regions whose polygon object was deleted without merging back to this compact splat
    object, as they were when taken"""

    bl_idname = "object.raysplats_restore_regions"
    bl_label = "Restore Deleted Regions"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        obj = context.active_object
        return splat_object.kind_of(obj) == splat_object.POINTS and bool(orphaned_regions(obj))

    @errors.reports_failures("Restore failed: ")
    def execute(self, context):
        obj = context.active_object
        if obj.mode == "EDIT":
            bpy.ops.object.mode_set(mode="OBJECT")
        count = restore_regions(obj, orphaned_regions(obj))
        self.report({"INFO"}, f"Restored {count:,} Gaussians to '{obj.name}'")
        return {"FINISHED"}


CLASSES = (OBJECT_OT_raysplats_edit_region, OBJECT_OT_raysplats_merge_region, OBJECT_OT_raysplats_restore_regions)


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)


def unregister():
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
