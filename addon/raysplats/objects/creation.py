# New splat objects of every kind: polygon objects (one, or spatial pieces under one empty) and compact point
# objects, linked to the active collection as the only selection; and their removal when an import fails.
import bpy

from .. import native
from ..blender import compat
from . import blender_splats, falloff_material, polygon_mesh, splat_object



# Polygon Vertices "Auto" (0): octagons up to this many Gaussians, quadrilaterals above, which halves the mesh and
# nearly halves the import's peak memory (examples/benchmark_import_memory.py --k; docs/benchmarks.md). Renders and
# exports do not depend on K (each Gaussian is recovered by moments); Solid view and Material Preview show the splats as
# four-cornered patches.
AUTO_OCTAGON_LIMIT = 1_000_000


def auto_vertices_per_polygon(count):
    """K for `count` Gaussians when Polygon Vertices is Auto: 8 up to AUTO_OCTAGON_LIMIT, 4 above."""
    return 8 if count <= AUTO_OCTAGON_LIMIT else 4


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
        polygon_mesh.fill_mesh(mesh, polygons)  # (takes the arrays out of `polygons`, freeing each once copied)
        del polygons
        mesh.materials.append(falloff_material.gaussian_material())
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
    for piece in [child for child in obj.children if polygon_mesh.is_gaussian_object(child)]:
        remove_gaussian_object(piece)
    data = obj.data
    bpy.data.objects.remove(obj)
    compat.remove_unused_data(data)


def add_compact_object(context, name, cloud, up_axis, source_file=""):
    """A new compact splat object holding `cloud` (the core's dict) in object space, in the active collection,
    selected and active; its transform is left as identity for the caller. A failure leaves nothing behind."""
    data = blender_splats.new_blender_splat_data(name, cloud)
    obj = None
    try:
        obj = bpy.data.objects.new(name, data)
        splat_object.set_up_axis(obj, up_axis)
        obj.raysplats.source_file = source_file
        if compat.points_are_vertices(data):
            # Blender draws a mesh's loose vertices only in Edit Mode: the bounds show where the scene is in Solid
            # view (Rendered view shows the splats; Edit Mode shows every point, to select a region).
            obj.display_type = "BOUNDS"
        link_as_only_selected(context, obj)
    except BaseException:
        if obj is not None:
            bpy.data.objects.remove(obj)
        compat.remove_unused_data(data)
        raise
    return obj
