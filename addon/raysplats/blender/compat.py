# Every fact about how the Blender versions RaySplats supports (3.4 to 5.x, docs/design.md §9) differ, in one place.
# Each name says what differs; its definition says since which version, and the comment why it matters here.
# Callers import these names and never test bpy.app.version or probe the API themselves, so that supporting a new
# Blender means reading this one file.
import bpy
import numpy as np


# The newest Blender the test suite runs on (scripts/test.sh, docs/design.md §9); blender_manifest.toml's
# blender_version_max is one minor version past it. On a newer Blender the facts below that are read out of Blender's
# memory (the BMesh offsets) are found by probes rather than taken from this table (blender/mesh_read.py).
NEWEST_TESTED_BLENDER = (5, 3)
NEWER_THAN_TESTED = tuple(bpy.app.version[:2]) > NEWEST_TESTED_BLENDER


def _since(major, minor):
    return bpy.app.version >= (major, minor, 0)


def _has_property(struct, name):
    """True when the RNA type `struct` (e.g. bpy.types.Camera) has the property `name`."""
    return name in struct.bl_rna.properties


# --- Materials and lights (Cycles) ---------------------------------------------------------------------------------

# Cycles' Principled BSDF v1 (Blender 2.8-3.x) has the principled (Disney) diffuse with roughness-dependent
# retro-reflection; v2 (Blender 4.0) a Lambertian diffuse under an energy-conserving dielectric specular layer, F82-tint
# metal and Specular IOR Level / Specular Tint inputs (native/src/render/bsdf.h models both).
PRINCIPLED_VERSION = "V2" if _since(4, 0) else "V1"

# The native area light emits radiance P / (4 A), Cycles 3.x's convention (kernel/light/area.h: eval_fac =
# 0.25 * invarea). Cycles 4.0 emits P / (pi A) (eval_fac = M_1_PI_F * invarea), so the same power is 4 / pi brighter.
AREA_LIGHT_POWER_SCALE = 4.0 / np.pi if _since(4, 0) else 1.0

# Motion blur's shutter position (Start, Center, End on Frame): Cycles' scene property (Scene.cycles) before 4.2,
# Blender's RenderSettings.motion_blur_position since (EEVEE Next shares it); the switch and the shutter length were
# RenderSettings' already.
MOTION_BLUR_POSITION_IN_RENDER_SETTINGS = _has_property(bpy.types.RenderSettings, "motion_blur_position")

# Blender 4.0 moved the panoramic camera settings (panorama_type, fisheye_fov, latitude_min, ...) from Cycles' camera
# properties onto the Camera itself; before, RaySplats keeps its own copy of them (engine/render_properties.py).
CAMERA_HAS_PANORAMA_SETTINGS = _has_property(bpy.types.Camera, "panorama_type")

# How EEVEE draws a transparent material. Blender 4.2's EEVEE Next replaced Material.blend_method (OPAQUE / CLIP /
# HASHED / BLEND) by surface_render_method (DITHERED / BLENDED), and shadow_method by use_transparent_shadow; 4.2
# keeps blend_method and shadow_method only as deprecated aliases that it no longer uses.
MATERIAL_HAS_SURFACE_RENDER_METHOD = _has_property(bpy.types.Material, "surface_render_method")

# EEVEE's engine identifier: Blender 4.2 to 4.x call EEVEE Next "BLENDER_EEVEE_NEXT" (5.0 names it "BLENDER_EEVEE"
# again).
EEVEE_ENGINE = next(engine for engine in ("BLENDER_EEVEE_NEXT", "BLENDER_EEVEE")
                    if engine in bpy.types.RenderSettings.bl_rna.properties["engine"].enum_items.keys())

# Solid shading's "Attribute" colour (the mesh's active colour attribute) is View3DShading.color_type 'VERTEX' on 3.x
# and 4.x alike (labelled "Attribute" since 3.2).
SOLID_COLOR_TYPE_ATTRIBUTE = "VERTEX"

# --- Mesh storage ---------------------------------------------------------------------------------------------------

# Blender 3.5 stores vertex positions as the generic float3 attribute "position" (before: MVert structs, read
# through vertices.foreach_get("co"), 20x slower on 4.x; see blender/mesh_read.py).
MESH_POSITIONS_ARE_AN_ATTRIBUTE = _since(3, 5)

# Blender 3.6 split a mesh's corner and face structs into int32 arrays of their own: corners were DNA MLoop
# {unsigned int v, e;} (8 bytes, DNA_meshdata_types.h of 3.4), now the ".corner_vert" and ".corner_edge" attributes;
# faces were DNA MPoly {int loopstart, totloop; ...} (12 bytes), now one array of corner offsets (face f's corners are
# offsets[f] up to offsets[f + 1]). MeshLoop.as_pointer() and MeshPolygon.as_pointer() point into these arrays (checked
# on 3.4 and 4.2); blender/mesh_read.py reads them in place and checks the layout on every mesh.
MESH_TOPOLOGY_IN_INT32_ARRAYS = _since(3, 6)
MESH_CORNER_VERTEX_ATTRIBUTE = ".corner_vert"  # from 3.6 on
LOOP_STRIDE = 4 if MESH_TOPOLOGY_IN_INT32_ARRAYS else 8  # bytes per corner element
LOOP_VERTEX_OFFSET = 0  # bytes from a corner element to its vertex index (MLoop.v is the first field)
FACE_STRIDE = 4 if MESH_TOPOLOGY_IN_INT32_ARRAYS else 12  # bytes per face element
FACE_START_OFFSET = 0  # bytes from a face element to its first corner (MPoly.loopstart; the offset itself)
FACE_SIZE_OFFSET = None if MESH_TOPOLOGY_IN_INT32_ARRAYS else 4  # to MPoly.totloop; None: offsets[f + 1] - offsets[f]

# Before 3.6 corner and edge vertex indices are unsigned ints (MLoop, MEdge): foreach_get/set copies them in bulk only
# with a matching uint32 buffer and otherwise converts element by element (14x slower for 12 M corners). From 3.6 on
# they are int32 attributes. The values always fit in int32.
MESH_INDEX_DTYPE = np.int32 if MESH_TOPOLOGY_IN_INT32_ARRAYS else np.uint32

# Writing those arrays: from 3.5 (positions) and 3.6 (edge and corner indices) Mesh.vertices/edges/loops.foreach_set
# sets them element by element through RNA on 4.x and 5.x (most of an import's time), and the attribute holding the
# array takes the same values in bulk, about a hundred times faster (docs/benchmarks.md, Import). Where the attribute
# exists, polygon_mesh.fill_mesh writes it: (collection, property) -> (attribute name, its value key).
MESH_ARRAY_ATTRIBUTES = {("vertices", "co"): ("position", "vector"),
                         ("edges", "vertices"): (".edge_verts", "value"),
                         ("loops", "vertex_index"): (".corner_vert", "value"),
                         ("loops", "edge_index"): (".corner_edge", "value")}

# Where faces are stored as offsets, a face's corner count follows from the next face's start and MeshPolygon.loop_total
# is read-only (4.2); before, it has to be written with the starts.
FACE_CORNER_COUNT_IS_WRITABLE = not bpy.types.MeshPolygon.bl_rna.properties["loop_total"].is_readonly

# Blender before 3.6 copies a mesh's vertex, corner and face arrays the first time Python reads them from a mesh that
# only references them (RNA asks for writable arrays: BKE_mesh_verts_for_write and the like), and an object's
# evaluated mesh references the arrays of its evaluated Mesh datablock when nothing changed them. From 3.6 on meshes
# share their arrays (implicit sharing) and a read through RNA copies them whichever mesh it is read from.
EVALUATED_MESH_COPIES_ON_READ = not _since(3, 6)

# Blender 3.5 stores UV maps as generic 2D float attributes of the corner domain (before: MLoopUV layers only reachable
# through Mesh.uv_layers); reading them as attributes is much faster on 4.x (mesh_read.read_uv_map).
UV_MAPS_ARE_ATTRIBUTES = _since(3, 5)

# Mesh.vertices/edges/polygons.add() select every new element: from 3.4 on in bool attributes of their own (before,
# flag bits in the MVert/MEdge/MPoly structs). A mesh without them has nothing selected.
MESH_SELECTION_ATTRIBUTES = (".select_vert", ".select_edge", ".select_poly")

# --- Blender's own Gaussian splats (5.3) -----------------------------------------------------------------------------

# Blender 5.3 gave PointCloud a type, POINTS ("Points") or GAUSSIAN_SPLAT ("3D Gaussian Splat"), and renders the
# latter as splats from the point attributes its PLY/SPZ importers write (objects/blender_splats.py has the layout). 5.2
# and older have no PointCloud.type. The item is found by its name, so that a renamed identifier is still found: None
# where the feature is missing.
def _native_gaussian_splat_type():
    if not hasattr(bpy.types, "PointCloud") or "type" not in bpy.types.PointCloud.bl_rna.properties:
        return None
    for item in bpy.types.PointCloud.bl_rna.properties["type"].enum_items:
        if "SPLAT" in item.identifier.upper() or "SPLAT" in item.name.upper():
            return item.identifier
    return None


NATIVE_GAUSSIAN_SPLAT_TYPE = _native_gaussian_splat_type()
HAS_NATIVE_GAUSSIAN_SPLATS = NATIVE_GAUSSIAN_SPLAT_TYPE is not None

# Python can add points to a PointCloud only where it has resize() (5.2 on; not in 3.4 to 5.0, where point clouds get
# their points from geometry nodes). resize is an RNA function: it is in bl_rna.functions, and hasattr on the type is
# False for it (only an instance has it as an attribute).
POINTCLOUD_CAN_RESIZE = hasattr(bpy.types, "PointCloud") and "resize" in bpy.types.PointCloud.bl_rna.functions

# Where our splats go as one point per Gaussian (compact objects, Convert > Blender Gaussian Splats): a Gaussian-splat
# point cloud where Blender has one (5.3 on: Workbench, EEVEE and Cycles draw it in Object Mode); before, the vertices
# of a mesh carrying the same point attributes (a mesh's points can be selected in Edit Mode; 5.2's plain point cloud
# would be drawn as dots).
SPLATS_AS_POINT_CLOUD = HAS_NATIVE_GAUSSIAN_SPLATS and POINTCLOUD_CAN_RESIZE


# A splat datablock of points is a PointCloud, or a Mesh whose vertices are the points (where Blender has no splat
# point cloud, and what older files hold). These are the one place that tells the two apart.
def points_are_vertices(data):
    """True for a Mesh whose vertices are the points, False for a PointCloud."""
    return isinstance(data, bpy.types.Mesh)


def points_of(data):
    """The point elements of a splat datablock: a mesh's vertices or a point cloud's points."""
    return data.vertices if points_are_vertices(data) else data.points


def point_count(data):
    return len(points_of(data))


def add_points(data, count):
    """Adds `count` points (zero) at the end of a splat datablock."""
    if points_are_vertices(data):
        data.vertices.add(count)
    else:
        data.resize(point_count(data) + count)


def remove_unused_data(data):
    """Removes a Mesh or PointCloud datablock when no object uses it any more."""
    if data is not None and data.users == 0:
        (bpy.data.meshes if points_are_vertices(data) else bpy.data.pointclouds).remove(data)


def tag_points_changed(data):
    """Tells Blender the points of a splat datablock changed: a mesh recomputes what it derives (Mesh.update); a
    PointCloud has no update(), only the depsgraph tag."""
    if points_are_vertices(data):
        data.update()
    else:
        data.update_tag()

_ATTRIBUTE_TYPES = set(bpy.types.Attribute.bl_rna.properties["data_type"].enum_items.keys())
# Attribute types of the splat layout: 5.3 stores "radiance:base" as a float4 attribute (FLOAT4, a type 5.0 and older
# lack) and "rotation" as a quaternion (QUATERNION since 4.0). Where a type is missing, the same four floats go into a
# FLOAT_COLOR attribute of the same name, which stores them unchanged (no colour management on attributes).
FLOAT4_ATTRIBUTE_TYPE = "FLOAT4" if "FLOAT4" in _ATTRIBUTE_TYPES else "FLOAT_COLOR"
QUATERNION_ATTRIBUTE_TYPE = "QUATERNION" if "QUATERNION" in _ATTRIBUTE_TYPES else "FLOAT_COLOR"
# The foreach_get/foreach_set key of each attribute type's values.
ATTRIBUTE_VALUE_KEY = {"FLOAT": "value", "FLOAT_VECTOR": "vector", "FLOAT_COLOR": "color", "QUATERNION": "value",
                       "FLOAT4": "vector"}

# --- Edit Mode meshes (BMesh) ------------------------------------------------------------------------------------------

# In Edit Mode a mesh lives in a BMesh; reading its positions through bpy makes Blender convert the whole BMesh into a
# Mesh (in time proportional to the whole mesh). blender/mesh_read.py reads them in place instead, at these byte offsets
# (source/blender/bmesh/bmesh_class.h, .hh from 4.0: the same from 2.8 to 5.x), each checked on the BMesh at hand
# against bmesh's Python API before its first read (reading through blender/blender_memory.py, which turns a wrong
# address into an error); any mismatch falls back to the conversion.
BMESH_LAYOUT = {
    "totvert": 0, "totloop": 8, "totface": 12,  # BMesh: int totvert, totedge, totloop, totface
    "elem_table_dirty": 29,  # after 7 ints: char elem_index_dirty, elem_table_dirty
    "vtable": 64, "ftable": 80, "vtable_tot": 88, "ftable_tot": 96,  # after the 4 mempool pointers (32..63)
    "elem_index": 8,  # BMHeader: void *data; int index; char htype, hflag, api_flag
    "vert_co": 16,  # BMVert: BMHeader head; float co[3]
    "face_first_loop": 16, "face_len": 24,  # BMFace: BMHeader head; BMLoop *l_first; int len
    "loop_vert": 16, "loop_next": 56,  # BMLoop: head; BMVert *v; BMEdge *e; BMFace *f; radial_next, radial_prev; next
    "vert_flag": 1, "face_flag": 8,  # BM_VERT, BM_FACE
}
# bmesh's Python objects (source/blender/python/bmesh/bmesh_py_types.h): a Python object header, then BMesh *bm, then
# (for elements) BMElem *ele. The header is PyObject_VAR_HEAD (3 words) up to 5.1 and PyObject_HEAD (2 words) from 5.2
# on (measured: 5.1.2 has the BMesh pointer at 24 bytes, 5.2.3 and 5.3.0 at 16; reading the old offset unchecked
# crashed Blender). mesh_read.probe_bmesh_layout checks them on a known BMesh before any read, and on a Blender newer
# than NEWEST_TESTED_BLENDER searches the other candidates too.
_BPY_HEADER = 2 * 8 if _since(5, 2) else 3 * 8
BPY_BMESH_POINTER_OFFSET = _BPY_HEADER
BPY_BMELEM_POINTER_OFFSET = _BPY_HEADER + 8

# --- Render results -------------------------------------------------------------------------------------------------

# RenderPass.rect.foreach_set copies a float32 buffer into the pass in bulk (640x360 RGBA in 2 ms on 3.4 and half a
# millisecond on 4.2 to 5.3, read back unchanged); assigning `rect` an array goes through Python sequences instead
# (0.09 s on 3.4, 0.1 s on 4.2, 0.4 s on 5.3 for that pass). The length it checks the buffer against differs: from
# 4.2 on, the pass's values (a flat buffer); on 3.4, its first dimension, the pixels (a pixels x channels buffer; a
# flat one is refused). 3.5 to 4.1 were not tried and take 3.4's shape.
RENDER_PASS_BUFFER_IS_FLAT = _since(4, 2)


def set_render_pass(render_pass, values):
    """Writes `values` (pixels bottom row first, `render_pass.channels` float32 each) into a RenderPass."""
    values = np.ascontiguousarray(values, dtype=np.float32)
    render_pass.rect.foreach_set(values.reshape(-1) if RENDER_PASS_BUFFER_IS_FLAT
                                 else values.reshape(-1, render_pass.channels))


# Blender 5.0 renamed render passes (RE_PASSNAME_* in the render pipeline's header): "IndexOB", "IndexMA" and "Env"
# became "Object Index", "Material Index" and "Environment", as Cycles registers them there (measured: Cycles' Render
# Layers node sockets in 3.4 and 5.0; and the light passes' short names, below). The core's film
# table names them as before 5.0.
_LIGHT_PASS_NAMES_5_0 = {"Emit": "Emission", "DiffDir": "Diffuse Direct", "DiffInd": "Diffuse Indirect",
                         "DiffCol": "Diffuse Color", "GlossDir": "Glossy Direct", "GlossInd": "Glossy Indirect",
                         "GlossCol": "Glossy Color", "TransDir": "Transmission Direct",
                         "TransInd": "Transmission Indirect", "TransCol": "Transmission Color"}
RENAMED_RENDER_PASSES = ({"IndexOB": "Object Index", "IndexMA": "Material Index", "Env": "Environment",
                          **_LIGHT_PASS_NAMES_5_0}
                         if _since(5, 0) else {})


def render_pass_name(name):
    """This Blender's name of a render pass the core's film table calls `name`."""
    return RENAMED_RENDER_PASSES.get(name, name)


# --- Compositor ---------------------------------------------------------------------------------------------------

# Blender 5.0 made the scene's compositor a node group of its own (Scene.compositing_node_group), whose Group Output
# is the composited image; before, it is Scene.node_tree (after Scene.use_nodes), whose Composite node is.
COMPOSITOR_IS_NODE_GROUP = _has_property(bpy.types.Scene, "compositing_node_group")


def new_compositor(scene):
    """Gives `scene` a new, empty compositor that renders use: returns (node tree, the input socket whose value is
    the composited image)."""
    if COMPOSITOR_IS_NODE_GROUP:
        tree = bpy.data.node_groups.new("Compositor", "CompositorNodeTree")
        tree.interface.new_socket("Image", in_out="OUTPUT", socket_type="NodeSocketColor")
        scene.compositing_node_group = tree
        return tree, tree.nodes.new("NodeGroupOutput").inputs[0]
    scene.use_nodes = True
    tree = scene.node_tree
    tree.nodes.clear()
    return tree, tree.nodes.new("CompositorNodeComposite").inputs["Image"]


# --- Operators --------------------------------------------------------------------------------------------------------

# bpy.ops.transform.rotate(value=a, orient_axis=X) turns by TRANSFORM_ROTATE_SIGN * a, right-handed about the axis.
# Measured, rotating (1, 0, 0) by 0.7 about global Z: 3.4 to 4.5 give (cos 0.7, -sin 0.7, 0), clockwise seen from +Z;
# 5.0 gives (cos 0.7, +sin 0.7, 0).
TRANSFORM_ROTATE_SIGN = 1.0 if _since(5, 0) else -1.0

# Blender 5.0 first chooses the kind of output, ImageFormatSettings.media_type: only with "MULTI_LAYER_IMAGE" does
# file_format offer "OPEN_EXR_MULTILAYER" (then its only item); before, file_format offers it directly.
IMAGE_FORMAT_HAS_MEDIA_TYPE = _has_property(bpy.types.ImageFormatSettings, "media_type")


def use_multilayer_exr(image_settings):
    """Sets `image_settings` (ImageFormatSettings) to write a multilayer OpenEXR file."""
    if IMAGE_FORMAT_HAS_MEDIA_TYPE:
        image_settings.media_type = "MULTI_LAYER_IMAGE"
    image_settings.file_format = "OPEN_EXR_MULTILAYER"


def use_single_image(image_settings, file_format):
    """Sets `image_settings` to write one image of `file_format` ("PNG", "OPEN_EXR", ...), not a multilayer file
    (from 5.0 on, that is the media type "IMAGE", which a multilayer output before has replaced)."""
    if IMAGE_FORMAT_HAS_MEDIA_TYPE:
        image_settings.media_type = "IMAGE"
    image_settings.file_format = file_format


def prepare_gltf_importer():
    """Blender 3.4's glTF importer calls np.bool, which numpy 1.24 removed (Debian's Blender 3.4 runs with numpy
    1.24; fixed in Blender 3.5): the alias is restored there, so the importer can read a glTF file's meshes."""
    if not _since(3, 5) and "bool" not in np.__dict__:
        np.bool = bool
