# Splat-object upkeep: reducing the SH degree, showing the colour adjustments in the viewport's colour
# attribute, and keeping a joined mesh a splat object (or marking one by hand) with its settings read back from its
# data. Per-Gaussian work runs in the core (color_adjustment.h). Selection is in tools/select_splats.py, the exact Apply
# Transform in tools/exact_apply.py, the handlers that call these on Blender's changes in tools/handlers.py, the panels
# and menus in ui/panels.py.
import math

import bpy
import numpy as np
from bpy.props import IntProperty

from .. import errors, native
from ..objects import color_adjustment, polygon_mesh
from ..objects.object_settings import RaySplatsObjectSettings
from ..blender.mesh_read import read_attribute, read_face_corners
from .select_splats import object_mode_data, target_objects

# A joined object becomes a splat object when more than this fraction of its faces carry splat data.
JOINED_SPLAT_FRACTION = 0.5


def reduce_sh_degree(obj, degree):
    """Drops the SH bands above `degree` of a Gaussian object (their attributes are removed). Returns the degree
    before."""
    settings = obj.raysplats
    before = settings.sh_degree
    if degree >= before:
        return before
    mesh = obj.data
    for k in range((degree + 1) ** 2, (before + 1) ** 2):
        attribute = mesh.attributes.get(polygon_mesh.sh_attribute_name(k))
        if attribute is not None:
            mesh.attributes.remove(attribute)
    settings.sh_degree = degree
    mesh.update()
    return before


class OBJECT_OT_raysplats_reduce_sh_degree(bpy.types.Operator):
    """Drop the view-dependent colour bands above a degree (smaller files and faster renders)"""

    bl_idname = "object.raysplats_reduce_sh_degree"
    bl_label = "Reduce SH Degree"
    bl_options = {"REGISTER", "UNDO"}
    degree: IntProperty(name="Degree", default=0, min=0, max=3, description="The highest SH degree kept")

    @classmethod
    def poll(cls, context):
        return polygon_mesh.is_gaussian_object(context.active_object)

    @errors.reports_failures("Reduce SH degree failed: ")
    def execute(self, context):
        with object_mode_data(context):
            for obj in target_objects(context):
                before = reduce_sh_degree(obj, self.degree)
                self.report({"INFO"}, f"'{obj.name}': SH degree {before} -> {obj.raysplats.sh_degree}")
        return {"FINISHED"}


def refresh_corner_colors(obj):
    """Rewrites the colour attribute the viewport shows (polygon_mesh.ATTR_COLOR) from the stored SH DC and opacity
    with the object's colour adjustments. In Edit Mode the edit mesh would overwrite it on leaving: then nothing is
    written and False returned (the panel greys the adjustments out there)."""
    mesh = getattr(obj, "data", None)
    if obj.type != "MESH" or obj.mode == "EDIT" or len(mesh.polygons) == 0:
        return False
    faces = len(mesh.polygons)
    sh_dc = read_attribute(mesh, polygon_mesh.sh_attribute_name(0), "FLOAT_VECTOR", "FACE", faces)
    if sh_dc is None:
        return False
    opacity = read_attribute(mesh, polygon_mesh.ATTR_OPACITY, "FLOAT", "FACE", faces)
    starts = np.empty(faces, dtype=np.int32)
    counts = np.empty(faces, dtype=np.int32)
    read_face_corners(mesh, sizes=counts, starts=starts)
    rgba8 = native.core().splat_corner_colors(sh_dc.reshape(-1, 3), opacity, starts, counts, len(mesh.loops),
                                              **color_adjustment.adjustment_of(obj.raysplats))
    polygon_mesh.write_corner_colors(mesh, rgba8)
    mesh.update()
    return True


def splat_faces(mesh):
    """Bool per face: the face carries an imported Gaussian (non-zero rest scales), or None without splat data."""
    rest = read_attribute(mesh, polygon_mesh.ATTR_REST_SCALE, "FLOAT_VECTOR", "FACE", len(mesh.polygons))
    return None if rest is None else np.any(rest.reshape(-1, 3) != 0.0, axis=1)


def infer_splat_settings(obj):
    """Reads K, rho and the SH degree of a mesh carrying splat data back from the data itself (for an object marked
    by hand or by a join): K is the commonest corner count of its splat faces, rho the radius of their corner UVs
    (rho cos θ, rho sin θ), the degree the number of stored SH attributes. False when the mesh has no splat data."""
    mesh = obj.data
    carried = splat_faces(mesh) if mesh is not None else None
    if carried is None or not carried.any():
        return False
    settings = obj.raysplats
    counts = np.empty(len(mesh.polygons), dtype=np.int32)
    read_face_corners(mesh, sizes=counts)
    settings.vertices_per_polygon = int(np.bincount(counts[carried]).argmax())
    uv_layer = mesh.uv_layers.get(polygon_mesh.UV_MAP)
    if uv_layer is not None:
        uvs = np.empty(len(mesh.loops) * 2, dtype=np.float32)
        uv_layer.data.foreach_get("uv", uvs)
        corner_of_splat = np.repeat(carried, counts)
        radius = float(np.sqrt((uvs.reshape(-1, 2)[corner_of_splat].astype(np.float64) ** 2).sum(axis=1)).max())
        settings.radius = round(radius, 5)
    coefficients = 0
    while mesh.attributes.get(polygon_mesh.sh_attribute_name(coefficients)) is not None and coefficients < 16:
        coefficients += 1
    settings.sh_degree = max(0, math.isqrt(coefficients) - 1)
    return True


# Objects whose splat data was already looked at (original object pointer -> (mesh pointer, face count)).
_joined_checked = {}


def claim_joined_splats(objects):
    """Marks as Gaussian objects the unmarked meshes among `objects` of which most faces carry splat data (what a
    join with an ordinary mesh active leaves: Blender keeps the active object's settings). Returns those marked."""
    marked = []
    for obj in objects:
        if obj.type != "MESH" or obj.raysplats.is_gaussian or obj.mode == "EDIT":
            continue
        mesh = obj.data
        if mesh.attributes.get(polygon_mesh.ATTR_REST_SCALE) is None:
            continue
        key = (mesh.as_pointer(), len(mesh.polygons))
        if _joined_checked.get(obj.as_pointer()) == key:
            continue
        _joined_checked[obj.as_pointer()] = key
        carried = splat_faces(mesh)
        if carried is not None and len(carried) and np.count_nonzero(carried) > JOINED_SPLAT_FRACTION * len(carried):
            obj.raysplats.is_gaussian = True
            infer_splat_settings(obj)
            marked.append(obj)
    return marked


# Gaussian objects' colour adjustments as their colour attribute shows them (original object pointer -> key).
_shown_adjustments = {}


def show_color_adjustments(objects):
    """Refreshes the colour attribute of the Gaussian objects among `objects` whose adjustments changed since it was
    written (an object seen for the first time is taken as imported: unadjusted colours)."""
    for obj in objects:
        if not polygon_mesh.is_gaussian_object(obj) or obj.mode == "EDIT":
            continue
        key = color_adjustment.adjustment_key(obj.raysplats)
        shown = _shown_adjustments.get(obj.as_pointer(), color_adjustment.adjustment_key(None))
        if key != shown and refresh_corner_colors(obj):
            _shown_adjustments[obj.as_pointer()] = key


# Owner of the message-bus subscriptions below (cleared on unregister and by Blender on file load).
_msgbus_owner = object()


def _adjustments_edited():
    """A colour adjustment was edited (message bus): show it in the viewport, and tag the objects so that the Rendered
    viewport re-syncs them (setting an add-on property tags nothing by itself)."""
    objects = [obj for obj in bpy.data.objects if polygon_mesh.is_gaussian_object(obj)]
    show_color_adjustments(objects)
    for obj in objects:
        obj.update_tag()


def _shading_edited():
    """An object's Gaussian shading was edited (message bus): tag the Gaussian objects so that the Rendered viewport
    re-syncs them (engine.sync applies the new shading in place)."""
    for obj in bpy.data.objects:
        if polygon_mesh.is_gaussian_object(obj):
            obj.update_tag()


def subscribe_to_adjustments():
    """Message-bus subscriptions to the colour adjustments of every object's settings. The message bus, not update=
    callbacks: a property with an update callback makes Blender 4.2 as a Python module (the bpy wheel the tests run)
    crash at exit, even once unregistered."""
    bpy.msgbus.clear_by_owner(_msgbus_owner)
    for name in color_adjustment.ADJUSTMENT_NAMES:
        bpy.msgbus.subscribe_rna(key=(RaySplatsObjectSettings, name), owner=_msgbus_owner, args=(),
                                 notify=_adjustments_edited)
    bpy.msgbus.subscribe_rna(key=(RaySplatsObjectSettings, "gaussian_shading"), owner=_msgbus_owner, args=(),
                             notify=_shading_edited)


def forget_objects():
    """Forgets what was remembered about objects (after a file load their pointers mean nothing)."""
    _shown_adjustments.clear()
    _joined_checked.clear()


class OBJECT_OT_raysplats_mark_splats(bpy.types.Operator):
    """Mark the active mesh as a Gaussian splat object, reading its polygon settings back from its splat data"""

    bl_idname = "object.raysplats_mark_splats"
    bl_label = "Mark as Gaussian Splats"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        obj = context.active_object
        return obj is not None and obj.type == "MESH" and not obj.raysplats.is_gaussian

    @errors.reports_failures("Mark as Gaussian splats failed: ")
    def execute(self, context):
        obj = context.active_object
        if obj.mode == "EDIT":
            obj.update_from_editmode()
        if splat_faces(obj.data) is None:
            raise ValueError(f"'{obj.name}' carries no splat data (it was not imported as Gaussian splats)")
        obj.raysplats.is_gaussian = True
        infer_splat_settings(obj)
        return {"FINISHED"}


def register():
    bpy.utils.register_class(OBJECT_OT_raysplats_reduce_sh_degree)
    bpy.utils.register_class(OBJECT_OT_raysplats_mark_splats)
    subscribe_to_adjustments()


def unregister():
    bpy.msgbus.clear_by_owner(_msgbus_owner)
    bpy.utils.unregister_class(OBJECT_OT_raysplats_mark_splats)
    bpy.utils.unregister_class(OBJECT_OT_raysplats_reduce_sh_degree)
