# Selecting Gaussians for clean-up: by opacity, size, colour, floaters and a crop box, and deleting the
# selected ones. The criteria run in the core over whole arrays (native/include/raysplats/splat_selection.h); this
# module reads the Gaussians and writes Blender's face, edge and vertex selection in bulk. Shown by ui/panels.py.
import bpy
import numpy as np
from bpy.props import BoolProperty, EnumProperty, FloatProperty, FloatVectorProperty, IntProperty, StringProperty

from .. import errors, native
from ..objects import axes, polygon_mesh
from ..blender.compat import MESH_INDEX_DTYPE
from ..blender.mesh_read import read_face_corners

SELECTION_ACTIONS = (
    ("SET", "Set", "Select only these Gaussians"),
    ("ADD", "Extend", "Add these Gaussians to the selection"),
    ("SUBTRACT", "Subtract", "Deselect these Gaussians"),
)

class NoSplatObject(ValueError):
    pass


def target_objects(context):
    """The Gaussian objects a tool works on: those in Edit Mode, else the selected ones (or the active one)."""
    if context.mode == "EDIT_MESH":
        objects = list(getattr(context, "objects_in_mode", None) or [context.edit_object])
    else:
        objects = list(context.selected_objects) or [context.active_object]
    objects = [obj for obj in objects if polygon_mesh.is_gaussian_object(obj)]
    if not objects:
        raise NoSplatObject("No Gaussian splat object is selected (Object Properties > Gaussian Splats marks one)")
    return objects


class object_mode_data:
    """Within it the objects' mesh data is current: Edit Mode is left for Object Mode (which writes the edit mesh
    back) and entered again on exit, so that bulk reads and writes of the mesh arrays are seen by Edit Mode."""

    def __init__(self, context):
        self.was_editing = context.mode == "EDIT_MESH"

    def __enter__(self):
        if self.was_editing:
            bpy.ops.object.mode_set(mode="OBJECT")
        return self

    def __exit__(self, *exc):
        if self.was_editing:
            bpy.ops.object.mode_set(mode="EDIT")
        return False


def _face_rows(cloud, mesh):
    """Checks that a recovered cloud has one row per face of `mesh` (no face was dropped)."""
    if len(cloud["opacities"]) != len(mesh.polygons):
        raise ValueError(f"'{mesh.name}': {len(mesh.polygons) - len(cloud['opacities'])} polygons have invalid "
                         "vertices (NaN or fewer than 3 corners); delete them first")
    return cloud


def world_gaussians(obj):
    """The Gaussians of obj's own mesh (one row per face, no modifiers) in world coordinates, colours adjusted:
    what the user sees of the faces a selection is made of."""
    core = native.core()
    mesh = obj.data
    cloud = polygon_mesh.recover_mesh_gaussians(core, mesh, obj.raysplats, axes.world_matrix(obj))
    return _face_rows(cloud, mesh)


def _read_flags(collection, name):
    flags = np.empty(len(collection), dtype=bool)
    collection.foreach_get(name, flags)
    return flags


def write_face_selection(mesh, face_mask):
    """Makes `face_mask` (bool per face) the mesh's selection, with the vertices and edges of the selected faces
    (Blender stores all three and Edit Mode expects them to agree)."""
    core = native.core()
    starts = np.empty(len(mesh.polygons), dtype=np.int32)
    counts = np.empty(len(mesh.polygons), dtype=np.int32)
    read_face_corners(mesh, sizes=counts, starts=starts)
    corner_vertices = np.empty(len(mesh.loops), dtype=MESH_INDEX_DTYPE)
    mesh.loops.foreach_get("vertex_index", corner_vertices)
    corner_edges = np.empty(len(mesh.loops), dtype=MESH_INDEX_DTYPE)
    mesh.loops.foreach_get("edge_index", corner_edges)
    vertex_mask, edge_mask = core.select_face_elements(face_mask, starts, counts, corner_vertices.view(np.int32),
                                                       corner_edges.view(np.int32), len(mesh.vertices),
                                                       len(mesh.edges))
    mesh.polygons.foreach_set("select", face_mask)
    mesh.vertices.foreach_set("select", vertex_mask)
    mesh.edges.foreach_set("select", edge_mask)
    mesh.update()


def combine_selection(mesh, mask, action):
    """The new face selection of `mesh` from the tool's mask: set, added to or subtracted from the current one;
    hidden faces are never selected."""
    current = _read_flags(mesh.polygons, "select")
    if action == "ADD":
        mask = current | mask
    elif action == "SUBTRACT":
        mask = current & ~mask
    return mask & ~_read_flags(mesh.polygons, "hide")


class _SelectGaussians:
    """Shared body of the selection operators: face_mask(obj) gives each object's mask (one bool per face)."""

    bl_options = {"REGISTER", "UNDO"}
    action: EnumProperty(name="Action", items=SELECTION_ACTIONS, default="SET")

    @classmethod
    def poll(cls, context):
        return polygon_mesh.is_gaussian_object(context.active_object)

    def face_mask(self, context, obj):
        raise NotImplementedError  # each selection operator defines its criterion

    @errors.reports_failures("Selection failed: ")
    def execute(self, context):
        objects = target_objects(context)
        selected = total = 0
        with object_mode_data(context):
            for obj in objects:
                mask = combine_selection(obj.data, np.asarray(self.face_mask(context, obj), dtype=bool), self.action)
                write_face_selection(obj.data, mask)
                selected += int(np.count_nonzero(mask))
                total += len(mask)
        self.report({"INFO"}, f"{selected:,} of {total:,} Gaussians selected")
        return {"FINISHED"}


class MESH_OT_raysplats_select_opacity(_SelectGaussians, bpy.types.Operator):
    """Select the Gaussians whose opacity lies in a range"""

    bl_idname = "mesh.raysplats_select_opacity"
    bl_label = "Select by Opacity"
    min_opacity: FloatProperty(name="Minimum", default=0.0, min=0.0, max=1.0)
    max_opacity: FloatProperty(name="Maximum", default=0.05, min=0.0, max=1.0)

    def face_mask(self, context, obj):
        opacity = world_gaussians(obj)["opacities"]
        return native.core().select_by_value_range(opacity, self.min_opacity, self.max_opacity)


class MESH_OT_raysplats_select_size(_SelectGaussians, bpy.types.Operator):
    """Select the Gaussians whose largest scale (standard deviation, in world units) lies in a range"""

    bl_idname = "mesh.raysplats_select_size"
    bl_label = "Select by Size"
    min_size: FloatProperty(name="Minimum", default=0.1, min=0.0, subtype="DISTANCE", unit="LENGTH")
    max_size: FloatProperty(name="Maximum", default=1e6, min=0.0, subtype="DISTANCE", unit="LENGTH")

    def face_mask(self, context, obj):
        return native.core().select_by_largest_scale(world_gaussians(obj)["scales"], self.min_size, self.max_size)


class MESH_OT_raysplats_select_color(_SelectGaussians, bpy.types.Operator):
    """Select the Gaussians whose base colour (as shown, adjustments included) is close to a colour"""

    bl_idname = "mesh.raysplats_select_color"
    bl_label = "Select by Color"
    color: FloatVectorProperty(name="Color", subtype="COLOR_GAMMA", size=3, min=0.0, max=1.0, default=(1.0, 1.0, 1.0))
    distance: FloatProperty(name="Distance", default=0.1, min=0.0, max=1.8,
                            description="Largest RGB distance (display values 0..1) from the colour")

    def face_mask(self, context, obj):
        sh_dc = np.ascontiguousarray(world_gaussians(obj)["sh"][:, 0, :])
        return native.core().select_by_color_distance(sh_dc, np.array(self.color, dtype=np.float32), self.distance)


class MESH_OT_raysplats_select_floaters(_SelectGaussians, bpy.types.Operator):
    """Select floaters: Gaussians far from their nearest neighbours (statistical outlier test on the centres)"""

    bl_idname = "mesh.raysplats_select_floaters"
    bl_label = "Select Floaters"
    neighbors: IntProperty(name="Neighbors", default=16, min=1, max=128,
                           description="How many nearest centres each Gaussian's mean distance is taken over")
    threshold: FloatProperty(name="Threshold", default=3.0, soft_min=0.0, soft_max=10.0,
                             description="Floaters are farther from their neighbours than the mean distance plus "
                                         "this many standard deviations")

    def face_mask(self, context, obj):
        mask, _ = native.core().select_floaters(world_gaussians(obj)["positions"], self.neighbors, self.threshold)
        return mask


def crop_box(crop_object):
    """(world -> box frame 4x4, box minimum, box maximum) of a crop object: its bounding box in its own
    coordinates (a cube's, or any object's), so a rotated or scaled box crops in its own axes."""
    corners = np.array([tuple(corner) for corner in crop_object.bound_box], dtype=np.float64)
    world_to_box = np.array(crop_object.matrix_world.inverted_safe(), dtype=np.float64)
    return world_to_box, corners.min(axis=0).astype(np.float32), corners.max(axis=0).astype(np.float32)


class MESH_OT_raysplats_select_crop_box(_SelectGaussians, bpy.types.Operator):
    """Select the Gaussians whose centres are inside (or outside) a crop object's bounding box"""

    bl_idname = "mesh.raysplats_select_crop_box"
    bl_label = "Select by Crop Box"
    crop_object: StringProperty(name="Crop Object", description="The object whose bounding box crops (empty: the "
                                                                 "scene's crop box)")
    inside: BoolProperty(name="Inside", default=False,
                         description="Select the Gaussians inside the box (off: those outside, to delete them)")

    def face_mask(self, context, obj):
        name = self.crop_object or getattr(context.scene.raysplats_tools.crop_object, "name", "")
        crop = context.scene.objects.get(name) if name else None
        if crop is None:
            raise ValueError(f"No crop object '{name}' in the scene" if name else
                             "No crop object: choose one in the Splats tab (Crop Box)")
        if crop == obj:
            raise ValueError(f"'{obj.name}' cannot crop itself; choose another object as the crop box")
        world_to_box, box_min, box_max = crop_box(crop)
        return native.core().select_in_box(world_gaussians(obj)["positions"], world_to_box, box_min, box_max,
                                           self.inside)


class MESH_OT_raysplats_delete_selected(bpy.types.Operator):
    """Delete the selected Gaussians (their polygons)"""

    bl_idname = "mesh.raysplats_delete_selected"
    bl_label = "Delete Selected Gaussians"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        return context.mode == "EDIT_MESH" and polygon_mesh.is_gaussian_object(context.edit_object)

    @errors.reports_failures("Delete failed: ")
    def execute(self, context):
        objects = target_objects(context)
        with object_mode_data(context):
            before = sum(len(obj.data.polygons) for obj in objects)
            selected = sum(int(np.count_nonzero(_read_flags(obj.data.polygons, "select"))) for obj in objects)
        # A splat's polygon shares no vertex with another, so deleting faces (with their now unused edges and
        # vertices) removes exactly the selected Gaussians.
        bpy.ops.mesh.delete(type="FACE")
        self.report({"INFO"}, f"Deleted {selected:,} of {before:,} Gaussians")
        return {"FINISHED"}


class RaySplatsToolSettings(bpy.types.PropertyGroup):
    crop_object: bpy.props.PointerProperty(
        type=bpy.types.Object, name="Crop Box",
        description="The object whose bounding box Select by Crop Box uses (a cube, or any mesh)")



CLASSES = (RaySplatsToolSettings, MESH_OT_raysplats_select_opacity, MESH_OT_raysplats_select_size,
           MESH_OT_raysplats_select_color, MESH_OT_raysplats_select_floaters, MESH_OT_raysplats_select_crop_box,
           MESH_OT_raysplats_delete_selected)


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.Scene.raysplats_tools = bpy.props.PointerProperty(type=RaySplatsToolSettings)


def unregister():
    del bpy.types.Scene.raysplats_tools
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
