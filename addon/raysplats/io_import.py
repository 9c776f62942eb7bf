# File > Import > Gaussian Splats (the formats the core reads, splat_formats() below): one mesh object, one
# polygon per Gaussian (a glTF file's other meshes through Blender's own glTF importer, io_gltf.py).
import os

import bpy
from bpy.props import BoolProperty, CollectionProperty, EnumProperty, FloatProperty, IntProperty, StringProperty
from bpy_extras.io_utils import ImportHelper

from . import axes, blender_compat, errors, gaussian_mesh, io_gltf, material, native
from .progress import StageProgress



def splat_formats(writable_only=False):
    """The splat formats the core reads (and, where "writable", writes), from the core (the one list of them): dicts of
    name, extensions (endings of file names: ".ply", or a whole name such as SOG's "meta.json"; the first is the one
    written), description, up_axis (of the cloud as read: -Y) and writable. `writable_only`: the ones export offers."""
    formats = native.core().splat_formats()
    return [f for f in formats if f.get("writable", True)] if writable_only else formats


def splat_format_of(filepath, writable_only=False):
    """The core's entry for the format the file's name ends with (the core's match_splat_format: the longest ending
    that matches, so "a.compressed.ply" is a compressed PLY, "a.ply" an INRIA one), or None."""
    match = native.core().match_splat_format(filepath, writable_only)
    return None if match is None else next(f for f in splat_formats() if f["name"] == match["name"])


def with_splat_extension(filepath, extension):
    """`filepath` ending in `extension`: the ending of a format the core writes (the whole ".compressed.ply") is
    replaced, anything else kept and the extension added."""
    match = native.core().match_splat_format(filepath, True)
    return filepath[:len(filepath) - len(match["ending"])] + extension if match else filepath + extension


def writable_splat_formats():
    """The entries of splat_formats() the core also writes (not glTF, written by the mesh export, nor SOG)."""
    return splat_formats(writable_only=True)


def splat_extensions(writable_only=False):
    return tuple(extension for f in splat_formats(writable_only) for extension in f["extensions"])


def splat_file_browser_filter(writable_only=False):
    """The file browser's filter_glob for splat files: "*.ply;*.splat;*.spz;…;*meta.json"."""
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


# Import representations (compact_splats.py): AUTO picks polygons for scenes they suit, compact points beyond. Where
# compact points are Blender's own Gaussian-splat point cloud (5.3 on), they are called by its name.
POINTS_NAME = "Blender Gaussian Splats" if blender_compat.SPLATS_AS_POINT_CLOUD else "Compact Points"
REPRESENTATION_ITEMS = (
    ("AUTO", "Automatic", "Editable polygons up to 3 million Gaussians when the memory allows them, compact points "
                          "beyond"),
    ("POLYGONS", "Editable Polygons", "One polygon per Gaussian, editable with every Blender tool (about 350-620 "
                                      "bytes per Gaussian as quadrilaterals, Auto's choice above a million, about "
                                      "twice that as octagons, and several KB in Edit Mode)"),
    ("POINTS", POINTS_NAME, "One point per Gaussian (about 60 bytes each, more with SH): renders, transforms and "
                            "exports exactly; edit a region as polygons with Edit Selected as Polygons"),
)
# Above this many Gaussians AUTO imports compact points: Blender's Edit Mode costs about 5 KB per polygon Gaussian
# (docs/benchmarks.md, Import), so bigger scenes are edited a region at a time.
AUTO_POLYGON_LIMIT = 3_000_000


# Polygon Vertices "Auto" (0): octagons up to this many Gaussians, quadrilaterals above, which halves the mesh and
# nearly halves the import's peak memory (examples/benchmark_import_memory.py --k; docs/benchmarks.md). Renders and
# exports do not depend on K (each Gaussian is recovered by moments); Solid view and Material Preview show the splats as
# four-cornered patches.
AUTO_OCTAGON_LIMIT = 1_000_000


def auto_vertices_per_polygon(count):
    """K for `count` Gaussians when Polygon Vertices is Auto: 8 up to AUTO_OCTAGON_LIMIT, 4 above."""
    return 8 if count <= AUTO_OCTAGON_LIMIT else 4


# Objects "Auto": a scene whose polygons have more than AUTO_SINGLE_OBJECT_VERTICES vertices is split into spatially
# compact pieces of at most AUTO_PIECE_VERTICES vertices, one object each, under one empty, so that edits run at
# interactive speed. In Rendered view and Material Preview Blender re-evaluates an edited object whole after each
# edit: it converts the edit mesh to a mesh to add the original coordinates those shadings request
# (DerivedMesh.cc, editbmesh_calc_modifiers: "avoid the need to convert to mesh data just to add an orco layer"),
# twice per edit, in time proportional to the object's vertices (blender_tests/gui/viewport_rendered.py prints an
# edit's time; docs/benchmarks.md, Editing big scenes, has the figures). biker_v4.spz (152 k octagons, 1.2 M
# vertices) stays one object.
AUTO_SINGLE_OBJECT_VERTICES = 1_500_000
AUTO_PIECE_VERTICES = 400_000

OBJECTS_ITEMS = (
    ("AUTO", "Automatic", "One object while the polygons have at most 1.5 million vertices (biker_v4: 152 k "
                          "octagons), spatial pieces of 400 thousand vertices above, under one empty"),
    ("ONE", "One Object", "Always one object (editing a few splats of a big scene then updates the whole object: "
                          "seconds per edit in Rendered view)"),
    ("PIECES", "Pieces", "Spatially compact pieces of at most Piece Size Gaussians, one object each, under one empty "
                         "that carries the scene's transform"),
)


def gaussians_per_piece(objects, count, vertices_per_polygon, piece_size=0):
    """How many Gaussians each object of an import of `count` Gaussians at K = `vertices_per_polygon` holds at most:
    `count` for one object (objects "ONE", or "AUTO" up to AUTO_SINGLE_OBJECT_VERTICES), else `piece_size` ("PIECES"
    with piece_size > 0) or AUTO_PIECE_VERTICES / K."""
    if objects not in {item[0] for item in OBJECTS_ITEMS}:
        raise ValueError(f"unknown Objects choice '{objects}' (known: {', '.join(i[0] for i in OBJECTS_ITEMS)})")
    if objects == "ONE" or (objects == "AUTO" and count * vertices_per_polygon <= AUTO_SINGLE_OBJECT_VERTICES):
        return max(count, 1)
    if objects == "PIECES" and piece_size > 0:
        return piece_size
    return max(1, AUTO_PIECE_VERTICES // vertices_per_polygon)


def resolve_vertices_per_polygon(core, filepath, vertices_per_polygon, max_count=0):
    """`vertices_per_polygon`, or for 0 (Auto) auto_vertices_per_polygon() of the Gaussians the file declares (at most
    max_count), read from its header."""
    if vertices_per_polygon in (1, 2) or vertices_per_polygon < 0:
        raise ValueError(f"Polygon Vertices {vertices_per_polygon}: a polygon needs at least 3 (0: Auto)")
    if vertices_per_polygon > 0:
        return vertices_per_polygon
    count = core.probe_splat_file(filepath)["count"]
    return auto_vertices_per_polygon(min(count, max_count) if max_count > 0 else count)


def _not_enough(filepath, count, needed, available, advice):
    return NotEnoughMemory(f"'{filepath}': not enough memory to import {count:,} Gaussians (needs about "
                           f"{memory_size_text(needed)}, {memory_size_text(available)} available); {advice}")


def check_import_memory(core, filepath, vertices_per_polygon, max_count=0, representation="POLYGONS"):
    """Which representation the import uses ("POLYGONS" or "POINTS"; AUTO resolved) and its memory estimate in bytes,
    from the file's header alone. Raises NotEnoughMemory, before anything is read or allocated, when the Gaussians
    the file declares (at most max_count of them) need more memory than the machine has available; AUTO falls back
    to compact points when polygons would not fit. Returns (representation, bytes, note for the user or None)."""
    summary = core.probe_splat_file(filepath)
    count = min(summary["count"], max_count) if max_count > 0 else summary["count"]
    polygons = core.import_memory_bytes(count, summary["sh_degree"], vertices_per_polygon)
    points = core.compact_import_memory_bytes(count, summary["sh_degree"])
    available = core.available_memory_bytes() or float("inf")
    limit = "set Maximum Count or Minimum Opacity to import fewer"
    if representation == "POINTS":
        if points > available:
            raise _not_enough(filepath, count, points, available, limit)
        return "POINTS", points, None
    if representation == "AUTO" and (count > AUTO_POLYGON_LIMIT or polygons > available):
        if points > available:
            raise _not_enough(filepath, count, points, available, limit)
        why = (f"as polygons they would need about {memory_size_text(polygons)} "
               f"({memory_size_text(available)} available)" if polygons > available
               else f"more than {AUTO_POLYGON_LIMIT:,} Gaussians are edited a region at a time")
        return "POINTS", points, (f"imported as {POINTS_NAME.lower()} ({why}); select a region in Edit Mode and use "
                                  "Edit Selected as Polygons to edit it")
    if polygons > available:
        raise _not_enough(filepath, count, polygons, available,
                          f"{limit}, use fewer Polygon Vertices, or import as {POINTS_NAME} (about "
                          f"{memory_size_text(points)})")
    return "POLYGONS", polygons, None


def import_gaussian_splats(context, filepath, vertices_per_polygon=0, radius=3.0, up_axis="DETECT",
                           min_opacity=0.0, max_count=0, gltf_meshes=True, representation="POLYGONS",
                           objects="AUTO", piece_size=0):
    """Imports a splat file as a new Gaussian object in the active collection: polygons, or compact points
    (compact_splats.py) when `representation` says so or (AUTO) when the scene is too big for polygons; for a glTF
    file with `gltf_meshes`, also its other meshes through Blender's glTF importer. `up_axis`: an axis, "AUTO" (the
    format's convention) or "DETECT" (axes.resolve_import_up_axis: the scene's own up where its data shows it).
    `vertices_per_polygon`: K, or 0 for Auto (auto_vertices_per_polygon). `objects`, `piece_size`: one object or
    spatial pieces (gaussians_per_piece); a split scene is an empty with the pieces as its children, and the object
    returned is that empty (gaussian_mesh.scene_pieces gives the pieces). Returns (object, warnings, stage timings).
    Raises on bad input or too little memory; nothing is added then (a failure at any step leaves no mesh or object
    behind)."""
    from . import compact_splats  # (it imports this module)

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
                obj = compact_splats.add_compact_object(context, name, cloud, resolved, filepath)
                del cloud
            else:
                cloud = holder.pop()
                per_piece = gaussians_per_piece(objects, len(cloud["opacities"]), vertices_per_polygon, piece_size)
                if per_piece < len(cloud["opacities"]):
                    obj, warnings = add_gaussian_pieces(context, name, cloud, per_piece, vertices_per_polygon, radius,
                                                        resolved, filepath, progress)
                else:
                    obj, warnings = add_gaussian_object(context, name, cloud, vertices_per_polygon, radius,
                                                        resolved, filepath, progress)
                del cloud
            obj.rotation_euler = axes.object_rotation_euler(resolved)
            if gltf_meshes and splat_format is not None and splat_format["name"] == "gltf":
                io_gltf.import_gltf_meshes(context, filepath)
                context.view_layer.objects.active = (gaussian_mesh.scene_pieces(obj) or [obj])[0]
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
    only reference to `cloud` lets it go as soon as the polygons hold every face's own Gaussian. `vertices_per_polygon`:
    K, or 0 for Auto (auto_vertices_per_polygon of the cloud's size)."""
    stage = progress.stage if progress is not None else (lambda name: None)
    if vertices_per_polygon <= 0:
        vertices_per_polygon = auto_vertices_per_polygon(len(cloud["opacities"]))
    stage("build polygons")
    polygons = _polygons_of(cloud, vertices_per_polygon, radius)
    warnings = list(cloud.get("warnings", ())) + _invisible_warnings(polygons["invisible_skipped"])
    sh_degree = cloud["sh_degree"]
    del cloud
    stage("fill Blender mesh")
    obj = _new_gaussian_object(name, polygons, vertices_per_polygon, radius, sh_degree, up_axis, source_file)
    stage("object and material")
    try:
        link_as_only_selected(context, obj)
    except BaseException:
        remove_gaussian_object(obj)
        raise
    return obj, warnings


def add_gaussian_pieces(context, name, cloud, per_piece, vertices_per_polygon, radius, up_axis, source_file="",
                        progress=None):
    """`cloud` as add_gaussian_object, split into spatially compact pieces of at most `per_piece` Gaussians
    (the core's k-d split of the centres): one Gaussian object per piece, named "<name>_01"..., each the child of
    one new empty `name` that carries the scene's transform (the pieces keep identity transforms). The empty and
    every piece are selected, and the first piece is active, so G moves the whole scene and Tab edits every piece.
    Returns (empty, warnings). On failure nothing stays."""
    stage = progress.stage if progress is not None else (lambda name: None)
    core = native.core()
    stage("build polygons")
    order, starts = core.split_into_spatial_pieces(cloud["positions"], per_piece)
    for key in ("positions", "rotations", "scales", "opacities", "sh"):
        cloud[key] = cloud[key][order]  # (each key's old array is freed as its piece-ordered copy replaces it)
    del order
    warnings, invisible, made = list(cloud.get("warnings", ())), 0, []
    width = len(str(len(starts) - 1))
    if progress is not None:
        progress.add_stages(2 * (len(starts) - 2))  # build and fill for each piece after the first
    root = bpy.data.objects.new(name, None)
    root.empty_display_type = "PLAIN_AXES"
    try:
        for index, (begin, end) in enumerate(zip(starts[:-1], starts[1:])):
            stage("build polygons")
            piece = {key: cloud[key][begin:end] for key in ("positions", "rotations", "scales", "opacities", "sh")}
            polygons = _polygons_of(piece, vertices_per_polygon, radius)
            del piece
            invisible += polygons["invisible_skipped"]
            if len(polygons["face_corner_start"]) == 0:
                continue  # a piece of invisible Gaussians only
            stage("fill Blender mesh")
            obj = _new_gaussian_object(f"{name}_{index + 1:0{width}d}", polygons, vertices_per_polygon, radius,
                                       cloud["sh_degree"], up_axis, source_file)
            made.append(obj)
            obj.parent = root
        stage("object and material")
        del cloud
        link_as_only_selected(context, root)
        collection = root.users_collection[0]
        for obj in made:
            collection.objects.link(obj)
            obj.select_set(True)
        if made:
            context.view_layer.objects.active = made[0]
    except BaseException:
        for obj in made:
            remove_gaussian_object(obj)
        bpy.data.objects.remove(root)
        raise
    return root, warnings + _invisible_warnings(invisible)


def _polygons_of(cloud, vertices_per_polygon, radius):
    return native.core().gaussians_to_polygons(
        cloud["positions"], cloud["rotations"], cloud["scales"], cloud["opacities"], cloud["sh"],
        vertices_per_polygon=vertices_per_polygon, radius=radius)


def _invisible_warnings(invisible_skipped):
    return ([f"{invisible_skipped:,} Gaussian(s) with opacity below 1/255 (invisible) not imported"]
            if invisible_skipped else [])


def _new_gaussian_object(name, polygons, vertices_per_polygon, radius, sh_degree, up_axis, source_file):
    """A Gaussian object of its own new mesh filled from `polygons` (the core's gaussians_to_polygons dict, emptied
    on the way), not linked to any collection. On failure nothing stays."""
    mesh = bpy.data.meshes.new(name)
    obj = None
    try:
        gaussian_mesh.fill_mesh(mesh, polygons)  # (takes the arrays out of `polygons`, freeing each once copied)
        del polygons
        mesh.materials.append(material.gaussian_material())
        obj = bpy.data.objects.new(name, mesh)
        settings = obj.raysplats
        settings.is_gaussian = True
        settings.vertices_per_polygon = vertices_per_polygon
        settings.radius = radius
        settings.sh_degree = sh_degree
        settings.source_file = source_file
        settings.up_axis = up_axis
    except BaseException:
        # Whatever step failed, the data-blocks made so far go: removing the object unlinks it everywhere.
        if obj is not None:
            bpy.data.objects.remove(obj)
        bpy.data.meshes.remove(mesh)
        raise
    return obj


def link_as_only_selected(context, obj):
    """Links a new object to the active collection (the scene's, without one) as the only selected, active object."""
    collection = context.collection if getattr(context, "collection", None) else context.scene.collection
    collection.objects.link(obj)
    for other in context.view_layer.objects:
        other.select_set(False)
    obj.select_set(True)
    context.view_layer.objects.active = obj


def remove_gaussian_object(obj):
    """Removes an object an import made, with its mesh or point cloud (the import failed after it), and for a split
    scene's empty its pieces."""
    for piece in [child for child in obj.children if gaussian_mesh.is_gaussian_object(child)]:
        remove_gaussian_object(piece)
    data = obj.data
    bpy.data.objects.remove(obj)
    if data is not None and data.users == 0:
        (bpy.data.meshes if isinstance(data, bpy.types.Mesh) else bpy.data.pointclouds).remove(data)


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
            pieces = gaussian_mesh.scene_pieces(obj)
            imported += [obj] + [piece for piece in pieces if piece is not obj]
            if self.color_solid_views and pieces:
                show_splat_colors_in_solid_views(context, pieces[0])
            for warning in warnings:
                self.report({"WARNING"}, f"{os.path.basename(path)}: {warning}")
            if pieces:
                count, up_axis = sum(len(piece.data.polygons) for piece in pieces), pieces[0].raysplats.up_axis
                form = f" in {len(pieces)} pieces" if pieces[0] is not obj else ""
            else:
                from . import compact_splats, native_splats
                count = compact_splats.point_count(obj.data)
                up_axis, form = native_splats.object_up_axis(obj), f" as {POINTS_NAME.lower()}"
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
