# Blender's Apply Transform kept exact for splat objects. Applying a non-uniform scale or a shear to the
# polygon corners alone changes each Gaussian's thickness; the exact Apply here maps the full Gaussians (covariance,
# thickness, view-dependent colour) and rebuilds their polygons. Blender's own, which scripts can still call, is noticed
# and reported (notice_corner_only_apply, called by tools/handlers.py). Shown by ui/panels.py (Ctrl+A).
import bpy
import numpy as np
from bpy.props import BoolProperty
from mathutils import Matrix

from .. import errors, native
from ..blender import compat
from ..objects import color_adjustment, compact_points, polygon_mesh, splat_object
from ..objects.modifier_checks import CORNER_ONLY_APPLY_PROPERTY
from .upkeep import refresh_corner_colors

# Gaussian objects' placement when last seen (original object pointer -> (world matrix, a few vertices in world space)).
_placements = {}
_SAMPLED_VERTICES = 4


def _placement(obj):
    world = np.array(obj.matrix_world, dtype=np.float64)
    vertices = compat.points_of(obj.data)
    step = max(1, len(vertices) // _SAMPLED_VERTICES)
    local = np.array([tuple(vertices[i].co) for i in range(0, len(vertices), step)][:_SAMPLED_VERTICES])
    return world, (local @ world[:3, :3].T + world[:3, 3]) if len(local) else local, len(vertices)


def forget_placements():
    """Forgets the remembered placements (after a file load their pointers mean nothing)."""
    _placements.clear()


def notice_corner_only_apply(objects, geometry_changed):
    """Records CORNER_ONLY_APPLY_PROPERTY on the splat objects whose geometry changed together with their transform
    while their vertices (a point object's centres) stayed where they were in the world (what Apply Transform does), by
    a map that is not a similarity (rotations and uniform scales keep the Gaussians exact)."""
    for obj in objects:
        if not splat_object.is_splat_object(obj) or obj.mode == "EDIT":
            continue
        now = _placement(obj)
        before = _placements.get(obj.as_pointer())
        _placements[obj.as_pointer()] = now
        if before is None or obj.as_pointer() not in geometry_changed or before[2] != now[2] or not len(now[1]):
            continue
        size = max(1.0, float(np.abs(now[1]).max()))
        if np.allclose(before[0], now[0], atol=1e-7 * size) or not np.allclose(before[1], now[1], atol=1e-5 * size):
            continue
        applied = (np.linalg.inv(now[0]) @ before[0])[:3, :3]  # old mesh coordinates -> new mesh coordinates
        gram = applied.T @ applied
        if not np.allclose(gram, np.eye(3) * np.trace(gram) / 3.0, rtol=1e-5, atol=1e-6 * np.trace(gram)):
            obj[CORNER_ONLY_APPLY_PROPERTY] = True



class OBJECT_OT_raysplats_apply_transform(bpy.types.Operator):
    """Apply the object's transform to its Gaussians exactly (full covariance, thickness and view-dependent colour
    included), unlike Apply > Scale/Rotation, which moves only the polygons' corners"""

    bl_idname = "object.raysplats_apply_transform"
    bl_label = "Apply Transform to Gaussians"
    bl_options = {"REGISTER", "UNDO"}
    location: BoolProperty(name="Location", default=False)
    rotation: BoolProperty(name="Rotation", default=True)
    scale: BoolProperty(name="Scale", default=True)

    @classmethod
    def poll(cls, context):
        return context.mode == "OBJECT" and splat_object.is_splat_object(context.active_object)

    @errors.reports_failures("Apply transform failed: ")
    def execute(self, context):
        objects = [obj for obj in (context.selected_objects or [context.active_object])
                   if splat_object.is_splat_object(obj)]
        for obj in objects:
            count = apply_transform_exactly(obj, self.location, self.rotation, self.scale)
            self.report({"INFO"}, f"'{obj.name}': transform applied to {count:,} Gaussians")
        return {"FINISHED"}


def bake_matrix_into_gaussians(obj, matrix):
    """Rewrites a Gaussian object's polygons as its Gaussians mapped by `matrix` (4x4, any affine map: the full
    covariance Σ' = A Σ Aᵀ, the SH rotated with the faces). The object's transform is left as it is. The mesh is
    rebuilt as imported polygons of the mapped Gaussians (with their rest state), so every Gaussian exports exactly as
    the same object with `matrix` in its transform did. Returns the number of Gaussians."""
    if obj.mode == "EDIT":
        raise ValueError(f"'{obj.name}' is in Edit Mode; apply transforms in Object Mode")
    core = native.core()
    mesh, settings = obj.data, obj.raysplats
    if mesh.users > 1:
        raise ValueError(f"'{obj.name}': its mesh '{mesh.name}' is shared by {mesh.users} users; make it single "
                         "user first (Object > Relations > Make Single User)")
    cloud = polygon_mesh.recover_from_arrays(core, polygon_mesh.mesh_arrays(mesh),
                                              polygon_mesh.face_attributes(mesh, settings.sh_degree), settings,
                                              np.asarray(matrix, dtype=np.float64), adjust_colors=False)
    polygons = core.gaussians_to_polygons(cloud["positions"], cloud["rotations"], cloud["scales"], cloud["opacities"],
                                          cloud["sh"], vertices_per_polygon=settings.vertices_per_polygon,
                                          radius=settings.radius)
    mesh.clear_geometry()
    polygon_mesh.fill_mesh(mesh, polygons)
    if not color_adjustment.is_identity(settings):
        refresh_corner_colors(obj)
    return len(mesh.polygons)


def apply_transform_exactly(obj, location, rotation, scale):
    """Apply Transform for Gaussian objects: the chosen parts of the object's own transform are baked into the
    Gaussians (bake_matrix_into_gaussians) and the rest kept, so the object looks and exports exactly as before
    (applying rotation without a non-uniform scale bakes the shear that keeps it so). Children keep their world
    placement. Returns the number of Gaussians."""
    if any(value != 0.0 for value in obj.delta_location) or any(value != 0.0 for value in obj.delta_rotation_euler) \
            or any(value != 1.0 for value in obj.delta_scale):
        raise ValueError(f"'{obj.name}' has delta transforms; clear them first (Object > Clear > Delta Transforms "
                         "is not undoable here)")
    basis = obj.matrix_basis.copy()
    loc, rot, sca = basis.decompose()
    kept = Matrix.Identity(4)
    if not location:
        kept = Matrix.Translation(loc)
    if not rotation:
        kept = kept @ rot.to_matrix().to_4x4()
    if not scale:
        kept = kept @ Matrix.Diagonal(sca.to_4d())
    applied = kept.inverted_safe() @ basis
    if splat_object.kind_of(obj) == splat_object.POLYGONS:
        count = bake_matrix_into_gaussians(obj, np.array(applied, dtype=np.float64))
    else:
        count = compact_points.bake_matrix_into_points(obj, np.array(applied, dtype=np.float64))
    obj.matrix_basis = kept
    # The rebuilt mesh holds exact Gaussians again: no longer the corners of an earlier inexact apply, and this
    # placement change is not Blender's apply.
    _placements.pop(obj.as_pointer(), None)
    if CORNER_ONLY_APPLY_PROPERTY in obj:
        del obj[CORNER_ONLY_APPLY_PROPERTY]
    for child in obj.children:
        # child world = parent world @ parent inverse @ child basis; the parent's world lost `applied`.
        child.matrix_parent_inverse = applied @ child.matrix_parent_inverse
    return count



def register():
    bpy.utils.register_class(OBJECT_OT_raysplats_apply_transform)


def unregister():
    bpy.utils.unregister_class(OBJECT_OT_raysplats_apply_transform)
