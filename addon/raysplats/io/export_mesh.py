# File > Export > RaySplats Mesh (.obj/.ply/.gltf/.glb): the scene's Gaussian objects as splat patches (or
# their polygons as they are) and its ordinary meshes with their Principled materials, written by the native
# core (raysplats/mesh_export.h: OpenMesh for OBJ/PLY, tinygltf + Draco for glTF). Glue only: Blender data
# is read in bulk and handed over as arrays.
import os

import bpy
import numpy as np
from bpy.props import BoolProperty, EnumProperty, IntProperty, StringProperty
from bpy_extras.io_utils import ExportHelper

from .. import errors, native
from ..blender import material_reader
from ..objects import axes, polygon_mesh, splat_object
from . import export_scope
from ..progress import StageProgress

MESH_EXTENSIONS = (".obj", ".ply", ".gltf", ".glb")
# Object types Blender can turn into a mesh (evaluated_get(...).to_mesh()).
MESH_LIKE_TYPES = {"MESH", "CURVE", "SURFACE", "FONT", "META"}
SPLAT_MATERIAL_NAME = "RaySplats Gaussian"

COORDINATE_ITEMS = (
    ("WORLD", "World", "Vertices in world coordinates (object transforms applied)"),
    ("LOCAL", "Local", "Vertices in each object's own coordinates; glTF nodes carry the object transforms"),
)
MESH_UP_AXIS_ITEMS = (
    ("Y", "Y up", "+Y up, -Z forward (glTF's convention, always used for .gltf/.glb; most tools' default)"),
    ("Z", "Z up", "Blender's own axes (OBJ and PLY only)"),
)
SPLAT_GEOMETRY_ITEMS = (
    ("PATCHES", "Splat Patches", "Each Gaussian as a fan of triangles around a centre vertex, with the opacity "
                                 "falloff in the vertex alpha and UVs for an alpha texture"),
    ("POLYGONS", "Original Polygons", "The Gaussian objects' polygons as they are in Blender, triangulated"),
)


# The Format drop-down beside the file name (as glTF's exporter has): each format and the extension it writes.
MESH_FORMAT_ITEMS = (
    ("GLB", "glTF Binary (.glb)", "One binary glTF file"),
    ("GLTF", "glTF Separate (.gltf + .bin)", "JSON glTF with its buffers beside it"),
    ("OBJ", "Wavefront OBJ (.obj)", "Triangles with vertex colours (no materials beyond the colours)"),
    ("PLY", "Stanford PLY (.ply)", "Triangles with vertex colours"),
)
MESH_FORMAT_EXTENSIONS = {"GLB": ".glb", "GLTF": ".gltf", "OBJ": ".obj", "PLY": ".ply"}


def mesh_format_of(filepath):
    """The MESH_FORMAT_ITEMS identifier of a file name's extension, or None."""
    extension = os.path.splitext(filepath)[1].lower()
    return next((name for name, ext in MESH_FORMAT_EXTENSIONS.items() if ext == extension), None)


def with_extension(filepath, extension, known_extensions):
    """`filepath` ending in `extension`: its extension replaced when it is one of `known_extensions` (one dot each,
    as MESH_EXTENSIONS; splat files, whose endings may have two, go through format_table.with_splat_extension), anything
    else kept and the extension added."""
    stem, current = os.path.splitext(filepath)
    return (stem if current.lower() in known_extensions else filepath) + extension


class NothingToExport(ValueError):
    pass


def _file_material_values(material, warn):
    """(linear base colour RGBA, metallic, roughness) the mesh files get for a Blender material: what the renderer is
    given (material_reader), in the files' metallic-roughness terms. The files carry no emission, so a surface whose
    only colour is its emission (an Emission shader) is written with the emission colour as base colour, clamped to
    glTF's [0, 1]."""
    values = dict(material_reader.RENDERER_DEFAULTS)
    if material is not None:
        values.update(material_reader.read_material(material, warn)[0])
    color = values["base_color"]
    emission = values["emission_color"]
    if max(color) <= 0.0 and values["emission_strength"] > 0.0 and max(emission) > 0.0:
        color = tuple(min(1.0, max(0.0, c)) for c in emission)
    return (color[0], color[1], color[2], values["alpha"]), values["metallic"], values["roughness"]


class _Materials:
    """Blender materials -> indices in the native scene, each added once."""

    def __init__(self, scene, warn):
        self.scene = scene
        self.warn = warn
        self.index = {}

    def of(self, material):
        key = material.name if material is not None else None
        if key not in self.index:
            color, metallic, roughness = _file_material_values(material, self.warn)
            self.index[key] = self.scene.add_material(
                key or "Default", [float(c) for c in color], float(metallic), float(roughness),
                alpha_blend=color[3] < 1.0, double_sided=material is not None and not material.use_backface_culling)
        return self.index[key]

    def splat_material(self):
        key = ("splats",)
        if key not in self.index:
            self.index[key] = self.scene.add_material(SPLAT_MATERIAL_NAME, [1.0, 1.0, 1.0, 1.0], 0.0, 1.0,
                                                      alpha_blend=True, double_sided=True)
        return self.index[key]


def _matrices(obj, coordinates, up_axis):
    """(vertex transform, node matrix) as float64 4x4: vertex data is always in the output axes; in local
    coordinates the node matrix carries the object transform (conv · world · conv⁻¹)."""
    conv = axes.blender_to_file(up_axis)
    world = axes.world_matrix(obj)
    if coordinates == "WORLD":
        return conv @ world, np.eye(4)
    return conv, conv @ world @ conv.T


def _add_gaussian_object(core, scene, materials, obj, depsgraph, transform, node, options):
    settings = obj.raysplats
    name = obj.name
    if options["splat_geometry"] == "POLYGONS":
        mesh = obj.evaluated_get(depsgraph).data if options["apply_modifiers"] else obj.data
        positions, corner_vertices, starts, counts = polygon_mesh.mesh_arrays(mesh)
        colors = uvs = None
        attribute = mesh.color_attributes.get(polygon_mesh.ATTR_COLOR)
        if attribute is not None and attribute.domain == "CORNER":
            colors = np.empty(len(mesh.loops) * 4, dtype=np.float32)
            attribute.data.foreach_get("color", colors)
        uv_layer = mesh.uv_layers.get(polygon_mesh.UV_MAP)
        if uv_layer is not None:
            uvs = np.empty(len(mesh.loops) * 2, dtype=np.float32)
            uv_layer.data.foreach_get("uv", uvs)
        scene.add_polygons(name, positions, corner_vertices, starts, counts, corner_colors=colors, corner_uvs=uvs,
                           transform=transform, material=materials.splat_material(), node_matrix=node)
        if not options["gaussian_splatting"]:
            return len(starts)
    cloud = polygon_mesh.recover_object_gaussians(core, obj, depsgraph, transform, options["apply_modifiers"])
    scene.add_splats(name, cloud["positions"], cloud["rotations"], cloud["scales"], cloud["opacities"],
                     cloud["sh"], vertices_per_polygon=settings.vertices_per_polygon, radius=settings.radius,
                     material=materials.splat_material(), node_matrix=node,
                     keep_gaussians=options["gaussian_splatting"], patches=options["splat_geometry"] == "PATCHES")
    return len(cloud["opacities"])


def _add_mesh_object(scene, materials, obj, depsgraph, transform, node, apply_modifiers):
    source = obj.evaluated_get(depsgraph) if apply_modifiers else obj
    mesh = source.to_mesh()
    try:
        mesh.calc_loop_triangles()
        triangle_count = len(mesh.loop_triangles)
        if triangle_count == 0:
            return 0
        triangles = np.empty(triangle_count * 3, dtype=np.int32)
        mesh.loop_triangles.foreach_get("vertices", triangles)
        triangle_materials = np.empty(triangle_count, dtype=np.int32)
        mesh.loop_triangles.foreach_get("material_index", triangle_materials)
        positions = np.empty(len(mesh.vertices) * 3, dtype=np.float32)
        mesh.vertices.foreach_get("co", positions)
        normals = np.empty(len(mesh.vertices) * 3, dtype=np.float32)
        mesh.vertices.foreach_get("normal", normals)
        slots = [materials.of(slot.material) for slot in obj.material_slots] or [materials.of(None)]
        scene.add_triangles(obj.name, positions, triangles.view(np.uint32), normals=normals,
                            triangle_materials=triangle_materials, material_slots=slots, transform=transform,
                            node_matrix=node)
        return triangle_count
    finally:
        source.to_mesh_clear()


def export_mesh_file(context, filepath, limit_to=export_scope.DEFAULT_LIMIT_TO, apply_modifiers=True, coordinates="WORLD",
                     up_axis="Y", splat_geometry="PATCHES", include_meshes=True, draco=False,
                     draco_position_bits=14, draco_normal_bits=10, draco_uv_bits=12, draco_compression_level=7,
                     gaussian_splatting=False):
    """Exports the Gaussian objects and meshes export_scope.objects_in_scope(limit_to) gives; format from the extension.
    Returns the native writer's stats (vertices, triangles, primitives, bytes) plus gaussians, objects and warnings
    (what the materials' conversion left out)."""
    extension = os.path.splitext(filepath)[1].lower()
    if extension not in MESH_EXTENSIONS:
        raise ValueError(f"'{filepath}': unknown mesh format '{extension}'; use .obj, .ply, .gltf or .glb")
    if extension in (".gltf", ".glb"):
        up_axis = "Y"  # glTF is +Y up by specification
    elif draco or gaussian_splatting:
        raise ValueError("Draco compression and KHR_gaussian_splatting are glTF features; use .gltf or .glb")
    objects = export_scope.objects_in_scope(context, limit_to)
    if not objects:
        raise NothingToExport(f"Nothing to export: no objects are {export_scope.describe(limit_to)}")
    gaussian_objects = [obj for obj in objects if splat_object.kind_of(obj) == splat_object.POLYGONS]
    # Compact splat objects are points, not surfaces: they export through File > Export > Gaussian Splats (or as
    # polygons after Object > Convert > RaySplats Gaussians).
    mesh_objects = [obj for obj in objects if include_meshes and obj.type in MESH_LIKE_TYPES
                    and not splat_object.is_splat_object(obj)]
    if not gaussian_objects and not mesh_objects:
        raise NothingToExport(f"Nothing to export: no Gaussian splat objects or meshes are "
                              f"{export_scope.describe(limit_to)}")

    core = native.core()
    scene = core.MeshExportScene()
    warnings = []
    materials = _Materials(scene, warnings.append)
    options = {"splat_geometry": splat_geometry, "apply_modifiers": apply_modifiers,
               "gaussian_splatting": gaussian_splatting}
    for obj in gaussian_objects + mesh_objects:
        if obj.mode == "EDIT":
            obj.update_from_editmode()  # edits made in Edit Mode reach the mesh data only through this
    depsgraph = context.evaluated_depsgraph_get()
    gaussians = 0
    with StageProgress(getattr(context, "window_manager", None), "RaySplats mesh export", 2) as progress:
        progress.stage("build meshes")
        for obj in gaussian_objects:
            transform, node = _matrices(obj, coordinates, up_axis)
            gaussians += _add_gaussian_object(core, scene, materials, obj, depsgraph, transform, node, options)
        for obj in mesh_objects:
            transform, node = _matrices(obj, coordinates, up_axis)
            _add_mesh_object(scene, materials, obj, depsgraph, transform, node, apply_modifiers)
        if scene.triangle_count == 0 and not (gaussian_splatting and gaussians):
            raise NothingToExport("Nothing to export: the objects have no faces")
        progress.stage("write file")
        stats = scene.write(filepath, draco=draco, position_bits=draco_position_bits, normal_bits=draco_normal_bits,
                            uv_bits=draco_uv_bits, compression_level=draco_compression_level,
                            gaussian_splatting=gaussian_splatting)
    print(progress.summary())
    stats["gaussians"] = gaussians
    stats["objects"] = len(gaussian_objects) + len(mesh_objects)
    stats["warnings"] = splat_object.export_warnings(gaussian_objects, apply_modifiers) + warnings
    return stats


class EXPORT_SCENE_OT_raysplats_mesh(bpy.types.Operator, ExportHelper):
    """Export Gaussian splat objects as mesh patches, with the scene's meshes, to OBJ, PLY, glTF or GLB"""

    bl_idname = "export_scene.raysplats_mesh"
    bl_label = "Export RaySplats Mesh"
    bl_options = {"REGISTER", "PRESET"}

    filename_ext = ".glb"
    check_extension = None  # .obj, .ply, .gltf and .glb are all accepted; the extension picks the format
    filter_glob: StringProperty(default="*.obj;*.ply;*.gltf;*.glb", options={"HIDDEN"})

    limit_to: EnumProperty(name="Limit to", items=export_scope.LIMIT_TO_ITEMS, default=export_scope.DEFAULT_LIMIT_TO,
                           description="Which objects are exported")
    use_selection: BoolProperty(name="Selected Only", default=False, options={"HIDDEN"},
                                description="Kept for scripts written before Limit to: True exports the selection")
    export_format: EnumProperty(name="Format", items=MESH_FORMAT_ITEMS, default="GLB",
                                description="File format; the file name's extension follows it")
    apply_modifiers: BoolProperty(name="Apply Modifiers", default=True,
                                  description="Export the objects as modifiers, shape keys and armatures leave them")
    coordinates: EnumProperty(name="Coordinates", items=COORDINATE_ITEMS, default="WORLD")
    up_axis: EnumProperty(name="Up Axis", items=MESH_UP_AXIS_ITEMS, default="Y",
                          description="Up direction of OBJ and PLY files (glTF is always +Y up)")
    splat_geometry: EnumProperty(name="Gaussians As", items=SPLAT_GEOMETRY_ITEMS, default="PATCHES")
    include_meshes: BoolProperty(name="Ordinary Meshes", default=True,
                                 description="Also export the meshes, curves and text objects beside the splats")
    draco: BoolProperty(name="Draco Compression", default=False,
                        description="Compress glTF meshes with KHR_draco_mesh_compression")
    draco_position_bits: IntProperty(name="Position Bits", default=14, min=1, max=30,
                                     description="Draco quantisation of positions")
    draco_normal_bits: IntProperty(name="Normal Bits", default=10, min=1, max=30,
                                   description="Draco quantisation of normals")
    draco_uv_bits: IntProperty(name="UV Bits", default=12, min=1, max=30, description="Draco quantisation of UVs")
    draco_compression_level: IntProperty(name="Compression Level", default=7, min=0, max=10,
                                         description="Draco effort: 0 fastest, 10 smallest")
    gaussian_splatting: BoolProperty(name="KHR_gaussian_splatting", default=False,
                                     description="Also write the Gaussians themselves as glTF points with the "
                                                 "KHR_gaussian_splatting extension (release candidate)")

    def check(self, context):
        # The extension follows the Format drop-down (glTF's exporter does the same); True redraws the browser.
        filepath = with_extension(self.filepath, MESH_FORMAT_EXTENSIONS[self.export_format], MESH_EXTENSIONS)
        changed = filepath != self.filepath
        self.filepath = filepath
        return changed

    def invoke(self, context, event):
        self.export_format = mesh_format_of(self.filepath) or self.export_format
        return ExportHelper.invoke(self, context, event)

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        is_gltf = self.export_format in ("GLB", "GLTF")
        for name in ("export_format", "limit_to", "apply_modifiers", "coordinates", "splat_geometry",
                     "include_meshes"):
            layout.prop(self, name)
        if not is_gltf:  # glTF is +Y up by specification: the choice is OBJ's and PLY's only
            layout.prop(self, "up_axis")
            return
        box = layout.box()
        box.label(text="glTF")
        box.prop(self, "draco")
        column = box.column()
        column.enabled = self.draco
        for name in ("draco_position_bits", "draco_normal_bits", "draco_uv_bits", "draco_compression_level"):
            column.prop(self, name)
        box.prop(self, "gaussian_splatting")

    @errors.reports_failures("Export failed: ")
    def execute(self, context):
        keywords = self.as_keywords(ignore=("filepath", "filter_glob", "check_existing", "export_format",
                                            "use_selection"))
        keywords["limit_to"] = export_scope.limit_of(self.limit_to, self.use_selection)
        stats = export_mesh_file(context, self.filepath, **keywords)
        for warning in stats["warnings"]:
            self.report({"WARNING"}, warning)
        self.report({"INFO"}, f"Exported {stats['objects']} objects ({stats['triangles']:,} triangles) to "
                              f"{os.path.basename(self.filepath)}")
        return {"FINISHED"}


def menu_export(self, context):
    self.layout.operator(EXPORT_SCENE_OT_raysplats_mesh.bl_idname, text="RaySplats Mesh (.obj/.ply/.gltf/.glb)")


def register():
    bpy.utils.register_class(EXPORT_SCENE_OT_raysplats_mesh)
    bpy.types.TOPBAR_MT_file_export.append(menu_export)


def unregister():
    bpy.types.TOPBAR_MT_file_export.remove(menu_export)
    bpy.utils.unregister_class(EXPORT_SCENE_OT_raysplats_mesh)
