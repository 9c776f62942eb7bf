# File > Export > RaySplats Mesh (.obj/.ply/.gltf/.glb): the scene's Gaussian objects as splat patches (or
# their polygons as they are) and its ordinary meshes with their Principled materials, written by the native
# core (raysplats/mesh_export.h: OpenMesh for OBJ/PLY, tinygltf + Draco for glTF). Glue only: Blender data
# is read in bulk and handed over as arrays.
import os

import bpy
import numpy as np
from bpy.props import BoolProperty, EnumProperty, IntProperty, StringProperty
from bpy_extras.io_utils import ExportHelper

from . import axes, gaussian_mesh, native
from .progress import StageProgress

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


class NothingToExport(ValueError):
    pass


def _principled_values(material):
    """(linear base colour RGBA, metallic, roughness) of a material's Principled BSDF, or of its viewport
    settings when it has none."""
    if material is None:
        return (0.8, 0.8, 0.8, 1.0), 0.0, 0.5
    if material.use_nodes and material.node_tree is not None:
        for node in material.node_tree.nodes:
            if node.type == "BSDF_PRINCIPLED":
                color = tuple(node.inputs["Base Color"].default_value)
                alpha = node.inputs["Alpha"].default_value if "Alpha" in node.inputs else 1.0
                return ((color[0], color[1], color[2], alpha), node.inputs["Metallic"].default_value,
                        node.inputs["Roughness"].default_value)
    return tuple(material.diffuse_color), material.metallic, material.roughness


class _Materials:
    """Blender materials -> indices in the native scene, each added once."""

    def __init__(self, scene):
        self.scene = scene
        self.index = {}

    def of(self, material):
        key = material.name if material is not None else None
        if key not in self.index:
            color, metallic, roughness = _principled_values(material)
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
        positions, corner_vertices, starts, counts = gaussian_mesh.mesh_arrays(mesh)
        colors = uvs = None
        attribute = mesh.color_attributes.get(gaussian_mesh.ATTR_COLOR)
        if attribute is not None and attribute.domain == "CORNER":
            colors = np.empty(len(mesh.loops) * 4, dtype=np.float32)
            attribute.data.foreach_get("color", colors)
        uv_layer = mesh.uv_layers.get(gaussian_mesh.UV_MAP)
        if uv_layer is not None:
            uvs = np.empty(len(mesh.loops) * 2, dtype=np.float32)
            uv_layer.data.foreach_get("uv", uvs)
        scene.add_polygons(name, positions, corner_vertices, starts, counts, corner_colors=colors, corner_uvs=uvs,
                           transform=transform, material=materials.splat_material(), node_matrix=node)
        if not options["gaussian_splatting"]:
            return len(starts)
    cloud = gaussian_mesh.recover_object_gaussians(core, obj, depsgraph, transform, options["apply_modifiers"])
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


def export_mesh_file(context, filepath, use_selection=False, apply_modifiers=True, coordinates="WORLD",
                     up_axis="Y", splat_geometry="PATCHES", include_meshes=True, draco=False,
                     draco_position_bits=14, draco_normal_bits=10, draco_uv_bits=12, draco_compression_level=7,
                     gaussian_splatting=False):
    """Exports the scene's (or the selected) Gaussian objects and meshes; format from the extension.
    Returns the native writer's stats (vertices, triangles, primitives, bytes) plus gaussians and objects."""
    extension = os.path.splitext(filepath)[1].lower()
    if extension not in MESH_EXTENSIONS:
        raise ValueError(f"'{filepath}': unknown mesh format '{extension}'; use .obj, .ply, .gltf or .glb")
    if extension in (".gltf", ".glb"):
        up_axis = "Y"  # glTF is +Y up by specification
    elif draco or gaussian_splatting:
        raise ValueError("Draco compression and KHR_gaussian_splatting are glTF features; use .gltf or .glb")
    objects = list(context.selected_objects if use_selection else context.scene.objects)
    if use_selection and not objects:
        raise NothingToExport("Nothing to export: no objects are selected")
    gaussian_objects = [obj for obj in objects if gaussian_mesh.is_gaussian_object(obj)]
    mesh_objects = [obj for obj in objects if include_meshes and obj.type in MESH_LIKE_TYPES
                    and not gaussian_mesh.is_gaussian_object(obj)]
    if not gaussian_objects and not mesh_objects:
        raise NothingToExport("Nothing to export: " + ("the selection has" if use_selection else "the scene has")
                              + " no Gaussian splat objects or meshes")

    core = native.core()
    scene = core.MeshExportScene()
    materials = _Materials(scene)
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
    return stats


class EXPORT_SCENE_OT_raysplats_mesh(bpy.types.Operator, ExportHelper):
    """Export Gaussian splat objects as mesh patches, with the scene's meshes, to OBJ, PLY, glTF or GLB"""

    bl_idname = "export_scene.raysplats_mesh"
    bl_label = "Export RaySplats Mesh"
    bl_options = {"REGISTER", "PRESET"}

    filename_ext = ".glb"
    check_extension = None  # .obj, .ply, .gltf and .glb are all accepted; the extension picks the format
    filter_glob: StringProperty(default="*.obj;*.ply;*.gltf;*.glb", options={"HIDDEN"})

    use_selection: BoolProperty(name="Selected Only", default=False, description="Export only the selected objects")
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

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        for name in ("use_selection", "apply_modifiers", "coordinates", "up_axis", "splat_geometry", "include_meshes"):
            layout.prop(self, name)
        box = layout.box()
        box.label(text="glTF")
        box.prop(self, "draco")
        column = box.column()
        column.enabled = self.draco
        for name in ("draco_position_bits", "draco_normal_bits", "draco_uv_bits", "draco_compression_level"):
            column.prop(self, name)
        box.prop(self, "gaussian_splatting")

    def execute(self, context):
        keywords = self.as_keywords(ignore=("filepath", "filter_glob", "check_existing"))
        try:
            stats = export_mesh_file(context, self.filepath, **keywords)
        except (native.NativeModuleMissing, RuntimeError, ValueError, OSError) as error:
            self.report({"ERROR"}, f"Export failed: {error}")
            return {"CANCELLED"}
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
