# The Blender side of the polygon bridge (docs/design.md §5): the attribute schema of a Gaussian mesh; writes the native
# core's polygon arrays into a Mesh with bulk foreach_set, and reads any (evaluated) mesh back into arrays for recovery
# (through blender/mesh_read.py, which knows how to read Blender's arrays fast).
import numpy as np

from .. import native
from . import color_adjustment
from ..blender.compat import (FACE_CORNER_COUNT_IS_WRITABLE, MESH_ARRAY_ATTRIBUTES, MESH_INDEX_DTYPE,
                              MESH_SELECTION_ATTRIBUTES, UV_MAPS_ARE_ATTRIBUTES)
from ..blender.mesh_read import (ATTRIBUTE_VALUE_PROPERTY, flat_buffer, read_attribute, read_corner_vertices,
                                 read_face_corners, read_uv_map, read_vertex_positions, write_bytes_in_place)

# Face-domain attributes of a Gaussian mesh. SH coefficient k (k = 0 is the DC term) lives in "gs_sh_<k>";
# coefficients k >= 1 are in the face's local frame.
ATTR_OPACITY = "gs_opacity"
# Written by imports of earlier versions, which stored it; recovery now takes each face's thickness from its rest
# scales where the attribute is missing.
ATTR_THICKNESS = "gs_thickness"
# rho_i, the Mahalanobis radius of the face's polygon: min(rho, sqrt(2 ln(255 a))), where the Gaussian is visible
# (docs/design.md §5). Recovery divides by it; faces without it (faces the user adds: 0) use the object's rho. Imports
# no longer write it: the UV map holds it (the corner at angle 0 is (rho_i, 0)), and face_attributes reads
# it from there (older files with the attribute keep using it).
ATTR_RADIUS = "gs_radius"
ATTR_SH_PREFIX = "gs_sh_"
# The Gaussian each face was made from; lets unedited faces export bit-exactly (see polygon_bridge.h).
ATTR_REST_CENTER = "gs_rest_center"
ATTR_REST_ROTATION = "gs_rest_rotation"  # quaternion w, x, y, z stored as a 4-float colour attribute
ATTR_REST_SCALE = "gs_rest_scale"
# Corner domain: display colour (a byte colour attribute: the SH DC colour as sRGB bytes, which Blender shows as linear
# RGB, A = opacity) and local polygon UVs.
ATTR_COLOR = "gs_color"
UV_MAP = "gs_uv"


def _indices_in(values):
    """An index array as Blender's foreach_set takes it fastest (a view, no copy)."""
    return np.ascontiguousarray(values, dtype=np.int32).view(MESH_INDEX_DTYPE)


def write_mesh_array(mesh, collection, prop, values):
    """mesh.<collection>.foreach_set(prop, values), through the attribute that holds the array where there is one
    (compat.MESH_ARRAY_ATTRIBUTES: a hundred times faster on 4.x)."""
    name, key = MESH_ARRAY_ATTRIBUTES[(collection, prop)]
    attribute = mesh.attributes.get(name)
    if attribute is not None:
        attribute.data.foreach_set(key, values)
    else:
        getattr(mesh, collection).foreach_set(prop, values)


def sh_attribute_name(k):
    return f"{ATTR_SH_PREFIX}{k}"


def _write_attribute(mesh, name, data_type, domain, values):
    attribute = mesh.attributes.get(name) or mesh.attributes.new(name, data_type, domain)
    values = np.ascontiguousarray(values, dtype=np.float32).ravel()
    attribute.data.foreach_set(ATTRIBUTE_VALUE_PROPERTY[data_type], values)
    return attribute


def write_corner_colors(mesh, rgba8):
    """Writes the splat colour attribute (ATTR_COLOR, a byte colour attribute of the corners, made when missing) from
    the core's bytes (corners x 4 uint8: sRGB-encoded RGB, linear A, as Blender stores byte colours; its `.color`
    gives the linear values back): copied straight into Blender's array where it is laid out as bytes, else through
    foreach_set. A float colour attribute of that name (files from before byte colours) is replaced."""
    attribute = mesh.color_attributes.get(ATTR_COLOR)
    if attribute is not None and (attribute.data_type != "BYTE_COLOR" or attribute.domain != "CORNER"):
        mesh.color_attributes.remove(attribute)
        attribute = None
    if attribute is None:
        mesh.color_attributes.new(ATTR_COLOR, "BYTE_COLOR", "CORNER")
    # (Looked up again: adding a layer may move the others, which leaves earlier references dangling.)
    attribute = mesh.color_attributes[ATTR_COLOR]
    if not write_bytes_in_place(attribute.data, rgba8):
        attribute.data.foreach_set("color", native.core().srgb8_to_linear(rgba8).ravel())
    mesh.color_attributes.active_color = attribute
    mesh.color_attributes.render_color_index = mesh.color_attributes.active_color_index


def fill_mesh(mesh, polygons):
    """Fills an empty Mesh with the polygons of gaussians_to_polygons() and their per-face attributes. The arrays are
    taken out of `polygons` (a dict the caller gives up) as Blender copies them, so that each is freed as soon as
    Blender holds its values: the peak memory of an import is the mesh plus what has not been copied yet."""
    take = polygons.pop
    vertex_positions = take("vertex_positions")
    mesh.vertices.add(len(vertex_positions))
    write_mesh_array(mesh, "vertices", "co", vertex_positions.ravel())
    del vertex_positions
    edge_vertices = take("edge_vertices")
    mesh.edges.add(len(edge_vertices))
    write_mesh_array(mesh, "edges", "vertices", _indices_in(edge_vertices.ravel()))
    del edge_vertices
    corner_vertices = take("corner_vertices")
    mesh.loops.add(len(corner_vertices))
    write_mesh_array(mesh, "loops", "vertex_index", _indices_in(corner_vertices))
    del corner_vertices
    write_mesh_array(mesh, "loops", "edge_index", _indices_in(take("corner_edges")))
    face_corner_start = take("face_corner_start")
    mesh.polygons.add(len(face_corner_start))
    mesh.polygons.foreach_set("loop_start", face_corner_start)
    del face_corner_start
    face_corner_count = take("face_corner_count")
    if FACE_CORNER_COUNT_IS_WRITABLE:
        mesh.polygons.foreach_set("loop_total", face_corner_count)
    del face_corner_count
    # Nothing is selected: Blender's add() selects every new element, in bool layers of their own that Edit Mode
    # would start from (all selected); without them nothing is, and each saves 1 byte per vertex, edge and face.
    remove_selection_layers(mesh)

    # (No gs_thickness: recovery computes each face's thickness from its rest scales, docs/design.md §5.)
    polygons.pop("thickness", None)
    _write_attribute(mesh, ATTR_OPACITY, "FLOAT", "FACE", take("opacity"))
    polygons.pop("polygon_radius")  # (no gs_radius: the UV map holds it, see ATTR_RADIUS)
    sh_local = take("sh_local")
    for k in range(sh_local.shape[1]):
        _write_attribute(mesh, sh_attribute_name(k), "FLOAT_VECTOR", "FACE", sh_local[:, k, :])
    del sh_local
    _write_attribute(mesh, ATTR_REST_CENTER, "FLOAT_VECTOR", "FACE", take("rest_centers"))
    _write_attribute(mesh, ATTR_REST_ROTATION, "FLOAT_COLOR", "FACE", take("rest_rotations"))
    _write_attribute(mesh, ATTR_REST_SCALE, "FLOAT_VECTOR", "FACE", take("rest_scales"))

    write_corner_colors(mesh, take("corner_colors"))
    uv_layer = mesh.uv_layers.new(name=UV_MAP)
    uvs = np.ascontiguousarray(take("corner_uvs"), dtype=np.float32).ravel()
    uv_attribute = mesh.attributes.get(UV_MAP) if UV_MAPS_ARE_ATTRIBUTES else None
    if uv_attribute is not None:
        uv_attribute.data.foreach_set(ATTRIBUTE_VALUE_PROPERTY["FLOAT2"], uvs)
    else:
        uv_layer.data.foreach_set("uv", uvs)
    mesh.update()


def remove_selection_layers(mesh):
    """Removes the selection layers of vertices, edges and faces (compat.MESH_SELECTION_ATTRIBUTES): nothing
    selected."""
    for name in MESH_SELECTION_ATTRIBUTES:
        attribute = mesh.attributes.get(name)
        if attribute is not None:
            mesh.attributes.remove(attribute)


def mesh_arrays(mesh, reuse=None, previous=None):
    """Vertex positions, corner vertices, face corner starts and counts of any mesh, as numpy arrays. `reuse`: an
    earlier result whose arrays may be overwritten. `previous`: the arrays of this mesh before an edit; when its
    corners and face sizes are unchanged and its faces were contiguous (as Blender writes every mesh; 4.x stores
    only the offsets), its face starts are taken as they are instead of read again."""
    reuse = reuse or (None,) * 4
    vertex_positions = flat_buffer(reuse[0], len(mesh.vertices) * 3, np.float32)
    read_vertex_positions(mesh, vertex_positions)
    corner_vertices = flat_buffer(None if reuse[1] is None else reuse[1].view(MESH_INDEX_DTYPE), len(mesh.loops),
                                  MESH_INDEX_DTYPE)
    read_corner_vertices(mesh, corner_vertices)
    corner_vertices = corner_vertices.view(np.int32)
    face_corner_count = flat_buffer(reuse[3], len(mesh.polygons), np.int32)
    read_face_corners(mesh, sizes=face_corner_count)
    if previous is not None and np.array_equal(previous[3], face_corner_count) \
            and np.array_equal(previous[1], corner_vertices) and _contiguous(previous[2], previous[3]):
        face_corner_start = previous[2]
    else:
        # (Not into an array `previous` still uses: its starts may be the very array reuse holds.)
        shared = previous is not None and reuse[2] is previous[2]
        face_corner_start = flat_buffer(None if shared else reuse[2], len(mesh.polygons), np.int32)
        read_face_corners(mesh, starts=face_corner_start)
    return vertex_positions.reshape((-1, 3)), corner_vertices, face_corner_start, face_corner_count


def _contiguous(starts, counts):
    """True when face f's corners follow face f - 1's."""
    return len(starts) == 0 or (starts[0] == 0 and np.array_equal(starts[1:], np.cumsum(counts[:-1])))


def face_attributes(mesh, sh_degree, reuse=None):
    """The stored per-face Gaussian attributes (None where a modifier or edit removed them; polygon_radius from the UV
    map where gs_radius is missing). `reuse`: an earlier result whose arrays may be overwritten."""
    reuse = reuse or {}
    faces = len(mesh.polygons)
    coeffs = (sh_degree + 1) ** 2
    sh_local = flat_buffer(reuse.get("sh_local"), faces * coeffs * 3, np.float32).reshape((faces, coeffs, 3))
    for k in range(coeffs):
        values = read_attribute(mesh, sh_attribute_name(k), "FLOAT_VECTOR", "FACE", faces)
        sh_local[:, k, :] = values if values is not None else 0.0
    attributes = {"sh_local": sh_local}
    for key, name, data_type in (("opacity", ATTR_OPACITY, "FLOAT"), ("thickness", ATTR_THICKNESS, "FLOAT"),
                                 ("polygon_radius", ATTR_RADIUS, "FLOAT"),
                                 ("rest_centers", ATTR_REST_CENTER, "FLOAT_VECTOR"),
                                 ("rest_rotations", ATTR_REST_ROTATION, "FLOAT_COLOR"),
                                 ("rest_scales", ATTR_REST_SCALE, "FLOAT_VECTOR")):
        attributes[key] = read_attribute(mesh, name, data_type, "FACE", faces, reuse.get(key))
    # From the splat UVs (which run counter-clockwise on import): "reflected", 1.0 for each face whose corners a
    # reflection reversed (a Mirror modifier, an applied negative scale), whose view-dependent colour recovery
    # reflects (polygon_bridge.h); and each face's rho_i where the mesh has no gs_radius.
    uvs = read_uv_map(mesh, UV_MAP) if faces else None
    if uvs is None:
        attributes["reflected"] = None
    else:
        starts = np.empty(faces, dtype=np.int32)
        counts = np.empty(faces, dtype=np.int32)
        read_face_corners(mesh, sizes=counts, starts=starts)
        attributes["reflected"] = native.core().faces_with_reversed_uvs(uvs, starts, counts)
        from_uvs = native.core().polygon_radius_from_uvs(uvs, starts, counts)
        stored = attributes["polygon_radius"]  # (a join with an older object: 0 on the faces that came without it)
        attributes["polygon_radius"] = from_uvs if stored is None else np.where(stored > 0, stored, from_uvs)
    return attributes


def is_gaussian_object(obj):
    return obj is not None and obj.type == "MESH" and getattr(obj, "raysplats", None) is not None \
        and obj.raysplats.is_gaussian


def scene_pieces(obj):
    """The Gaussian objects of an imported scene: `obj` itself when it is one, or the pieces of a split scene
    (creation.add_gaussian_pieces) when `obj` is their empty, in name order; [] otherwise."""
    if is_gaussian_object(obj):
        return [obj]
    if obj is None or obj.type != "EMPTY":
        return []
    return sorted((child for child in obj.children if is_gaussian_object(child)), key=lambda child: child.name)


def recover_from_arrays(core, arrays, attributes, settings, mesh_to_output, faces=None, adjust_colors=True):
    """Recovers the Gaussians of mesh_arrays() and face_attributes() of a Gaussian mesh in the space given by
    mesh_to_output (4x4, applied to the mesh's own coordinates); with `faces`, only those (row j is face faces[j]).
    With adjust_colors the object's colour adjustments are applied to the SH (what is rendered and exported).
    Returns the core's dict."""
    cloud = core.recover_gaussians(
        *arrays, settings.vertices_per_polygon, settings.radius,
        np.ascontiguousarray(mesh_to_output, dtype=np.float64), **attributes, faces=faces)
    return color_adjustment.adjust_cloud_colors(cloud, settings) if adjust_colors else cloud


def recover_mesh_gaussians(core, mesh, settings, mesh_to_output):
    """Recovers one Gaussian per face of `mesh` (an evaluated Gaussian mesh) in the space given by
    mesh_to_output (4x4, applied to the mesh's own coordinates). Returns the core's dict."""
    return recover_from_arrays(core, mesh_arrays(mesh), face_attributes(mesh, settings.sh_degree), settings,
                               mesh_to_output)


def recover_object_gaussians(core, obj, depsgraph, mesh_to_output, apply_modifiers=True):
    """Recovers the Gaussians of one Gaussian object, evaluated (modifiers, shape keys, armatures) or not."""
    if obj.mode == "EDIT":
        obj.update_from_editmode()
    # The evaluated object's data is the mesh after modifiers, shape keys and deformers; reading it directly
    # avoids the full copy that to_mesh() makes.
    mesh = obj.evaluated_get(depsgraph).data if apply_modifiers else obj.data
    return recover_mesh_gaussians(core, mesh, obj.raysplats, mesh_to_output)
