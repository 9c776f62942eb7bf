# File > Import > Gaussian Splats (the formats the core reads, splat_formats() below): one mesh object, one
# polygon per Gaussian (a glTF file's other meshes through Blender's own glTF importer, gltf_mesh_import.py).
import os

import bpy
from bpy.props import BoolProperty, CollectionProperty, EnumProperty, FloatProperty, IntProperty, StringProperty
from bpy_extras.io_utils import ImportHelper

from .. import errors, native
from ..objects import axes, creation, polygon_mesh, splat_object
from ..progress import StageProgress
from ..blender.viewport_shading import raise_material_preview_samples, show_splat_colors_in_solid_views
from . import gltf_mesh_import
from .format_table import open_splat_file_browser, splat_format_of, splat_menu_text
from .import_policy import (NotEnoughMemory, OBJECTS_ITEMS, POINTS_NAME, REPRESENTATION_ITEMS, check_import_memory,
                            gaussians_per_piece, memory_size_text, resolve_vertices_per_polygon)


def import_gaussian_splats(context, filepath, vertices_per_polygon=0, radius=3.0, up_axis="DETECT",
                           min_opacity=0.0, max_count=0, gltf_meshes=True, representation="POLYGONS",
                           objects="AUTO", piece_size=0):
    """Imports a splat file as a new Gaussian object in the active collection: polygons, or compact points
    (objects/compact_points.py) when `representation` says so or (AUTO) when the scene is too big for polygons; for a
    glTF file with `gltf_meshes`, also its other meshes through Blender's glTF importer. `up_axis`: an axis, "AUTO" (the
    format's convention) or "DETECT" (axes.resolve_import_up_axis: the scene's own up where its data shows it).
    `vertices_per_polygon`: K, or 0 for Auto (auto_vertices_per_polygon). `objects`, `piece_size`: one object or
    spatial pieces (gaussians_per_piece); a split scene is an empty with the pieces as its children, and the object
    returned is that empty (polygon_mesh.scene_pieces gives the pieces). Returns (object, warnings, stage timings).
    Raises on bad input or too little memory; nothing is added then (a failure at any step leaves no mesh or object
    behind)."""

    core = native.core()
    splat_format = splat_format_of(filepath)
    base = os.path.basename(filepath)
    match = core.match_splat_format(base)
    extension = match["ending"] if match else os.path.splitext(base)[1]
    name = base[:len(base) - len(extension)] or "Gaussians"  # "guitar.compressed.ply" -> "guitar"
    if base.lower() == "meta.json":  # an unbundled SOG: its folder names the scene
        name = os.path.basename(os.path.dirname(os.path.abspath(filepath))) or "Gaussians"
    vertices_per_polygon = resolve_vertices_per_polygon(core, filepath, vertices_per_polygon, max_count)
    representation, needed, note = check_import_memory(core, filepath, vertices_per_polygon, max_count,
                                                       representation)
    obj = None
    with StageProgress(getattr(context, "window_manager", None), "RaySplats import", 4) as progress:
        try:
            progress.stage("read file")
            # Held in a list so that add_gaussian_object gets the only reference (holder.pop()) and can release it.
            holder = [core.read_splats(filepath, min_opacity=min_opacity, max_count=max_count)]
            estimate = None
            if axes.detection_wanted(up_axis, splat_format):
                cloud = holder[0]
                estimate = core.estimate_up_axis(cloud["positions"], cloud["rotations"], cloud["scales"],
                                                 cloud["opacities"])
                del cloud
            resolved = axes.resolve_import_up_axis(up_axis, splat_format, estimate)
            if estimate is not None:
                print(f"RaySplats: {os.path.basename(filepath)}: up axis {resolved} ("
                      f"{'found from the data' if estimate['decided'] else 'no clear ground in the data: convention'}; "
                      f"best {estimate['axis']}, margin {estimate['margin']:.2f})")
            # The cloud is handed over, not kept: add_gaussian_object releases it once the polygons hold it.
            if representation == "POINTS":
                cloud = holder.pop()
                warnings = list(cloud.get("warnings", ())) + ([note] if note else [])
                progress.stage("fill Blender points")
                obj = creation.add_compact_object(context, name, cloud, resolved, filepath)
                del cloud
            else:
                cloud = holder.pop()
                per_piece = gaussians_per_piece(objects, len(cloud["opacities"]), vertices_per_polygon, piece_size)
                if per_piece < len(cloud["opacities"]):
                    obj, warnings = creation.add_gaussian_pieces(context, name, cloud, per_piece, vertices_per_polygon,
                                                                 radius, resolved, filepath, progress)
                else:
                    obj, warnings = creation.add_gaussian_object(context, name, cloud, vertices_per_polygon, radius,
                                                                 resolved, filepath, progress)
                del cloud
            obj.rotation_euler = axes.object_rotation_euler(resolved)
            if gltf_meshes and splat_format is not None and splat_format["name"] == "gltf":
                gltf_mesh_import.import_gltf_meshes(context, filepath)
                context.view_layer.objects.active = (polygon_mesh.scene_pieces(obj) or [obj])[0]
        except BaseException as error:
            # Whatever step failed, nothing half-imported stays (add_gaussian_object cleans up its own failures).
            if obj is not None:
                creation.remove_gaussian_object(obj)
            if isinstance(error, MemoryError):  # the estimate was too low, or memory went to something else
                raise NotEnoughMemory(f"'{filepath}': not enough memory to import the file's Gaussians (needs about "
                                      f"{memory_size_text(needed)}): {error}") from error
            raise
    print(progress.summary())
    return obj, warnings, progress.times


class IMPORT_SCENE_OT_gaussian_splats(bpy.types.Operator, ImportHelper):
    """Import a 3D Gaussian Splatting scene as an editable mesh (one polygon per Gaussian)"""

    bl_idname = "import_scene.gaussian_splats"
    bl_label = "Import Gaussian Splats"
    bl_options = {"REGISTER", "UNDO", "PRESET"}

    filename_ext = ".ply"
    filter_glob: StringProperty(default="", options={"HIDDEN"})  # set from the core's formats in invoke()
    # Several files at once, as Blender's own importers: the file browser fills `files` (names) and `directory`.
    files: CollectionProperty(type=bpy.types.OperatorFileListElement, options={"HIDDEN", "SKIP_SAVE"})
    directory: StringProperty(subtype="DIR_PATH", options={"HIDDEN", "SKIP_SAVE"})

    vertices_per_polygon: IntProperty(
        name="Polygon Vertices", default=0, min=0, max=64,
        description="Vertices of the polygon each Gaussian becomes (more: smoother outline in Solid view and Material "
                    "Preview, heavier mesh; renders and exports do not depend on it). 0: Auto, 8 up to 1 million "
                    "Gaussians and 4 above (half the memory)")
    radius: FloatProperty(
        name="Polygon Radius", default=3.0, min=0.5, max=6.0,
        description="Mahalanobis radius of the polygons: 3 covers the Gaussian's 3-sigma support")
    up_axis: EnumProperty(
        name="Up Axis", items=axes.IMPORT_UP_AXIS_ITEMS, default="DETECT",
        description="Up direction in the file; the object is rotated (not baked) so that it stands upright")
    representation: EnumProperty(
        name="Import As", items=REPRESENTATION_ITEMS, default="AUTO",
        description="How the Gaussians are held in Blender: editable polygons, or compact points for big scenes")
    objects: EnumProperty(
        name="Objects", items=OBJECTS_ITEMS, default="AUTO",
        description="One object, or spatial pieces under one empty: moving splats in Edit Mode then updates only "
                    "the pieces they are in, which keeps big scenes interactive in Rendered view")
    piece_size: IntProperty(
        name="Piece Size", default=0, min=0,
        description="Gaussians per piece when Objects is Pieces (0: Auto, 400 thousand polygon vertices: 100 k "
                    "quadrilaterals or 50 k octagons)")
    gltf_meshes: BoolProperty(
        name="glTF Meshes", default=True,
        description="For .glb/.gltf files: also import the file's meshes (not its splats) with Blender's glTF importer")
    min_opacity: FloatProperty(
        name="Minimum Opacity", default=0.0, min=0.0, max=1.0,
        description="Gaussians less opaque than this are not imported (0 imports all)")
    max_count: IntProperty(
        name="Maximum Count", default=0, min=0,
        description="Import at most this many Gaussians, a uniform random choice over the whole file (the same "
                    "every time; 0 imports all)")
    color_solid_views: BoolProperty(
        name="Color Solid View", default=True,
        description="Set Solid shading's colour to the splat colour attribute in the 3D views that show the "
                    "imported object, so Solid and Edit Mode show the splats' colours instead of grey")
    preview_samples: IntProperty(
        name="Preview Samples", default=64, min=0, max=4096,
        description="Raise the scene's EEVEE viewport samples to at least this, so that Material Preview's "
                    "stochastic transparency converges to the render (0 leaves them as they are)")

    def invoke(self, context, event):
        return open_splat_file_browser(self, ImportHelper, context, event)

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        for heading, names in (("Polygons", ("representation", "vertices_per_polygon", "radius", "up_axis",
                                             "objects", "piece_size")),
                               ("Limit", ("min_opacity", "max_count")),
                               ("glTF", ("gltf_meshes",)),
                               ("Viewport", ("color_solid_views", "preview_samples"))):
            box = layout.box()
            box.label(text=heading)
            for name in names:
                box.prop(self, name)

    def selected_paths(self):
        """The files chosen in the browser (several at once), or `filepath` alone when called from a script."""
        names = [entry.name for entry in self.files if entry.name]
        if names and self.directory:
            return [os.path.join(self.directory, name) for name in names]
        return [self.filepath]

    @errors.reports_failures("Import failed: ")
    def execute(self, context):
        imported = []
        for path in self.selected_paths():
            obj, warnings, _ = import_gaussian_splats(
                context, path, self.vertices_per_polygon, self.radius, self.up_axis, self.min_opacity, self.max_count,
                self.gltf_meshes, self.representation, self.objects, self.piece_size)
            pieces = polygon_mesh.scene_pieces(obj)
            imported += [obj] + [piece for piece in pieces if piece is not obj]
            if self.color_solid_views and pieces:
                show_splat_colors_in_solid_views(context, pieces[0])
            for warning in warnings:
                self.report({"WARNING"}, f"{os.path.basename(path)}: {warning}")
            if pieces:
                count, up_axis = sum(len(piece.data.polygons) for piece in pieces), pieces[0].raysplats.up_axis
                form = f" in {len(pieces)} pieces" if pieces[0] is not obj else ""
            else:
                count = splat_object.shown_count(obj)
                up_axis, form = splat_object.up_axis_of(obj), f" as {POINTS_NAME.lower()}"
            self.report({"INFO"}, f"Imported {count:,} Gaussians from {os.path.basename(path)}{form} "
                                  f"(up axis {up_axis})")
        # All of them selected, the last file's active (import_gaussian_splats selects only its own): for a split
        # scene its first piece, so that Tab enters Edit Mode.
        active = context.view_layer.objects.active
        for obj in imported:
            obj.select_set(True)
        context.view_layer.objects.active = active
        raise_material_preview_samples(context.scene, self.preview_samples)
        return {"FINISHED"}


def menu_import(self, context):
    self.layout.operator(IMPORT_SCENE_OT_gaussian_splats.bl_idname, text=splat_menu_text())


def menu_add(self, context):
    # Shift+A > Gaussian Splats: the same importer, from where objects are added.
    self.layout.separator()
    self.layout.operator(IMPORT_SCENE_OT_gaussian_splats.bl_idname, text="Gaussian Splats")


def register():
    bpy.utils.register_class(IMPORT_SCENE_OT_gaussian_splats)
    bpy.types.TOPBAR_MT_file_import.append(menu_import)
    bpy.types.VIEW3D_MT_add.append(menu_add)


def unregister():
    bpy.types.VIEW3D_MT_add.remove(menu_add)
    bpy.types.TOPBAR_MT_file_import.remove(menu_import)
    bpy.utils.unregister_class(IMPORT_SCENE_OT_gaussian_splats)
