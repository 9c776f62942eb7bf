# File > Import > Gaussian Splats (.ply/.splat/.spz/.sog/meta.json): one mesh object, one polygon per Gaussian.
import os

import bpy
from bpy.props import BoolProperty, CollectionProperty, EnumProperty, FloatProperty, IntProperty, StringProperty
from bpy_extras.io_utils import ImportHelper

from . import axes, blender_compat, errors, gaussian_mesh, material, native
from .progress import StageProgress



def splat_formats(writable_only=False):
    """The splat formats the core reads (and, where "writable", writes), from the core (the one list of them): dicts of
    name, extensions (endings of file names: ".ply", or a whole name such as SOG's "meta.json"; the first is the one
    written), description, up_axis (of the cloud as read: -Y) and writable. `writable_only`: the ones export offers."""
    formats = native.core().splat_formats()
    return [f for f in formats if f.get("writable", True)] if writable_only else formats


def splat_format_of(filepath, writable_only=False):
    """The core's entry for the format the file's name ends with (the longest ending that matches), or None."""
    name = filepath.lower()
    best, best_length = None, 0
    for f in splat_formats(writable_only):
        for ending in f["extensions"]:
            if name.endswith(ending) and len(ending) > best_length:
                best, best_length = f, len(ending)
    return best


def splat_extensions(writable_only=False):
    return tuple(extension for f in splat_formats(writable_only) for extension in f["extensions"])


def splat_file_browser_filter(writable_only=False):
    """The file browser's filter_glob for splat files: "*.ply;*.splat;*.spz;*.sog;*meta.json"."""
    return ";".join("*" + extension for extension in splat_extensions(writable_only))


def open_splat_file_browser(operator, helper, context, event, writable_only=False):
    """The invoke() of a splat import/export operator: the file browser (ImportHelper's or ExportHelper's)
    filtered to the core's formats (export: `writable_only`); without the native module, the error instead."""
    try:
        operator.filter_glob = splat_file_browser_filter(writable_only)
    except native.NativeModuleMissing as error:
        operator.report({"ERROR"}, str(error))
        return {"CANCELLED"}
    return helper.invoke(operator, context, event)


def splat_menu_text(writable_only=False):
    """ "Gaussian Splats (.ply/.splat/.spz/.sog/meta.json)", or without the list when the native module is missing."""
    try:
        return f"Gaussian Splats ({'/'.join(splat_extensions(writable_only))})"
    except native.NativeModuleMissing:
        return "Gaussian Splats"


class NotEnoughMemory(OSError):
    """The machine has too little memory for an import (a user-facing condition, not a bug: reported as such)."""


def memory_size_text(n):
    """Bytes for a message: "3.2 GB", or "650 MB" below a gigabyte."""
    return f"{n / 1e9:.1f} GB" if n >= 1e9 else f"{n / 1e6:.0f} MB"


def check_import_memory(core, filepath, vertices_per_polygon, max_count=0):
    """Raises NotEnoughMemory, before anything is read or allocated, when the Gaussians the file's header declares
    (at most max_count of them) need more memory than the machine has available. Returns the estimate in bytes."""
    summary = core.probe_splat_file(filepath)
    count = min(summary["count"], max_count) if max_count > 0 else summary["count"]
    needed = core.import_memory_bytes(count, summary["sh_degree"], vertices_per_polygon)
    available = core.available_memory_bytes()
    if available and needed > available:
        raise NotEnoughMemory(f"'{filepath}': not enough memory to import {count:,} Gaussians (needs about "
                              f"{memory_size_text(needed)}, {memory_size_text(available)} available); set Maximum Count or "
                              f"Minimum Opacity to import fewer, or use fewer Polygon Vertices")
    return needed


def import_gaussian_splats(context, filepath, vertices_per_polygon=8, radius=3.0, up_axis="AUTO",
                           min_opacity=0.0, max_count=0):
    """Imports a splat file as a new Gaussian object in the active collection.
    Returns (object, warnings, stage timings). Raises on bad input or too little memory; nothing is added then
    (a failure at any step leaves no mesh or object behind)."""
    core = native.core()
    up_axis = axes.resolve_import_up_axis(up_axis, splat_format_of(filepath))
    name = os.path.splitext(os.path.basename(filepath))[0] or "Gaussians"
    if os.path.basename(filepath).lower() == "meta.json":  # an unbundled SOG: its folder names the scene
        name = os.path.basename(os.path.dirname(os.path.abspath(filepath))) or name
    needed = check_import_memory(core, filepath, vertices_per_polygon, max_count)
    obj = None
    with StageProgress(getattr(context, "window_manager", None), "RaySplats import", 4) as progress:
        try:
            progress.stage("read file")
            # The cloud is handed over, not kept: add_gaussian_object releases it once the polygons hold it.
            obj, warnings = add_gaussian_object(
                context, name, core.read_splats(filepath, min_opacity=min_opacity, max_count=max_count),
                vertices_per_polygon, radius, up_axis, filepath, progress)
            obj.rotation_euler = (axes.object_rotation_x(up_axis), 0.0, 0.0)
        except BaseException as error:
            # Whatever step failed, nothing half-imported stays (add_gaussian_object cleans up its own failures).
            if obj is not None:
                remove_gaussian_object(obj)
            if isinstance(error, MemoryError):  # the estimate was too low, or memory went to something else
                raise NotEnoughMemory(f"'{filepath}': not enough memory to import the file's Gaussians (needs about "
                                      f"{memory_size_text(needed)}): {error}") from error
            raise
    print(progress.summary())
    return obj, warnings, progress.times


def add_gaussian_object(context, name, cloud, vertices_per_polygon, radius, up_axis, source_file="", progress=None):
    """A new Gaussian object (one polygon per Gaussian, at each Gaussian's opacity-aware radius) made from `cloud`
    (the core's dict: positions, rotations, scales, opacities, sh, sh_degree, optional warnings), in the active
    collection, selected and active. Its transform is left as identity for the caller. Returns (object, warnings):
    the cloud's and this step's. `progress`: a StageProgress to report the stages to. A caller that hands over its
    only reference to `cloud` lets it go as soon as the polygons hold every face's own Gaussian."""
    stage = progress.stage if progress is not None else (lambda name: None)
    core = native.core()
    stage("build polygons")
    polygons = core.gaussians_to_polygons(
        cloud["positions"], cloud["rotations"], cloud["scales"], cloud["opacities"], cloud["sh"],
        vertices_per_polygon=vertices_per_polygon, radius=radius)
    warnings = list(cloud.get("warnings", ()))
    if polygons["invisible_skipped"]:
        warnings.append(f"{polygons['invisible_skipped']:,} Gaussian(s) with opacity below 1/255 (invisible) "
                        "not imported")
    sh_degree = cloud["sh_degree"]
    del cloud
    stage("fill Blender mesh")
    mesh = bpy.data.meshes.new(name)
    obj = None
    try:
        gaussian_mesh.fill_mesh(mesh, polygons)
        del polygons
        stage("object and material")
        mesh.materials.append(material.gaussian_material())
        obj = bpy.data.objects.new(name, mesh)
        settings = obj.raysplats
        settings.is_gaussian = True
        settings.vertices_per_polygon = vertices_per_polygon
        settings.radius = radius
        settings.sh_degree = sh_degree
        settings.source_file = source_file
        settings.up_axis = up_axis
        collection = context.collection if getattr(context, "collection", None) else context.scene.collection
        collection.objects.link(obj)
        for other in context.view_layer.objects:
            other.select_set(False)
        obj.select_set(True)
        context.view_layer.objects.active = obj
    except BaseException:
        # Whatever step failed, the data-blocks made so far go: removing the object unlinks it everywhere.
        if obj is not None:
            bpy.data.objects.remove(obj)
        bpy.data.meshes.remove(mesh)
        raise
    return obj, warnings


def remove_gaussian_object(obj):
    """Removes an object add_gaussian_object made, with its mesh (the import failed after it)."""
    mesh = obj.data
    bpy.data.objects.remove(obj)
    if mesh is not None and mesh.users == 0:
        bpy.data.meshes.remove(mesh)


def show_splat_colors_in_solid_views(context, obj):
    """Switches the Solid shading colour of every 3D view that shows `obj` to its colour attribute (the splat
    colour, gaussian_mesh.ATTR_COLOR, the mesh's active colour attribute), so Solid and Edit Mode show the scene
    instead of grey polygons. Views of other scenes or whose local view leaves `obj` out keep their setting.
    Returns how many views were switched; without a window manager or windows (headless scripts), none."""
    window_manager = getattr(context, "window_manager", None)
    switched = 0
    for window in getattr(window_manager, "windows", ()):
        screen = window.screen
        if screen is None or window.scene != context.scene:
            continue
        for area in screen.areas:
            if area.type != "VIEW_3D":
                continue
            for space in area.spaces:
                if space.type == "VIEW_3D" and obj.visible_in_viewport_get(space):
                    space.shading.color_type = blender_compat.SOLID_COLOR_TYPE_ATTRIBUTE
                    switched += 1
            area.tag_redraw()
    return switched


def raise_material_preview_samples(scene, samples):
    """Raises the scene's EEVEE viewport samples to at least `samples` (never lowers them). The import material's
    hashed (dithered) transparency is noisy until enough samples have accumulated: on unicorn_sh3_reordered.ply
    EEVEE's agreement with the RaySplats render was 23.5 / 22.6 dB PSNR (front / back) at EEVEE's default 16 samples
    and 27.8 / 27.2 dB at 64 (examples/material_preview_agreement.py, Blender 3.4)."""
    eevee = getattr(scene, "eevee", None)
    if eevee is not None and samples > 0 and eevee.taa_samples < samples:
        eevee.taa_samples = samples


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
        for heading, names in (("Polygons", ("vertices_per_polygon", "radius", "up_axis")),
                               ("Limit", ("min_opacity", "max_count")),
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
                context, path, self.vertices_per_polygon, self.radius, self.up_axis, self.min_opacity, self.max_count)
            imported.append(obj)
            if self.color_solid_views:
                show_splat_colors_in_solid_views(context, obj)
            for warning in warnings:
                self.report({"WARNING"}, f"{os.path.basename(path)}: {warning}")
            self.report({"INFO"}, f"Imported {len(obj.data.polygons):,} Gaussians from {os.path.basename(path)}")
        for obj in imported:  # all of them selected, the last one active (import_gaussian_splats selects only its own)
            obj.select_set(True)
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
