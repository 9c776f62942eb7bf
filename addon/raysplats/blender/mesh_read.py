# Fast reads of a mesh's geometry and attributes into numpy arrays: the generic attributes where Blender has them,
# else Blender's own vertex, corner and face arrays read in place through as_pointer() (the layout checked on every
# mesh against compat's facts, with spot checks against RNA), else foreach_get, which always works. Any mesh,
# not only Gaussian meshes: objects/polygon_mesh.py builds on these; nothing here knows the Gaussian attribute schema.
import ctypes

import bpy
import numpy as np

from .. import native
from . import blender_memory, compat

_WIDTH_OF = {"FLOAT": 1, "FLOAT2": 2, "FLOAT_VECTOR": 3, "FLOAT_COLOR": 4}
# The AttributeGroup data property that holds an attribute's values, by data type (foreach_get/foreach_set).
ATTRIBUTE_VALUE_PROPERTY = {"FLOAT": "value", "FLOAT2": "vector", "FLOAT_VECTOR": "vector", "FLOAT_COLOR": "color"}


def flat_buffer(reuse, size, dtype):
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


def read_attribute(mesh, name, data_type, domain, count, reuse=None):
    """The values of attribute `name` (count x width float32, or flat for FLOAT) when `mesh` has it with this type,
    domain and number of elements, else None. `reuse`: an earlier result that may be overwritten."""
    attribute = _attribute(mesh, name, data_type, domain, count)
    if attribute is None:
        return None
    width = _WIDTH_OF[data_type]
    out = flat_buffer(reuse, count * width, np.float32)
    attribute.data.foreach_get(ATTRIBUTE_VALUE_PROPERTY[data_type], out)
    return out.reshape((count, width)) if width > 1 else out


# Reading a Gaussian mesh back was most of the viewport's update after an edit on 4.x, where
# vertices.foreach_get("co") and loops.foreach_get("vertex_index") are 20-140 times slower than the same values
# through the attributes "position" and ".corner_vert"; on 3.4 a copy straight out of Blender's loop array is several
# times faster than foreach_get (which needs uint32, see compat.MESH_INDEX_DTYPE). docs/benchmarks.md,
# Blender-side reads, has the figures. So: the attributes where they exist (4.x), else the loop array in place (3.x),
# else foreach_get.
#
# The byte layouts read in place (compat.LOOP_STRIDE, FACE_STRIDE and their offsets) are checked on the mesh
# at hand before every read; a copy out of the face array in place is about ten times faster than
# polygons.foreach_get("loop_total").
_loop_layout_failed = False  # the check failed once: this Blender lays its loops out otherwise, do not look again
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
    # The spot checks read through blender_memory (an address that is not Blender's array gives an error, not a
    # crash); the first and the last element among them, so that the view below spans checked memory only.
    spots = np.linspace(0, count - 1, _SPOT_CHECKS).astype(np.int64)
    if any(value_of(elements[int(i)]) != blender_memory.uint32_at(first + int(i) * stride + offset) for i in spots):
        return None
    raw = np.frombuffer((ctypes.c_char * (count * stride)).from_address(first), dtype=np.uint32)
    return raw.reshape((count, stride // 4))[:, offset // 4]


def _loop_vertex_view(loops):
    """The vertex index of each corner in place in Blender's loop array, or None when the array is not laid out as
    compat.LOOP_STRIDE and LOOP_VERTEX_OFFSET say."""
    return _field_view(loops, compat.LOOP_STRIDE, compat.LOOP_VERTEX_OFFSET,
                       lambda loop: loop.vertex_index)


def read_corner_vertices(mesh, out):
    """Fills `out` (flat, one compat.MESH_INDEX_DTYPE element per corner of `mesh`) with the vertex of each
    corner. Returns how it read them: "attribute", "pointer" or "foreach_get"."""
    global _loop_layout_failed
    attribute = _attribute(mesh, compat.MESH_CORNER_VERTEX_ATTRIBUTE, "INT", "CORNER", len(out))
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
        blender_memory.warn_fallback("Reading a mesh's corners",
                                     "its loop array is not laid out as compat.LOOP_STRIDE says")
    mesh.loops.foreach_get("vertex_index", out)
    return "foreach_get"


def _face_views(mesh):
    """(first corner, corner count) of each face of `mesh` (uint32) out of Blender's face array in place (the counts
    computed from the offsets from 3.6 on), or None when the array is not laid out as compat.FACE_STRIDE,
    FACE_START_OFFSET and FACE_SIZE_OFFSET say."""
    faces = mesh.polygons
    starts = _field_view(faces, compat.FACE_STRIDE, compat.FACE_START_OFFSET,
                         lambda face: face.loop_start)
    if starts is None:
        return None
    if compat.FACE_SIZE_OFFSET is not None:
        sizes = _field_view(faces, compat.FACE_STRIDE, compat.FACE_SIZE_OFFSET,
                            lambda face: face.loop_total)
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
        blender_memory.warn_fallback("Reading a mesh's faces",
                                     "its face array is not laid out as compat.FACE_STRIDE says")
    for out, name in ((starts, "loop_start"), (sizes, "loop_total")):
        if out is not None:
            mesh.polygons.foreach_get(name, out)
    return "foreach_get"


# Why evaluated_mesh (see compat.EVALUATED_MESH_COPIES_ON_READ): on Blender 3.4 the first read of an evaluated
# mesh after an edit makes a fresh copy of each array (page faults and all), while the datablock owns its arrays and
# reads them as they are. From 3.6 on a read through RNA copies the arrays whichever mesh it is read from (the
# evaluated mesh, its datablock or the original alike), so there is nothing to gain there. docs/benchmarks.md,
# Blender-side reads, has the figures.
# Parent types that only place their child. Parenting with deformation (Blender's PARSKEL, which RNA calls "ARMATURE"
# or "LATTICE") adds a virtual deform modifier, as shape keys do (BKE_modifiers_get_virtual_modifierlist).
_PLACING_PARENT_TYPES = {"OBJECT", "VERTEX", "VERTEX_3", "BONE"}


def places_only(obj):
    """True when `obj`'s parent (if any) only places it: no deforming parent's virtual modifier changes its geometry."""
    return obj.parent is None or obj.parent_type in _PLACING_PARENT_TYPES


def evaluated_mesh(obj, depsgraph):
    """The mesh to read the evaluated geometry of `obj` (an evaluated mesh object, not an instance) from: its evaluated
    mesh, or before Blender 3.6, when evaluation leaves the geometry as it is (Object Mode, no modifiers, no shape
    keys, no deforming parent), its evaluated Mesh datablock: the same data, without the copy a read of the evaluated
    mesh makes."""
    mesh = obj.data
    if not compat.EVALUATED_MESH_COPIES_ON_READ or obj.original.mode != "OBJECT" or len(obj.modifiers) \
            or not places_only(obj):
        return mesh
    datablock = obj.original.data.evaluated_get(depsgraph)
    if datablock.shape_keys is not None or (len(datablock.vertices), len(datablock.loops), len(datablock.polygons)) \
            != (len(mesh.vertices), len(mesh.loops), len(mesh.polygons)):
        return mesh
    return datablock


def read_uv_map(mesh, name):
    """The UV map `name` of `mesh` (corners x 2 float32), or None without it: through the generic float2 attribute
    where UV maps are one (compat.UV_MAPS_ARE_ATTRIBUTES; on showroom_1.5M, Blender 4.2, about 10x faster than
    uv_layers[...].data.foreach_get("uv")), else through the UV layer."""
    if compat.UV_MAPS_ARE_ATTRIBUTES:
        values = read_attribute(mesh, name, "FLOAT2", "CORNER", len(mesh.loops))
        if values is not None:
            return values
    uv_layer = mesh.uv_layers.get(name)
    if uv_layer is None:
        return None
    uvs = np.empty(len(mesh.loops) * 2, dtype=np.float32)
    uv_layer.data.foreach_get("uv", uvs)
    return uvs.reshape(-1, 2)


def write_bytes_in_place(elements, values):
    """Copies `values` (count x 4 uint8) straight into the array behind the bpy collection `elements` (a byte colour
    attribute's data: r, g, b, a bytes per element, as Blender 3.4 to 5.x store them) without the float array
    foreach_set would need (16 bytes a corner). Checks first that the elements are 4 bytes apart and span exactly the
    values and that the bytes there, read safely, are the colours RNA (color_srgb) reports; after the copy, that the
    values read back through RNA are the ones written. False (nothing trustworthy written: the caller writes through
    foreach_set) when a check fails."""
    count = len(elements)
    if count != len(values) or values.dtype != np.uint8 or values.shape[1:] != (4,):
        return False
    if count == 0:
        return True
    try:
        first = elements[0].as_pointer()
        if count > 1 and (elements[1].as_pointer() - first != 4 or elements[count - 1].as_pointer() - first
                          != 4 * (count - 1)):
            return False
        spots = np.linspace(0, count - 1, _SPOT_CHECKS).astype(np.int64)
        for i in spots:  # (the first and the last element among them: the copy stays within checked memory)
            now = np.frombuffer(blender_memory.read(first + 4 * int(i), 4), dtype=np.uint8)
            if not np.allclose(tuple(elements[int(i)].color_srgb), now / 255.0, atol=1e-6):
                return False
        np.copyto(np.frombuffer((ctypes.c_char * (4 * count)).from_address(first), dtype=np.uint8),
                  np.ascontiguousarray(values).reshape(-1))
        return all(np.allclose(tuple(elements[int(i)].color_srgb), values[i] / 255.0, atol=1e-6) for i in spots)
    except Exception:  # the fast path is only an optimisation: foreach_set still writes
        return False


# --- Edit Mode --------------------------------------------------------------------------------------------------------
# In Edit Mode the evaluated mesh wraps the edit BMesh; reading its arrays through bpy, or obj.to_mesh(), makes Blender
# convert the whole BMesh into a Mesh, in time proportional to the whole mesh after every move of a few splats
# (docs/benchmarks.md). The native core walks the BMesh's vertex and face tables in place instead
# (read_edit_mesh_positions, at the byte offsets compat.BMESH_LAYOUT gives). Nothing is read there before two checks,
# each reading through blender_memory (a wrong address is an error, not a crash) and comparing with bmesh's own Python
# API: the probe, once a session, on a small BMesh of known contents (every field the native reader uses, and where
# bmesh's Python objects hold their pointers); then each BMesh at hand, on a few of its elements. Only the positions are
# read: the topology must be the one the caller had (checked corner by corner), and face attributes are taken as
# unchanged (Edit Mode's tools move vertices; an attribute set in Edit Mode reaches the render when Edit Mode is left).
_bmesh_layout_failed = False  # a check failed once: this Blender lays its BMesh out otherwise; do not look again
_bmesh_checked = set()  # addresses of the BMeshes whose layout was checked (a new one each time Edit Mode is entered)
_bmesh_offsets = None  # what the probe found: (BMesh pointer, element pointer) offsets in bmesh's Python objects


def _pointer_at(address):
    return blender_memory.pointer_at(address)


def _int_at(address):
    return blender_memory.int_at(address)


def _bmesh_layout_holds(bm, address, element):
    """True when the BMesh at `address` (bmesh's `bm`, element tables ensured) is laid out as BMESH_LAYOUT says: its
    counts, and for a few vertices and faces their table entries, indices, positions, face sizes and loop links, match
    what bmesh's Python API says. `element`: the offset of the element pointer in bmesh's element objects. Every read
    is a safe one (MemoryUnreadable for an address that is not mapped)."""
    layout = compat.BMESH_LAYOUT
    if (_int_at(address + layout["totvert"]), _int_at(address + layout["totface"])) != (len(bm.verts), len(bm.faces)):
        return False
    if not len(bm.verts) or not len(bm.faces):
        return False
    vtable, ftable = _pointer_at(address + layout["vtable"]), _pointer_at(address + layout["ftable"])
    if not vtable or not ftable or _int_at(address + layout["vtable_tot"]) < len(bm.verts) \
            or _int_at(address + layout["ftable_tot"]) < len(bm.faces):
        return False
    for i in np.linspace(0, len(bm.verts) - 1, _SPOT_CHECKS).astype(np.int64):
        vert = bm.verts[int(i)]
        pointer = _pointer_at(vtable + 8 * int(i))
        if pointer == 0 or pointer != _pointer_at(id(vert) + element) \
                or _int_at(pointer + layout["elem_index"]) != vert.index:
            return False
        if blender_memory.floats_at(pointer + layout["vert_co"], 3) != tuple(vert.co):
            return False
    for j in np.linspace(0, len(bm.faces) - 1, _SPOT_CHECKS).astype(np.int64):
        face = bm.faces[int(j)]
        pointer = _pointer_at(ftable + 8 * int(j))
        if pointer == 0 or pointer != _pointer_at(id(face) + element) \
                or _int_at(pointer + layout["face_len"]) != len(face.loops):
            return False
        loop = _pointer_at(pointer + layout["face_first_loop"])
        for face_loop in face.loops:
            vert = face_loop.vert  # (held: the address of a temporary's element would be read after it is freed)
            if loop == 0 or loop != _pointer_at(id(face_loop) + element) \
                    or _pointer_at(loop + layout["loop_vert"]) != _pointer_at(id(vert) + element):
                return False
            loop = _pointer_at(loop + layout["loop_next"])
    return True


def _bmesh_offset_candidates():
    """(BMesh pointer, element pointer) offsets to try in bmesh's Python objects: compat's on a Blender that was
    tested; on a newer one also every other word of the first 64 bytes (the object header changed size once, in
    5.2), the element pointer always the word after the BMesh pointer (BPy_BMElem: header, BMesh *bm, BMElem *ele)."""
    table = (compat.BPY_BMESH_POINTER_OFFSET, compat.BPY_BMELEM_POINTER_OFFSET)
    if not compat.NEWER_THAN_TESTED:
        return [table]
    return [table] + [(offset, offset + 8) for offset in range(8, 64, 8) if offset != table[0]]


def _known_bmesh_holds(bm, address, element):
    """The probe's checks on `bm`, the known BMesh of probe_bmesh_layout, at `address`: _bmesh_layout_holds, the corner
    count, and the table flags the native reader relies on (clear after ensure_lookup_table, the vertex flag set by a
    new vertex)."""
    layout = compat.BMESH_LAYOUT
    dirty = address + layout["elem_table_dirty"]
    tables = layout["vert_flag"] | layout["face_flag"]
    if not _bmesh_layout_holds(bm, address, element) or blender_memory.byte_at(dirty) & tables \
            or _int_at(address + layout["totloop"]) != sum(len(face.loops) for face in bm.faces):
        return False
    bm.verts.new((9.0, 9.0, 9.0))
    made_dirty = blender_memory.byte_at(dirty) & layout["vert_flag"]
    bm.verts.ensure_lookup_table()
    return bool(made_dirty) and not blender_memory.byte_at(dirty) & tables and _bmesh_layout_holds(bm, address, element)


def probe_bmesh_layout():
    """Where bmesh's Python objects hold their pointers, (BMesh pointer offset, element pointer offset), found on a
    BMesh of known contents (5 vertices, a quad and a triangle) whose every field of compat.BMESH_LAYOUT that the
    native reader uses reads, safely, as bmesh's Python API reports it; None when no candidate holds or this system
    cannot read memory safely."""
    import bmesh

    if not blender_memory.available():
        return None
    bm = bmesh.new()
    try:
        for k in range(5):
            bm.verts.new((0.5 * k, 1.0 - 0.25 * k, 0.125 * k * k))
        bm.verts.ensure_lookup_table()
        bm.faces.new([bm.verts[k] for k in (0, 1, 2, 3)])
        bm.faces.new([bm.verts[k] for k in (1, 4, 2)])
        bm.verts.index_update()
        bm.faces.index_update()
        bm.verts.ensure_lookup_table()
        bm.faces.ensure_lookup_table()
        for bmesh_offset, element_offset in _bmesh_offset_candidates():
            try:
                address = _pointer_at(id(bm) + bmesh_offset)
                if address and address % 8 == 0 and _known_bmesh_holds(bm, address, element_offset):
                    return bmesh_offset, element_offset
            except blender_memory.MemoryUnreadable:
                continue
        return None
    finally:
        bm.free()


def read_edit_mode_positions(mesh, out, corner_vertices, face_corner_start, face_corner_count):
    """Fills `out` (vertices x 3 float32, C-contiguous) with the vertex positions of `mesh` (in Edit Mode) straight from
    its BMesh, when its faces are still exactly the given corner arrays. Returns how it went: "read"; "topology" (the
    faces changed: read the mesh in full); "unavailable" (not in Edit Mode, or the BMesh is not laid out as expected,
    or memory cannot be read safely here: the caller reads through the Python API)."""
    global _bmesh_layout_failed, _bmesh_offsets
    import bmesh

    if _bmesh_layout_failed or not mesh.is_editmode:
        return "unavailable"
    if _bmesh_offsets is None:
        try:
            _bmesh_offsets = probe_bmesh_layout()
        except Exception:  # the fast path is only an optimisation: the caller reads the mesh in full
            _bmesh_offsets = None
        if _bmesh_offsets is None:
            _bmesh_layout_failed = True
            blender_memory.warn_fallback("Reading Edit Mode meshes", f"on Blender {bpy.app.version_string} the BMesh "
                                         "layout probe found no layout that reads as bmesh reports")
            return "unavailable"
    bm = bmesh.from_edit_mesh(mesh)
    # Clean element tables are what the native read relies on; both calls are free while nothing changed them.
    bm.verts.ensure_lookup_table()
    bm.faces.ensure_lookup_table()
    try:
        address = _pointer_at(id(bm) + _bmesh_offsets[0])
        holds = address in _bmesh_checked or _bmesh_layout_holds(bm, address, _bmesh_offsets[1])
    except Exception:  # the fast path is only an optimisation: the caller reads the mesh in full
        holds = False
    if not holds:
        _bmesh_layout_failed = True
        blender_memory.warn_fallback("Reading Edit Mode meshes",
                                     f"the BMesh of '{mesh.name}' does not read as bmesh reports it")
        return "unavailable"
    _bmesh_checked.add(address)
    core = native.core()
    result = core.read_edit_mesh_positions(address, compat.BMESH_LAYOUT, out, corner_vertices,
                                           face_corner_start, face_corner_count)
    if result == "stale":  # (not expected right after ensure_lookup_table, which rebuilds dirty tables)
        bm.verts.ensure_lookup_table()
        bm.faces.ensure_lookup_table()
        result = core.read_edit_mesh_positions(address, compat.BMESH_LAYOUT, out, corner_vertices,
                                               face_corner_start, face_corner_count)
    return "topology" if result != "read" else "read"
