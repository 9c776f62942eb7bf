// raysplats._native: thin pybind11 bindings over the core. Arrays in are numpy (C-contiguous float32 or
// int32, shapes checked); arrays out are numpy views of the core's vectors (no copies); the GIL is released
// around native work so Blender stays responsive. No logic lives here.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <optional>
#include <string>
#include <vector>

#include "conversions.h"
#include "raysplats/errors.h"
#include "raysplats/gaussian_cloud.h"
#include "raysplats/gaussian_transform.h"
#include "raysplats/gltf_contents.h"
#include "raysplats/memory_budget.h"
#include "raysplats/polygon_bridge.h"
#include "raysplats/spatial_pieces.h"
#include "raysplats/splat_io.h"
#include "raysplats/up_axis.h"

namespace py = pybind11;
using namespace pybind11::literals;
using namespace raysplats::python;

void register_render_bindings(py::module_& m);  // render_bindings.cpp

namespace {

// The splat formats of the core (splat_io.h): list of {name, extensions, description, up_axis, writable}.
py::list splat_formats() {
    py::list out;
    for (const raysplats::SplatFormatInfo& f : raysplats::splat_formats()) {
        py::list extensions;
        for (const char* e : f.extensions) extensions.append(e);
        out.append(py::dict("name"_a = f.name, "extensions"_a = extensions, "description"_a = f.description,
                            "up_axis"_a = f.up_axis, "up_axis_by_specification"_a = f.up_axis_by_specification, "writable"_a = f.writable));
    }
    return out;
}

py::dict estimate_up_axis(const FloatArray& positions, const FloatArray& rotations, const FloatArray& scales,
                          const FloatArray& opacities) {
    const std::size_t n = std::size_t(opacities.size());
    raysplats::GaussianCloud cloud = cloud_from_arrays(positions, rotations, scales, opacities,
                                                       FloatArray(std::vector<py::ssize_t>{py::ssize_t(n), 1, 3}));
    raysplats::UpAxisEstimate e;
    {
        py::gil_scoped_release release;
        e = raysplats::estimate_up_axis(cloud);
    }
    py::dict scores;
    for (std::size_t k = 0; k < 6; ++k) scores[raysplats::UpAxisEstimate::kAxisNames[k]] = e.scores[k];
    return py::dict("axis"_a = e.axis(), "decided"_a = e.decided, "margin"_a = e.margin, "scores"_a = scores,
                    "flat_gaussians"_a = e.flat_gaussians);
}

py::dict read_splats(const std::string& path, float min_opacity, std::size_t max_count) {
    raysplats::LoadReport report;
    raysplats::GaussianCloud cloud;
    {
        py::gil_scoped_release release;
        raysplats::ReadOptions options;
        options.min_opacity = min_opacity;
        options.max_count = max_count;
        cloud = raysplats::read_splat_file(path, options, &report);
    }
    py::dict d = cloud_to_dict(std::move(cloud));
    d["warnings"] = report.warnings;
    return d;
}

void write_splats(const std::string& path, const FloatArray& positions, const FloatArray& rotations,
                  const FloatArray& scales, const FloatArray& opacities, const FloatArray& sh) {
    raysplats::GaussianCloud cloud = cloud_from_arrays(positions, rotations, scales, opacities, sh);
    py::gil_scoped_release release;
    raysplats::write_splat_file(path, cloud);
}

py::dict gaussians_to_polygons(const FloatArray& positions, const FloatArray& rotations, const FloatArray& scales,
                               const FloatArray& opacities, const FloatArray& sh, int vertices_per_polygon, float radius) {
    raysplats::GaussianCloud cloud = cloud_from_arrays(positions, rotations, scales, opacities, sh);
    raysplats::PolygonSettings settings{vertices_per_polygon, radius};
    raysplats::SplatPolygons p;
    {
        py::gil_scoped_release release;
        p = raysplats::gaussians_to_polygons(cloud, settings);
    }
    // One face per visible Gaussian (the others skipped, counted in invisible_skipped).
    const auto n = py::ssize_t(p.face_corner_start.size());
    const auto corners = n * vertices_per_polygon;
    py::dict d;
    d["vertex_positions"] = to_numpy(std::move(p.vertex_positions), {corners, 3});
    d["corner_vertices"] = to_numpy(std::move(p.corner_vertices), {corners});
    d["face_corner_start"] = to_numpy(std::move(p.face_corner_start), {n});
    d["face_corner_count"] = to_numpy(std::move(p.face_corner_count), {n});
    d["edge_vertices"] = to_numpy(std::move(p.edge_vertices), {corners, 2});
    d["corner_edges"] = to_numpy(std::move(p.corner_edges), {corners});
    d["thickness"] = to_numpy(std::move(p.thickness), {n});
    d["sh_local"] = to_numpy(std::move(p.sh_local), {n, py::ssize_t(cloud.coeffs_per_channel()), 3});
    d["corner_colors"] = to_numpy(std::move(p.corner_colors), {corners, 4});  // uint8: a byte colour attribute's
    d["corner_uvs"] = to_numpy(std::move(p.corner_uvs), {corners, 2});
    d["polygon_radius"] = to_numpy(std::move(p.polygon_radius), {n});
    d["opacity"] = to_numpy(std::move(p.opacity), {n});
    d["rest_centers"] = to_numpy(std::move(p.rest_centers), {n, 3});
    d["rest_rotations"] = to_numpy(std::move(p.rest_rotations), {n, 4});
    d["rest_scales"] = to_numpy(std::move(p.rest_scales), {n, 3});
    d["invisible_skipped"] = p.invisible_skipped;
    return d;
}

raysplats::PolygonMeshView mesh_view_of(const FloatArray& vertex_positions, const IntArray& corner_vertices,
                                        const IntArray& face_corner_start, const IntArray& face_corner_count) {
    raysplats::PolygonMeshView mesh;
    mesh.vertex_count = std::size_t(require_shape(vertex_positions, "vertex_positions", {kAnySize, 3}));
    mesh.vertex_positions = vertex_positions.data();
    mesh.corner_count = std::size_t(require_shape(corner_vertices, "corner_vertices", {kAnySize}));
    mesh.corner_vertices = corner_vertices.data();
    const py::ssize_t faces = require_shape(face_corner_start, "face_corner_start", {kAnySize});
    require_shape(face_corner_count, "face_corner_count", {faces});
    mesh.face_corner_start = face_corner_start.data();
    mesh.face_corner_count = face_corner_count.data();
    mesh.face_count = std::size_t(faces);
    return mesh;
}

py::array_t<std::uint32_t> faces_with_moved_vertices(const FloatArray& previous_positions, const FloatArray& vertex_positions,
                                                     const IntArray& corner_vertices, const IntArray& face_corner_start,
                                                     const IntArray& face_corner_count) {
    const raysplats::PolygonMeshView mesh = mesh_view_of(vertex_positions, corner_vertices, face_corner_start, face_corner_count);
    require_shape(previous_positions, "previous_positions", {py::ssize_t(mesh.vertex_count), 3});
    std::vector<std::uint32_t> faces;
    {
        py::gil_scoped_release release;
        faces = raysplats::faces_with_moved_vertices(mesh, previous_positions.data());
    }
    const py::ssize_t n = py::ssize_t(faces.size());
    return to_numpy(std::move(faces), {n});
}

py::array_t<std::uint32_t> rows_that_differ(const FloatArray& previous, const FloatArray& current) {
    if (previous.ndim() < 1)
        throw raysplats::InvalidArgument("array 'previous' has shape () but (N,...) was expected");
    bool same = previous.ndim() == current.ndim();
    for (py::ssize_t d = 0; same && d < previous.ndim(); ++d) same = previous.shape(d) == current.shape(d);
    if (!same)
        throw raysplats::InvalidArgument("array 'current' has shape " + shape_text(current) + " but " +
                                         shape_text(previous) + " (the shape of 'previous') was expected");
    const std::size_t rows = std::size_t(previous.shape(0));
    const std::size_t width = rows ? std::size_t(previous.size()) / rows : 0;
    std::vector<std::uint32_t> changed;
    {
        py::gil_scoped_release release;
        changed = raysplats::rows_that_differ(previous.data(), current.data(), rows, width);
    }
    const py::ssize_t n = py::ssize_t(changed.size());
    return to_numpy(std::move(changed), {n});
}

// The faces and corners of a mesh whose corner UVs are given (no vertices): what the per-face UV readers take.
raysplats::PolygonMeshView uv_mesh_view(const FloatArray& corner_uvs, const IntArray& face_corner_start,
                                        const IntArray& face_corner_count) {
    raysplats::PolygonMeshView mesh;
    mesh.corner_count = std::size_t(require_shape(corner_uvs, "corner_uvs", {kAnySize, 2}));
    const py::ssize_t faces = require_shape(face_corner_start, "face_corner_start", {kAnySize});
    require_shape(face_corner_count, "face_corner_count", {faces});
    mesh.face_corner_start = face_corner_start.data();
    mesh.face_corner_count = face_corner_count.data();
    mesh.face_count = std::size_t(faces);
    return mesh;
}

py::array_t<float> faces_with_reversed_uvs(const FloatArray& corner_uvs, const IntArray& face_corner_start,
                                           const IntArray& face_corner_count) {
    const raysplats::PolygonMeshView mesh = uv_mesh_view(corner_uvs, face_corner_start, face_corner_count);
    const py::ssize_t faces = py::ssize_t(mesh.face_count);
    std::vector<float> reversed;
    {
        py::gil_scoped_release release;
        reversed = raysplats::faces_with_reversed_uvs(mesh, corner_uvs.data());
    }
    return to_numpy(std::move(reversed), {faces});
}

py::array_t<float> polygon_radius_from_uvs(const FloatArray& corner_uvs, const IntArray& face_corner_start,
                                           const IntArray& face_corner_count) {
    const raysplats::PolygonMeshView mesh = uv_mesh_view(corner_uvs, face_corner_start, face_corner_count);
    const py::ssize_t faces = py::ssize_t(mesh.face_count);
    std::vector<float> radius;
    {
        py::gil_scoped_release release;
        radius = raysplats::polygon_radius_from_uvs(mesh, corner_uvs.data());
    }
    return to_numpy(std::move(radius), {faces});
}

py::dict transform_gaussians(const FloatArray& positions, const FloatArray& rotations, const FloatArray& scales,
                             const FloatArray& opacities, const FloatArray& sh, const DoubleArray& matrix) {
    require_shape(matrix, "matrix", {4, 4});
    raysplats::GaussianCloud cloud = cloud_from_arrays(positions, rotations, scales, opacities, sh);
    {
        py::gil_scoped_release release;
        cloud = raysplats::transform_gaussians(cloud, matrix.data());
    }
    return cloud_to_dict(std::move(cloud));
}

py::dict recover_gaussians(const FloatArray& vertex_positions, const IntArray& corner_vertices,
                           const IntArray& face_corner_start, const IntArray& face_corner_count,
                           int vertices_per_polygon, float radius, const DoubleArray& mesh_to_output,
                           std::optional<FloatArray> opacity, std::optional<FloatArray> thickness,
                           std::optional<FloatArray> polygon_radius, std::optional<FloatArray> sh_local,
                           std::optional<FloatArray> rest_centers,
                           std::optional<FloatArray> rest_rotations, std::optional<FloatArray> rest_scales,
                           std::optional<FloatArray> reflected, std::optional<UintArray> subset) {
    raysplats::PolygonMeshView mesh = mesh_view_of(vertex_positions, corner_vertices, face_corner_start, face_corner_count);
    const py::ssize_t faces = py::ssize_t(mesh.face_count);
    require_shape(mesh_to_output, "mesh_to_output", {4, 4});

    raysplats::SplatFaceAttributesView attr;
    if (opacity) require_shape(*opacity, "opacity", {faces}), attr.opacity = opacity->data();
    if (thickness) require_shape(*thickness, "thickness", {faces}), attr.thickness = thickness->data();
    if (polygon_radius)
        require_shape(*polygon_radius, "polygon_radius", {faces}), attr.polygon_radius = polygon_radius->data();
    if (sh_local) {
        require_shape(*sh_local, "sh_local", {faces, kAnySize, 3});
        attr.sh_degree = sh_degree_from_coefficients(sh_local->shape(1), "sh_local");
        attr.sh_local = sh_local->data();
    }
    if (rest_centers) require_shape(*rest_centers, "rest_centers", {faces, 3}), attr.rest_centers = rest_centers->data();
    if (rest_rotations)
        require_shape(*rest_rotations, "rest_rotations", {faces, 4}), attr.rest_rotations = rest_rotations->data();
    if (rest_scales) require_shape(*rest_scales, "rest_scales", {faces, 3}), attr.rest_scales = rest_scales->data();
    if (reflected) require_shape(*reflected, "reflected", {faces}), attr.reflected = reflected->data();

    raysplats::RecoveryOptions options;
    options.polygon = {vertices_per_polygon, radius};
    std::copy(mesh_to_output.data(), mesh_to_output.data() + 16, options.mesh_to_output);
    raysplats::RecoveryStats stats;
    raysplats::GaussianCloud cloud;
    {
        py::gil_scoped_release release;
        cloud = raysplats::recover_gaussians_from_polygons(mesh, attr, options, &stats, subset ? subset->data() : nullptr,
                                                           subset ? std::size_t(subset->size()) : 0);
    }
    py::dict d = cloud_to_dict(std::move(cloud));
    d["stats"] = py::dict("unedited"_a = stats.unedited, "recovered"_a = stats.recovered, "added"_a = stats.added,
                          "degenerate"_a = stats.degenerate, "dropped"_a = stats.dropped,
                          "invalid_rest_rotation"_a = stats.invalid_rest_rotation,
                          "invalid_rest_scale"_a = stats.invalid_rest_scale);
    return d;
}

}  // namespace

// mesh_export_bindings.cpp
void register_mesh_export(py::module_& m);
// splat_tools_bindings.cpp
void register_splat_tools(py::module_& m);
// edit_mesh_bindings.cpp
void register_edit_mesh(py::module_& m);

PYBIND11_MODULE(_native, m) {
    m.doc() = "RaySplats native core: splat file I/O, the polygon bridge and mesh export (see docs/design.md).";

    auto error = py::register_exception<raysplats::Error>(m, "Error", PyExc_RuntimeError);
    py::register_exception<raysplats::FileFormatError>(m, "FileFormatError", error.ptr());
    py::register_exception<raysplats::InvalidArgument>(m, "InvalidArgument", PyExc_ValueError);

    // The docstrings that list formats take them from the core's format table.
    static const std::string read_doc =
        "Reads a splat file (" + raysplats::splat_endings_text(false, "/") +
        "; the format from its content, else its name). Returns a dict of numpy arrays (positions, rotations wxyz, "
        "linear scales, linear opacities, sh [N, coeffs, 3]), sh_degree and warnings.";
    static const std::string write_doc = "Writes Gaussians atomically; the format comes from the file name's ending (" +
                                         raysplats::splat_endings_text(true) + ").";
    m.def("read_splats", &read_splats, "path"_a, "min_opacity"_a = 0.0f, "max_count"_a = 0, read_doc.c_str());
    m.def("probe_splat_file", [](const std::string& path) {
              const raysplats::SplatFileSummary s = raysplats::probe_splat_file(path);
              return py::dict("format"_a = raysplats::splat_format_name(s.format), "count"_a = s.count,
                              "sh_degree"_a = s.sh_degree);
          }, "path"_a,
          "What a splat file's header says, without reading its data: dict of format, count (splats declared), "
          "sh_degree. Raises FileFormatError like read_splats for a file refused at its header.");
    m.def("import_memory_bytes", &raysplats::import_memory_bytes, "count"_a, "sh_degree"_a, "vertices_per_polygon"_a,
          "Estimated peak bytes of importing count Gaussians as polygons (cloud, polygons, the mesh and its undo copy).");
    m.def("compact_import_memory_bytes", &raysplats::compact_import_memory_bytes, "count"_a, "sh_degree"_a,
          "Estimated peak bytes of importing count Gaussians as a compact splat object (one point per Gaussian).");
    m.def("available_memory_bytes", &raysplats::available_memory_bytes,
          "Bytes that can be allocated without swapping (MemAvailable, within the cgroup limit); 0 if unknown.");
    m.def("write_splats", &write_splats, "path"_a, "positions"_a, "rotations"_a, "scales"_a, "opacities"_a, "sh"_a,
          write_doc.c_str());
    m.def("gaussians_to_polygons", &gaussians_to_polygons, "positions"_a, "rotations"_a, "scales"_a, "opacities"_a,
          "sh"_a, "vertices_per_polygon"_a = 8, "radius"_a = 3.0f,
          "Flat K-gon per visible Gaussian at its radius rho_i = min(rho, sqrt(2 ln(255 a))), with the mesh topology, "
          "face attributes (the Gaussian's rest values, opacity, rho_i) and corner colours/UVs (docs/design.md §5); "
          "invisible_skipped counts the Gaussians with opacity below 1/255, which get no face.");
    m.def("split_into_spatial_pieces", [](const FloatArray& positions, std::size_t max_per_piece) {
              const py::ssize_t n = require_shape(positions, "positions", {kAnySize, 3});
              raysplats::SpatialPieces pieces;
              {
                  py::gil_scoped_release release;
                  pieces = raysplats::split_into_spatial_pieces(positions.data(), std::size_t(n), max_per_piece);
              }
              const py::ssize_t count = py::ssize_t(pieces.starts.size());
              return py::make_tuple(to_numpy(std::move(pieces.order), {n}), to_numpy(std::move(pieces.starts), {count}));
          }, "positions"_a, "max_per_piece"_a,
          "(order, starts): the Gaussians split into spatially compact pieces of at most max_per_piece (a k-d split "
          "of the centres); piece p is order[starts[p]:starts[p + 1]], in file order.");
    m.def("transform_gaussians", &transform_gaussians, "positions"_a, "rotations"_a, "scales"_a, "opacities"_a, "sh"_a,
          "matrix"_a,
          "The Gaussians mapped by an affine 4x4 matrix exactly (centres, covariances A Σ Aᵀ, SH turned by the "
          "matrix's rotation); the identity returns them unchanged.");
    m.def("recover_gaussians", &recover_gaussians, "vertex_positions"_a, "corner_vertices"_a, "face_corner_start"_a,
          "face_corner_count"_a, "vertices_per_polygon"_a, "radius"_a, "mesh_to_output"_a, "opacity"_a = py::none(),
          "thickness"_a = py::none(), "polygon_radius"_a = py::none(), "sh_local"_a = py::none(),
          "rest_centers"_a = py::none(), "rest_rotations"_a = py::none(), "rest_scales"_a = py::none(),
          "reflected"_a = py::none(), "faces"_a = py::none(),
          "Recovers one Gaussian per polygon by moments (docs/design.md §5), in the space of mesh_to_output, dividing "
          "by each face's polygon_radius (rho_i; `radius` where it is missing or 0); faces marked `reflected` (their "
          "corners reversed by a reflection) get their local SH reflected; with `faces`, only those (row j is face "
          "faces[j], bit-identical to a full recovery's).");
    m.def("faces_with_reversed_uvs", &faces_with_reversed_uvs, "corner_uvs"_a, "face_corner_start"_a,
          "face_corner_count"_a,
          "Per face 1.0 where its corner UVs wind clockwise (a reflection reversed its corners), else 0.0.");
    m.def("polygon_radius_from_uvs", &polygon_radius_from_uvs, "corner_uvs"_a, "face_corner_start"_a,
          "face_corner_count"_a, "Per face rho_i read from its polygon UVs (polygon_bridge.h), 0 where none is.");
    m.def("rows_that_differ", &rows_that_differ, "previous"_a, "current"_a,
          "Rows (ascending uint32) in which two float arrays of the same shape differ bit for bit.");
    m.def("faces_with_moved_vertices", &faces_with_moved_vertices, "previous_positions"_a, "vertex_positions"_a,
          "corner_vertices"_a, "face_corner_start"_a, "face_corner_count"_a,
          "Faces (ascending uint32) with a corner on a vertex whose position differs bit for bit from "
          "previous_positions (the same mesh before an edit that kept its topology).");
    m.def("estimate_up_axis", &estimate_up_axis, "positions"_a, "rotations"_a, "scales"_a, "opacities"_a,
          "Which way is up, from the Gaussians alone (raysplats/up_axis.h: the supporting plane of flat Gaussians): "
          "dict of axis ('X', '-X', 'Y', '-Y', 'Z', '-Z'), decided (False: no clear supporting plane), margin "
          "((best - second) / best), scores per axis, flat_gaussians.");
    m.def("gltf_contents", [](const std::string& path) {
              raysplats::GltfContents c;
              {
                  py::gil_scoped_release release;
                  c = raysplats::gltf_contents(path);
              }
              return py::dict("splat_primitives"_a = c.splat_primitives, "other_primitives"_a = c.other_primitives,
                              "splat_only_meshes"_a = c.splat_only_meshes);
          }, "path"_a,
          "What a glTF file holds: splat_primitives (KHR_gaussian_splatting), other_primitives, and the names of the "
          "meshes that hold only splat primitives. Raises FileFormatError for a file that is not valid glTF.");
    m.def("match_splat_format", [](const std::string& path, bool writable_only) -> py::object {
              const raysplats::SplatFormatMatch match = raysplats::match_splat_format(path, writable_only);
              if (!match.format) return py::none();
              return py::dict("name"_a = match.format->name,
                              "ending"_a = path.substr(path.size() - match.ending_length));
          }, "path"_a, "writable_only"_a = false,
          "The format a file name ends with, by the core's rule (the longest ending of splat_formats() that matches, "
          "case-insensitive: 'a.compressed.ply' is compressed_ply): dict of name and ending (the path's own last "
          "characters that matched), or None. writable_only: among the formats the core writes.");
    m.def("splat_formats", &splat_formats,
          "The splat formats read and written: list of {name, extensions (the first is written), description, "
          "up_axis (the up direction of the cloud as read: '-Y', COLMAP, for every format), up_axis_by_specification "
          "(True when the format's specification fixes up, as glTF's +Y), writable (False: read only, glTF and SOG)}.");
    m.attr("NEW_FACE_OPACITY") = raysplats::kNewFaceOpacity;
    register_render_bindings(m);
    register_mesh_export(m);
    register_splat_tools(m);
    register_edit_mesh(m);
}
