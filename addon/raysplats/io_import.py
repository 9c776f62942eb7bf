# File > Import > Gaussian Splats (.ply/.splat/.spz): one mesh object, one polygon per Gaussian.
import os

import bpy
from bpy.props import EnumProperty, FloatProperty, IntProperty, StringProperty
from bpy_extras.io_utils import ImportHelper

from . import axes, gaussian_mesh, material, native
from .progress import StageProgress

SPLAT_EXTENSIONS = (".ply", ".splat", ".spz")


def import_gaussian_splats(context, filepath, vertices_per_polygon=8, radius=3.0, up_axis="AUTO",
                           min_opacity=0.0, max_count=0):
    """Imports a splat file as a new Gaussian object in the active collection.
    Returns (object, warnings, stage timings). Raises on bad input; nothing is added then."""
    core = native.core()
    up_axis = axes.resolve_import_up_axis(up_axis, filepath)
    name = os.path.splitext(os.path.basename(filepath))[0] or "Gaussians"
    with StageProgress(getattr(context, "window_manager", None), "RaySplats import", 4) as progress:
        progress.stage("read file")
        cloud = core.read_splats(filepath, min_opacity=min_opacity, max_count=max_count)
        progress.stage("build polygons")
        polygons = core.gaussians_to_polygons(
            cloud["positions"], cloud["rotations"], cloud["scales"], cloud["opacities"], cloud["sh"],
            vertices_per_polygon=vertices_per_polygon, radius=radius)
        progress.stage("fill Blender mesh")
        mesh = bpy.data.meshes.new(name)
        try:
            gaussian_mesh.fill_mesh(mesh, polygons, cloud)
        except Exception:
            bpy.data.meshes.remove(mesh)
            raise
        del polygons
        progress.stage("object and material")
        mesh.materials.append(material.gaussian_material())
        obj = bpy.data.objects.new(name, mesh)
        obj.rotation_euler = (axes.object_rotation_x(up_axis), 0.0, 0.0)
        settings = obj.raysplats
        settings.is_gaussian = True
        settings.vertices_per_polygon = vertices_per_polygon
        settings.radius = radius
        settings.sh_degree = cloud["sh_degree"]
        settings.source_file = filepath
        settings.up_axis = up_axis
        collection = context.collection if getattr(context, "collection", None) else context.scene.collection
        collection.objects.link(obj)
        for other in context.view_layer.objects:
            other.select_set(False)
        obj.select_set(True)
        context.view_layer.objects.active = obj
    print(progress.summary())
    return obj, list(cloud["warnings"]), progress.times


class IMPORT_SCENE_OT_gaussian_splats(bpy.types.Operator, ImportHelper):
    """Import a 3D Gaussian Splatting scene as an editable mesh (one polygon per Gaussian)"""

    bl_idname = "import_scene.gaussian_splats"
    bl_label = "Import Gaussian Splats"
    bl_options = {"REGISTER", "UNDO", "PRESET"}

    filename_ext = ".ply"
    filter_glob: StringProperty(default="*.ply;*.splat;*.spz", options={"HIDDEN"})

    vertices_per_polygon: IntProperty(
        name="Polygon Vertices", default=8, min=3, max=64,
        description="Vertices of the polygon each Gaussian becomes (more: smoother outline, heavier mesh)")
    radius: FloatProperty(
        name="Polygon Radius", default=3.0, min=0.5, max=6.0,
        description="Mahalanobis radius of the polygons: 3 covers the Gaussian's 3-sigma support")
    up_axis: EnumProperty(
        name="Up Axis", items=axes.IMPORT_UP_AXIS_ITEMS, default="AUTO",
        description="Up direction in the file; the object is rotated (not baked) so that it stands upright")
    min_opacity: FloatProperty(
        name="Minimum Opacity", default=0.0, min=0.0, max=1.0,
        description="Gaussians less opaque than this are not imported (0 imports all)")
    max_count: IntProperty(
        name="Maximum Count", default=0, min=0,
        description="Import at most this many Gaussians, the first in the file (0 imports all)")

    def execute(self, context):
        try:
            obj, warnings, _ = import_gaussian_splats(
                context, self.filepath, self.vertices_per_polygon, self.radius, self.up_axis,
                self.min_opacity, self.max_count)
        except (native.NativeModuleMissing, RuntimeError, ValueError, OSError) as error:
            self.report({"ERROR"}, f"Import failed: {error}")
            return {"CANCELLED"}
        for warning in warnings:
            self.report({"WARNING"}, warning)
        self.report({"INFO"}, f"Imported {len(obj.data.polygons):,} Gaussians from {os.path.basename(self.filepath)}")
        return {"FINISHED"}


def menu_import(self, context):
    self.layout.operator(IMPORT_SCENE_OT_gaussian_splats.bl_idname, text="Gaussian Splats (.ply/.splat/.spz)")


def register():
    bpy.utils.register_class(IMPORT_SCENE_OT_gaussian_splats)
    bpy.types.TOPBAR_MT_file_import.append(menu_import)


def unregister():
    bpy.types.TOPBAR_MT_file_import.remove(menu_import)
    bpy.utils.unregister_class(IMPORT_SCENE_OT_gaussian_splats)
