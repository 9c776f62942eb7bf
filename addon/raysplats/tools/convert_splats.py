# Object > Convert between Blender's own Gaussian splats (Blender 5.3) and our polygon Gaussian objects, so that
# splats pass between Blender's renderers (which draw its splat point clouds) and ours (which edits, exports and ray
# traces our objects). The layout is objects/blender_splats.py's.
import bpy
import numpy as np
from bpy.props import BoolProperty, FloatProperty, IntProperty

from .. import errors, native
from ..blender import compat
from ..objects import polygon_mesh, splat_object
from ..objects.compact_points import object_cloud
from ..objects.creation import add_gaussian_object
from ..objects.blender_splats import is_blender_splat_object, new_blender_splat_data



def _replace_in_scene(context, old, new, keep_original):
    for collection in old.users_collection:
        collection.objects.link(new)
    new.matrix_world = old.matrix_world.copy()
    new.select_set(True)
    context.view_layer.objects.active = new
    if keep_original:
        old.select_set(False)
    else:
        bpy.data.objects.remove(old)


def convert_to_blender_splats(context, obj, keep_original=False):
    """Blender splat object made from our Gaussian object `obj` (evaluated: modifiers and edits applied), in the same
    place (object transform kept, not baked). Returns the new object."""
    depsgraph = context.evaluated_depsgraph_get()
    gaussians = polygon_mesh.recover_object_gaussians(native.core(), obj, depsgraph, np.eye(4))
    new = bpy.data.objects.new(obj.name + " splats", new_blender_splat_data(obj.name, gaussians))
    splat_object.set_up_axis(new, splat_object.up_axis_of(obj))
    _replace_in_scene(context, obj, new, keep_original)
    return new


def convert_from_blender_splats(context, obj, vertices_per_polygon=8, radius=3.0, keep_original=False):
    """Our Gaussian object made from a Blender splat object `obj` (evaluated: geometry nodes applied), in the same
    place, exporting as `obj` does (splat_object.up_axis_of). Returns the new object."""
    data = obj.evaluated_get(context.evaluated_depsgraph_get()).data
    cloud = object_cloud(obj, data)  # the Gaussians it shows: not those out in a region being edited
    if cloud is None:
        raise ValueError(f"'{obj.name}' has no Gaussians to convert")
    up_axis = splat_object.up_axis_of(obj)
    new, _ = add_gaussian_object(context, obj.name.removesuffix(" splats"), cloud, vertices_per_polygon, radius, up_axis)
    # add_gaussian_object linked it to the active collection; the converted object goes where the original was.
    for collection in list(new.users_collection):
        collection.objects.unlink(new)
    _replace_in_scene(context, obj, new, keep_original)
    return new


class OBJECT_OT_raysplats_to_native_splats(bpy.types.Operator):
    """Convert the selected RaySplats Gaussian objects to Blender's own Gaussian splat point clouds"""

    bl_idname = "object.raysplats_to_native_splats"
    bl_label = "Blender Gaussian Splats"
    bl_options = {"REGISTER", "UNDO"}

    keep_original: BoolProperty(name="Keep Original", default=False,
                                description="Keep the RaySplats objects beside the new splat objects")

    @classmethod
    def poll(cls, context):
        return any(polygon_mesh.is_gaussian_object(obj) for obj in context.selected_objects)

    @errors.reports_failures("Conversion failed: ")
    def execute(self, context):
        objects = [obj for obj in context.selected_objects if polygon_mesh.is_gaussian_object(obj)]
        for obj in objects:
            convert_to_blender_splats(context, obj, self.keep_original)
        if not compat.HAS_NATIVE_GAUSSIAN_SPLATS:
            self.report({"WARNING"}, "This Blender has no Gaussian splat point clouds (5.3+): the splat attributes "
                                     "were written on mesh vertices")
        self.report({"INFO"}, f"Converted {len(objects)} object(s) to Blender Gaussian splats")
        return {"FINISHED"}


class OBJECT_OT_raysplats_from_native_splats(bpy.types.Operator):
    """Convert the selected Blender Gaussian splat point clouds to editable RaySplats Gaussian objects"""

    bl_idname = "object.raysplats_from_native_splats"
    bl_label = "RaySplats Gaussians"
    bl_options = {"REGISTER", "UNDO"}

    vertices_per_polygon: IntProperty(name="Polygon Vertices", default=8, min=3, max=64,
                                      description="Vertices of the polygon each Gaussian becomes")
    radius: FloatProperty(name="Polygon Radius", default=3.0, min=0.5, max=6.0,
                          description="Mahalanobis radius of the polygons: 3 covers the Gaussian's 3-sigma support")
    keep_original: BoolProperty(name="Keep Original", default=False,
                                description="Keep the splat point clouds beside the new RaySplats objects")

    @classmethod
    def poll(cls, context):
        return any(is_blender_splat_object(obj) for obj in context.selected_objects)

    @errors.reports_failures("Conversion failed: ")
    def execute(self, context):
        objects = [obj for obj in context.selected_objects if is_blender_splat_object(obj)]
        for obj in objects:
            convert_from_blender_splats(context, obj, self.vertices_per_polygon, self.radius, self.keep_original)
        self.report({"INFO"}, f"Converted {len(objects)} splat object(s) to RaySplats Gaussians")
        return {"FINISHED"}


_classes = (OBJECT_OT_raysplats_to_native_splats, OBJECT_OT_raysplats_from_native_splats)


def menu_convert(self, context):
    self.layout.separator()
    self.layout.operator(OBJECT_OT_raysplats_to_native_splats.bl_idname)
    self.layout.operator(OBJECT_OT_raysplats_from_native_splats.bl_idname)


def register():
    for cls in _classes:
        bpy.utils.register_class(cls)
    bpy.types.VIEW3D_MT_object_convert.append(menu_convert)


def unregister():
    bpy.types.VIEW3D_MT_object_convert.remove(menu_convert)
    for cls in reversed(_classes):
        bpy.utils.unregister_class(cls)
