// Reading the vertex positions of a mesh in Blender's Edit Mode straight from its BMesh.
//
// Why: in Edit Mode the evaluated mesh only wraps the edit BMesh; reading it through bpy (obj.to_mesh(), or touching
// the evaluated mesh's arrays) makes Blender convert the whole BMesh into a Mesh after every move of a few splats, in
// time proportional to the whole mesh. Walking the BMesh's vertex table here costs a small fraction of that per
// vertex (docs/benchmarks.md). The add-on (addon/raysplats/blender/mesh_read.py) finds the BMesh through the bmesh module,
// checks the struct layout below, first on a BMesh of known contents and then on the mesh at hand, against bmesh's
// own Python API before the first read (compat holds the offsets; every read of those checks goes through
// blender_memory.py, where a wrong address is an error, not a crash), and falls back to to_mesh() whenever a check
// fails. This function trusts the address and offsets it is given: nothing else may call it.
//
// The struct fields read (Blender's source/blender/bmesh/bmesh_class.h(h), unchanged from 2.8 to 5.x):
//   BMesh  { int totvert, totedge, totloop, totface; ...; char elem_index_dirty, elem_table_dirty; ...;
//            BMVert **vtable; BMEdge **etable; BMFace **ftable; int vtable_tot, etable_tot, ftable_tot; ... }
//   BMHeader { void *data; int index; char htype, hflag, api_flag; }   (the first member of every element)
//   BMVert { BMHeader head; float co[3]; ... }
//   BMFace { BMHeader head; BMLoop *l_first; int len; ... }
//   BMLoop { BMHeader head; BMVert *v; BMEdge *e; BMFace *f; BMLoop *radial_next, *radial_prev, *next, *prev; }
// Only clean tables are read (elem_table_dirty clear for vertices and faces: every entry points at a live element);
// otherwise it returns "stale" and the caller makes Blender rebuild them.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <atomic>
#include <cstdint>
#include <cstring>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "conversions.h"
#include "raysplats/errors.h"

namespace py = pybind11;
using namespace pybind11::literals;
using namespace raysplats::python;

namespace {

// Offsets (bytes) of the fields read, from the add-on (compat.BMESH_LAYOUT); checked there.
struct BMeshLayout {
    std::size_t totvert, totloop, totface, table_dirty, vtable, ftable, vtable_tot, ftable_tot;
    std::size_t vert_co, face_first_loop, face_len, loop_vert, loop_next;
    int vert_flag, face_flag;  // BM_VERT, BM_FACE: the bits of the dirty flags
};

template <typename T>
T field(const void* base, std::size_t offset) {
    T value;
    std::memcpy(&value, static_cast<const char*>(base) + offset, sizeof(T));
    return value;
}

BMeshLayout layout_of(const py::dict& d) {
    auto get = [&](const char* key) { return d[key].cast<std::size_t>(); };
    return {get("totvert"), get("totloop"), get("totface"), get("elem_table_dirty"),
            get("vtable"), get("ftable"), get("vtable_tot"), get("ftable_tot"), get("vert_co"),
            get("face_first_loop"), get("face_len"), get("loop_vert"), get("loop_next"),
            d["vert_flag"].cast<int>(), d["face_flag"].cast<int>()};
}

// "read": `positions` holds every vertex's position in the order of `corner_vertices`' indices, and the faces are
// exactly `face_corner_start`/`face_corner_count`/`corner_vertices` (the topology the caller had); "topology": the
// BMesh's faces or counts differ from them (an edit added, removed or reconnected elements); "stale": its tables are
// not up to date (the caller refreshes them through bmesh and tries again).
const char* read_edit_mesh_positions(std::uintptr_t bmesh_address, const py::dict& layout_dict,
                                     py::array_t<float, py::array::c_style>& positions,
                                     const IntArray& corner_vertices, const IntArray& face_corner_start,
                                     const IntArray& face_corner_count) {
    if (bmesh_address == 0) throw raysplats::InvalidArgument("read_edit_mesh_positions: no BMesh (address 0)");
    const BMeshLayout L = layout_of(layout_dict);
    const py::ssize_t vertex_count = require_shape(positions, "positions", {kAnySize, 3});
    const py::ssize_t corner_count = require_shape(corner_vertices, "corner_vertices", {kAnySize});
    const py::ssize_t face_count = require_shape(face_corner_start, "face_corner_start", {kAnySize});
    require_shape(face_corner_count, "face_corner_count", {face_count});
    const void* bm = reinterpret_cast<const void*>(bmesh_address);
    if (field<int>(bm, L.totvert) != vertex_count || field<int>(bm, L.totloop) != corner_count ||
        field<int>(bm, L.totface) != face_count)
        return "topology";
    if (field<char>(bm, L.table_dirty) & (L.vert_flag | L.face_flag)) return "stale";
    const auto* const* vtable = field<const char* const*>(bm, L.vtable);
    const auto* const* ftable = field<const char* const*>(bm, L.ftable);
    if ((vertex_count && (!vtable || field<int>(bm, L.vtable_tot) < vertex_count)) ||
        (face_count && (!ftable || field<int>(bm, L.ftable_tot) < face_count)))
        return "stale";

    float* out = positions.mutable_data();
    const std::int32_t* corners = corner_vertices.data();
    const std::int32_t* starts = face_corner_start.data();
    const std::int32_t* counts = face_corner_count.data();
    std::atomic<bool> same_topology{true};
    {
        py::gil_scoped_release release;
        // Vertex i is the table's entry i. The faces are checked against the caller's corners by the vertex each loop
        // points at (a pointer compare with the table entry the corner names: no read of the vertex itself), so the
        // elements' own indices are not needed, and a flipped, deleted or added face is found whatever the counts.
        tbb::parallel_for(tbb::blocked_range<py::ssize_t>(0, vertex_count, 1 << 15), [&](const auto& range) {
            for (py::ssize_t i = range.begin(); i != range.end(); ++i)
                std::memcpy(out + 3 * i, vtable[i] + L.vert_co, 3 * sizeof(float));
        });
        tbb::parallel_for(tbb::blocked_range<py::ssize_t>(0, face_count, 1 << 13), [&](const auto& range) {
            for (py::ssize_t f = range.begin(); f != range.end() && same_topology; ++f) {
                const char* face = ftable[f];
                const int len = field<int>(face, L.face_len);
                const std::int64_t start = starts[f];
                if (len != counts[f] || start < 0 || start + len > corner_count) {
                    same_topology = false;
                    return;
                }
                const char* loop = field<const char*>(face, L.face_first_loop);
                for (int k = 0; k < len; ++k) {
                    const std::int32_t vertex = corners[start + k];
                    if (vertex < 0 || vertex >= vertex_count || field<const char*>(loop, L.loop_vert) != vtable[vertex]) {
                        same_topology = false;
                        return;
                    }
                    loop = field<const char*>(loop, L.loop_next);
                }
            }
        });
    }
    return same_topology ? "read" : "topology";
}

}  // namespace

void register_edit_mesh(py::module_& m) {
    m.def("read_edit_mesh_positions", &read_edit_mesh_positions, "bmesh_address"_a, "layout"_a, py::arg("positions").noconvert(),
          "corner_vertices"_a, "face_corner_start"_a, "face_corner_count"_a,
          "Fills `positions` (float32, one row per vertex) from the BMesh of a mesh in Edit Mode at `bmesh_address`, "
          "whose struct offsets `layout` gives, when its faces are exactly the corner arrays given: returns 'read'; "
          "'topology' when they differ (read the mesh in full), 'stale' when its element tables need refreshing "
          "first. The caller must have checked the layout on this BMesh (blender/mesh_read.py).");
}
