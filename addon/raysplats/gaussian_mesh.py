# The Blender side of the polygon bridge (DESIGN §5): writes the native core's polygon arrays into a Mesh
# with bulk foreach_set, and reads any (evaluated) mesh back into arrays for recovery (foreach_get, or the
# attributes and loop array behind it where they are faster: see read_corner_vertices).
import ctypes

import bpy
import numpy as np

# Face-domain attributes of a Gaussian mesh. SH coefficient k (k = 0 is the DC term) lives in "gs_sh_<k>";
# coefficients k >= 1 are in the face's local frame.
ATTR_OPACITY = "gs_opacity"
ATTR_THICKNESS = "gs_thickness"
ATTR_SH_PREFIX = "gs_sh_"
# The Gaussian each face was made from; lets unedited faces export bit-exactly (see polygon_bridge.h).
ATTR_REST_CENTER = "gs_rest_center"
ATTR_REST_ROTATION = "gs_rest_rotation"  # quaternion w, x, y, z stored as a 4-float colour attribute
ATTR_REST_SCALE = "gs_rest_scale"
# Corner domain: display colour (linear RGB from the SH DC term, A = opacity) and local polygon UVs.
ATTR_COLOR = "gs_color"
UV_MAP = "gs_uv"

_WIDTH_OF = {"FLOAT": 1, "FLOAT_VECTOR": 3, "FLOAT_COLOR": 4}

# Blender before 3.6 keeps corner and edge vertex indices as unsigned ints (MLoop, MEdge): foreach_get/set
# copies them in bulk only with a matching uint32 buffer and otherwise converts element by element (14x
# slower for 12 M corners). From 3.6 on they are int32 attributes. The values always fit in int32.
_INDEX_DTYPE = np.uint32 if bpy.app.version < (3, 6, 0) else np.int32


def _indices_in(values):
    """An index array as Blender's foreach_set takes it fastest (a view, no copy)."""
    return np.ascontiguousarray(values, dtype=np.int32).view(_INDEX_DTYPE)
_PROPERTY_OF = {"FLOAT": "value", "FLOAT_VECTOR": "vector", "FLOAT_COLOR": "color"}


def sh_attribute_name(k):
    return f"{ATTR_SH_PREFIX}{k}"


def _write_attribute(mesh, name, data_type, domain, values):
    attribute = mesh.attributes.get(name) or mesh.attributes.new(name, data_type, domain)
    attribute.data.foreach_set(_PROPERTY_OF[data_type], np.ascontiguousarray(values, dtype=np.float32).ravel())
    return attribute


def _flat_buffer(reuse, size, dtype):
    """A flat array of `size` elements: `reuse` (an earlier result that may be overwritten) when it has that size and
    type, else a new one. The viewport reads the same mesh after every edit; reusing the arrays spares the page
    faults of fresh ones (about 0.2 s per 100 MB)."""
    if reuse is not None and reuse.size == size and reuse.dtype == dtype and reuse.flags.c_contiguous:
        return reuse.reshape(-1)
    return np.empty(size, dtype=dtype)


def _attribute(mesh, name, data_type, domain, count):
    """Attribute `name` of `mesh` when it has this type, domain and number of elements, else None."""
    attribute = mesh.attributes.get(name)
    if attribute is None or attribute.data_type != data_type or attribute.domain != domain \
            or len(attribute.data) != count:
        return None
    return attribute


def _read_attribute(mesh, name, data_type, domain, count, reuse=None):
    attribute = _attribute(mesh, name, data_type, domain, count)
    if attribute is None:
        return None
    width = _WIDTH_OF[data_type]
    out = _flat_buffer(reuse, count * width, np.float32)
    attribute.data.foreach_get(_PROPERTY_OF[data_type], out)
    return out.reshape((count, width)) if width > 1 else out


def fill_mesh(mesh, polygons, cloud):
    """Fills an empty Mesh with the polygons of gaussians_to_polygons() and the per-face attributes."""
    vertex_positions = polygons["vertex_positions"]
    corner_count = len(polygons["corner_vertices"])
    face_count = len(polygons["face_corner_start"])

    mesh.vertices.add(len(vertex_positions))
    mesh.vertices.foreach_set("co", vertex_positions.ravel())
    mesh.edges.add(len(polygons["edge_vertices"]))
    mesh.edges.foreach_set("vertices", _indices_in(polygons["edge_vertices"].ravel()))
    mesh.loops.add(corner_count)
    mesh.loops.foreach_set("vertex_index", _indices_in(polygons["corner_vertices"]))
    mesh.loops.foreach_set("edge_index", _indices_in(polygons["corner_edges"]))
    mesh.polygons.add(face_count)
    mesh.polygons.foreach_set("loop_start", polygons["face_corner_start"])
    try:  # Blender 3.x needs the corner count per face; 4.x derives it from loop_start (read-only there).
        mesh.polygons.foreach_set("loop_total", polygons["face_corner_count"])
    except (AttributeError, TypeError, RuntimeError):
        pass

    _write_attribute(mesh, ATTR_OPACITY, "FLOAT", "FACE", cloud["opacities"])
    _write_attribute(mesh, ATTR_THICKNESS, "FLOAT", "FACE", polygons["thickness"])
    sh_local = polygons["sh_local"]
    for k in range(sh_local.shape[1]):
        _write_attribute(mesh, sh_attribute_name(k), "FLOAT_VECTOR", "FACE", sh_local[:, k, :])
    _write_attribute(mesh, ATTR_REST_CENTER, "FLOAT_VECTOR", "FACE", cloud["positions"])
    _write_attribute(mesh, ATTR_REST_ROTATION, "FLOAT_COLOR", "FACE", cloud["rotations"])
    _write_attribute(mesh, ATTR_REST_SCALE, "FLOAT_VECTOR", "FACE", cloud["scales"])

    color = mesh.color_attributes.new(ATTR_COLOR, "FLOAT_COLOR", "CORNER")
    color.data.foreach_set("color", polygons["corner_colors"].ravel())
    try:
        mesh.color_attributes.active_color = color
        mesh.color_attributes.render_color_index = mesh.color_attributes.active_color_index
    except AttributeError:
        pass
    uv_layer = mesh.uv_layers.new(name=UV_MAP)
    uv_layer.data.foreach_set("uv", polygons["corner_uvs"].ravel())
    mesh.update()


# Reading a Gaussian mesh back was most of the viewport's update after an edit on 4.x. On showroom_1.5M (12 M vertices
# and corners, warm buffers), Blender 4.2: vertices.foreach_get("co") 0.22 s, loops.foreach_get("vertex_index")
# 0.57 s; the same values through the attributes "position" and ".corner_vert" 0.011 s and 0.004 s. Blender 3.4:
# vertices.foreach_get("co") 0.036 s, loops.foreach_get("vertex_index") 0.033 s (into uint32, see _INDEX_DTYPE;
# 0.47 s into int32), a copy straight out of Blender's loop array 0.005 s. So: the attributes where they exist (4.x),
# else the loop array in place (3.x), else foreach_get.
#
# Blender before 3.6 stores a mesh's corners as one array of DNA MLoop {unsigned int v, e;} (8 bytes,
# DNA_meshdata_types.h of 3.4); from 3.6 on the corner vertices are an int32 array of their own (".corner_vert"),
# which MeshLoop.as_pointer() points into (checked on 4.2). Every read checks this layout on the mesh at hand.
_LOOP_STRIDE = 8 if bpy.app.version < (3, 6, 0) else 4
_LOOP_VERTEX_OFFSET = 0  # bytes from the start of a loop element to its vertex index (MLoop.v is the first field)
_CORNER_VERT_ATTRIBUTE = ".corner_vert"
_loop_layout_failed = False  # the check failed once: this Blender lays its loops out otherwise, do not look again
# Faces likewise: before 3.6 an array of DNA MPoly {int loopstart, totloop; ...} (12 bytes, DNA_meshdata_types.h of
# 3.4); from 3.6 on an int32 array of corner offsets (face f's corners are offsets[f] up to offsets[f + 1], the last
# offset is the corner count), which MeshPolygon.as_pointer() points into (both checked on 3.4 and 4.2). After an
# edit of showroom_1.5M, polygons.foreach_get("loop_total") took 0.04 s (3.4) and 0.065 s (4.2); a copy out of the
# array in place a few milliseconds.
_FACE_STRIDE = 12 if bpy.app.version < (3, 6, 0) else 4
_FACE_START_OFFSET = 0  # bytes from the start of a face element to its first corner (MPoly.loopstart; the offset)
_FACE_SIZE_OFFSET = 4 if bpy.app.version < (3, 6, 0) else None  # to MPoly.totloop; None: offsets[f + 1] - offsets[f]
_face_layout_failed = False
_SPOT_CHECKS = 8  # elements whose value in place is compared with RNA's: the first, the last and 6 evenly in between


def read_vertex_positions(mesh, out):
    """Fills `out` (flat float32, 3 per vertex) with the positions of the vertices of `mesh`. Returns how it read
    them: "attribute" or "foreach_get"."""
    attribute = _attribute(mesh, "position", "FLOAT_VECTOR", "POINT", len(mesh.vertices))
    if attribute is not None:
        attribute.data.foreach_get("vector", out)
        return "attribute"
    mesh.vertices.foreach_get("co", out)
    return "foreach_get"


def _field_view(elements, stride, offset, value_of):
    """The 4-byte integer `offset` bytes into each element of the bpy collection `elements`, in place in Blender's
    array (uint32, valid while the mesh is unchanged), or None when the array is not laid out `stride` bytes per
    element or the spot checks find a value other than value_of(element)."""
    count = len(elements)
    first = elements[0].as_pointer()
    # The span is checked before anything is read, so that the view never reaches past Blender's array.
    if stride % 4 or offset % 4 or offset + 4 > stride or elements[1].as_pointer() - first != stride \
            or elements[count - 1].as_pointer() - first != (count - 1) * stride:
        return None
    raw = np.frombuffer((ctypes.c_char * (count * stride)).from_address(first), dtype=np.uint32)
    view = raw.reshape((count, stride // 4))[:, offset // 4]
    spots = np.linspace(0, count - 1, _SPOT_CHECKS).astype(np.int64)
    if any(value_of(elements[int(i)]) != int(view[i]) for i in spots):
        return None
    return view


def _loop_vertex_view(loops):
    """The vertex index of each corner in place in Blender's loop array, or None when the array is not laid out as
    _LOOP_STRIDE and _LOOP_VERTEX_OFFSET say."""
    return _field_view(loops, _LOOP_STRIDE, _LOOP_VERTEX_OFFSET, lambda loop: loop.vertex_index)


def read_corner_vertices(mesh, out):
    """Fills `out` (flat, one _INDEX_DTYPE element per corner of `mesh`) with the vertex of each corner. Returns how it
    read them: "attribute", "pointer" or "foreach_get"."""
    global _loop_layout_failed
    attribute = _attribute(mesh, _CORNER_VERT_ATTRIBUTE, "INT", "CORNER", len(out))
    if attribute is not None:
        attribute.data.foreach_get("value", out.view(np.int32))
        return "attribute"
    if not _loop_layout_failed and len(out) > 1:
        try:
            view = _loop_vertex_view(mesh.loops)
        except Exception:  # the fast path is only an optimisation: whatever went wrong, foreach_get still reads
            view = None
        if view is not None:
            np.copyto(out, view.view(out.dtype))
            return "pointer"
        _loop_layout_failed = True
    mesh.loops.foreach_get("vertex_index", out)
    return "foreach_get"


def _face_views(mesh):
    """(first corner, corner count) of each face of `mesh` (uint32) out of Blender's face array in place (the counts
    computed from the offsets from 3.6 on), or None when the array is not laid out as _FACE_STRIDE, _FACE_START_OFFSET
    and _FACE_SIZE_OFFSET say."""
    faces = mesh.polygons
    starts = _field_view(faces, _FACE_STRIDE, _FACE_START_OFFSET, lambda face: face.loop_start)
    if starts is None:
        return None
    if _FACE_SIZE_OFFSET is not None:
        sizes = _field_view(faces, _FACE_STRIDE, _FACE_SIZE_OFFSET, lambda face: face.loop_total)
        return None if sizes is None else (starts, sizes)
    # The last offset (the corner count) follows the last face's in Blender's array; it is not read from there, so
    # that nothing past the elements checked is read.
    sizes = np.empty(len(starts), dtype=np.uint32)
    np.subtract(starts[1:], starts[:-1], out=sizes[:-1])
    sizes[-1] = len(mesh.loops) - int(starts[-1])
    spots = np.linspace(0, len(sizes) - 1, _SPOT_CHECKS).astype(np.int64)
    if any(faces[int(i)].loop_total != int(sizes[i]) for i in spots):
        return None
    return starts, sizes


def read_face_corners(mesh, sizes=None, starts=None):
    """Fills `sizes` and `starts` (each flat int32, one per face of `mesh`, or None: not wanted) with the number of
    corners of each face and its first corner. Returns how it read them: "pointer" or "foreach_get"."""
    global _face_layout_failed
    if not _face_layout_failed and len(mesh.polygons) > 1:
        try:
            views = _face_views(mesh)
        except Exception:  # the fast path is only an optimisation: whatever went wrong, foreach_get still reads
            views = None
        if views is not None:
            for out, view in ((starts, views[0]), (sizes, views[1])):
                if out is not None:
                    np.copyto(out, view.view(np.int32))
            return "pointer"
        _face_layout_failed = True
    for out, name in ((starts, "loop_start"), (sizes, "loop_total")):
        if out is not None:
            mesh.polygons.foreach_get(name, out)
    return "foreach_get"


def mesh_arrays(mesh, reuse=None, previous=None):
    """Vertex positions, corner vertices, face corner starts and counts of any mesh, as numpy arrays. `reuse`: an
    earlier result whose arrays may be overwritten. `previous`: the arrays of this mesh before an edit; when its
    corners and face sizes are unchanged and its faces were contiguous (as Blender writes every mesh; 4.x stores
    only the offsets), its face starts are taken as they are instead of read again."""
    reuse = reuse or (None,) * 4
    vertex_positions = _flat_buffer(reuse[0], len(mesh.vertices) * 3, np.float32)
    read_vertex_positions(mesh, vertex_positions)
    corner_vertices = _flat_buffer(None if reuse[1] is None else reuse[1].view(_INDEX_DTYPE), len(mesh.loops),
                                   _INDEX_DTYPE)
    read_corner_vertices(mesh, corner_vertices)
    corner_vertices = corner_vertices.view(np.int32)
    face_corner_count = _flat_buffer(reuse[3], len(mesh.polygons), np.int32)
    read_face_corners(mesh, sizes=face_corner_count)
    if previous is not None and np.array_equal(previous[3], face_corner_count) \
            and np.array_equal(previous[1], corner_vertices) and _contiguous(previous[2], previous[3]):
        face_corner_start = previous[2]
    else:
        # (Not into an array `previous` still uses: its starts may be the very array reuse holds.)
        shared = previous is not None and reuse[2] is previous[2]
        face_corner_start = _flat_buffer(None if shared else reuse[2], len(mesh.polygons), np.int32)
        read_face_corners(mesh, starts=face_corner_start)
    return vertex_positions.reshape((-1, 3)), corner_vertices, face_corner_start, face_corner_count


def _contiguous(starts, counts):
    """True when face f's corners follow face f - 1's."""
    return len(starts) == 0 or (starts[0] == 0 and np.array_equal(starts[1:], np.cumsum(counts[:-1])))


def face_attributes(mesh, sh_degree, reuse=None):
    """The stored per-face Gaussian attributes (None where a modifier or edit removed them). `reuse`: an earlier
    result whose arrays may be overwritten."""
    reuse = reuse or {}
    faces = len(mesh.polygons)
    coeffs = (sh_degree + 1) ** 2
    sh_local = _flat_buffer(reuse.get("sh_local"), faces * coeffs * 3, np.float32).reshape((faces, coeffs, 3))
    for k in range(coeffs):
        values = _read_attribute(mesh, sh_attribute_name(k), "FLOAT_VECTOR", "FACE", faces)
        sh_local[:, k, :] = values if values is not None else 0.0
    attributes = {"sh_local": sh_local}
    for key, name, data_type in (("opacity", ATTR_OPACITY, "FLOAT"), ("thickness", ATTR_THICKNESS, "FLOAT"),
                                 ("rest_centers", ATTR_REST_CENTER, "FLOAT_VECTOR"),
                                 ("rest_rotations", ATTR_REST_ROTATION, "FLOAT_COLOR"),
                                 ("rest_scales", ATTR_REST_SCALE, "FLOAT_VECTOR")):
        attributes[key] = _read_attribute(mesh, name, data_type, "FACE", faces, reuse.get(key))
    return attributes


# Blender before 3.6 copies a mesh's vertex, corner and face arrays the first time Python reads them from a mesh that
# only references them (RNA asks for writable arrays: BKE_mesh_verts_for_write and the like), and an object's
# evaluated mesh references the arrays of its evaluated Mesh datablock when nothing changed them. Measured on
# showroom_1.5M after an edit, Blender 3.4: the first read of the evaluated mesh's positions 0.09-0.37 s (46,700 page
# faults: a fresh 192 MB copy), corners 0.08-0.16 s, face sizes 0.05-0.12 s; from the datablock, which owns its
# arrays, 0.04 s each with foreach_get. From 3.6 on meshes share their arrays (implicit sharing) and a read through RNA
# copies them whichever mesh it is read from (4.2: positions 0.07-0.09 s from the evaluated mesh, its datablock or the
# original alike), so there is nothing to gain there.
_EVALUATED_MESH_COPIES_ON_READ = bpy.app.version < (3, 6, 0)
# Parent types that only place their child. Parenting with deformation (Blender's PARSKEL, which RNA calls "ARMATURE"
# or "LATTICE") adds a virtual deform modifier, as shape keys do (BKE_modifiers_get_virtual_modifierlist).
_PLACING_PARENT_TYPES = {"OBJECT", "VERTEX", "VERTEX_3", "BONE"}


def evaluated_mesh(obj, depsgraph):
    """The mesh to read the evaluated geometry of `obj` (an evaluated mesh object, not an instance) from: its evaluated
    mesh, or before Blender 3.6, when evaluation leaves the geometry as it is (Object Mode, no modifiers, no shape
    keys, no deforming parent), its evaluated Mesh datablock: the same data, without the copy a read of the evaluated
    mesh makes."""
    mesh = obj.data
    if not _EVALUATED_MESH_COPIES_ON_READ or obj.original.mode != "OBJECT" or len(obj.modifiers) \
            or (obj.parent is not None and obj.parent_type not in _PLACING_PARENT_TYPES):
        return mesh
    datablock = obj.original.data.evaluated_get(depsgraph)
    if datablock.shape_keys is not None or (len(datablock.vertices), len(datablock.loops), len(datablock.polygons)) \
            != (len(mesh.vertices), len(mesh.loops), len(mesh.polygons)):
        return mesh
    return datablock


def is_gaussian_object(obj):
    return obj is not None and obj.type == "MESH" and getattr(obj, "raysplats", None) is not None \
        and obj.raysplats.is_gaussian


def recover_from_arrays(core, arrays, attributes, settings, mesh_to_output, faces=None):
    """Recovers the Gaussians of mesh_arrays() and face_attributes() of a Gaussian mesh in the space given by
    mesh_to_output (4x4, applied to the mesh's own coordinates); with `faces`, only those (row j is face faces[j]).
    Returns the core's dict."""
    return core.recover_gaussians(
        *arrays, settings.vertices_per_polygon, settings.radius,
        np.ascontiguousarray(mesh_to_output, dtype=np.float64), **attributes, faces=faces)


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
    # avoids the full copy that to_mesh() makes (2.4 s for 1.5 M splats).
    mesh = obj.evaluated_get(depsgraph).data if apply_modifiers else obj.data
    return recover_mesh_gaussians(core, mesh, obj.raysplats, mesh_to_output)
