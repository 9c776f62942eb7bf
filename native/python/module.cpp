// raysplats._native: thin pybind11 bindings over the core. Arrays in are numpy (C-contiguous float32 or
// int32, shapes checked); arrays out are numpy views of the core's vectors (no copies); the GIL is released
// around native work so Blender stays responsive. No logic lives here.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <optional>
#include <string>
#include <vector>

#include "raysplats/errors.h"
#include "raysplats/gaussian_cloud.h"
#include "raysplats/polygon_bridge.h"
#include "raysplats/splat_io.h"

namespace py = pybind11;
using namespace pybind11::literals;

void register_render_bindings(py::module_& m);  // render_bindings.cpp

namespace {

using FloatArray = py::array_t<float, py::array::c_style | py::array::forcecast>;
using IntArray = py::array_t<std::int32_t, py::array::c_style | py::array::forcecast>;
using DoubleArray = py::array_t<double, py::array::c_style | py::array::forcecast>;
using UintArray = py::array_t<std::uint32_t, py::array::c_style | py::array::forcecast>;

// Hands a vector to numpy without copying: the array owns the vector through a capsule.
template <typename T>
py::array_t<T> to_numpy(std::vector<T>&& values, std::vector<py::ssize_t> shape) {
    auto* owned = new std::vector<T>(std::move(values));
    py::capsule owner(owned, [](void* p) { delete static_cast<std::vector<T>*>(p); });
    return py::array_t<T>(shape, owned->data(), owner);
}

// Checks an array's shape: `shape` entries of -1 match anything. Returns the first dimension.
template <typename A>
py::ssize_t check_shape(const A& array, const char* name, std::vector<py::ssize_t> shape) {
    bool ok = array.ndim() == py::ssize_t(shape.size());
    for (std::size_t i = 0; ok && i < shape.size(); ++i) ok = shape[i] < 0 || array.shape(i) == shape[i];
    if (!ok) {
        std::string want = "(", got = "(";
        for (auto s : shape) want += (s < 0 ? std::string("N") : std::to_string(s)) + ",";
        for (py::ssize_t i = 0; i < array.ndim(); ++i) got += std::to_string(array.shape(i)) + ",";
        throw raysplats::InvalidArgument(std::string("array '") + name + "' has shape " + got + ") but " + want +
                                         ") was expected");
    }
    return array.ndim() ? array.shape(0) : 0;
}

template <typename T, typename A>
std::vector<T> to_vector(const A& a) {
    return std::vector<T>(a.data(), a.data() + a.size());
}

int degree_from_coeffs(py::ssize_t coeffs) {
    for (int d = 0; d <= 3; ++d)
        if (raysplats::sh_coeff_count(d) == coeffs) return d;
    throw raysplats::InvalidArgument("SH array has " + std::to_string(coeffs) +
                                     " coefficients per channel; 1, 4, 9 or 16 expected");
}

py::dict cloud_to_dict(raysplats::GaussianCloud&& cloud) {
    const auto n = py::ssize_t(cloud.size());
    const auto coeffs = py::ssize_t(cloud.coeffs_per_channel());
    py::dict d;
    d["sh_degree"] = cloud.sh_degree;
    d["positions"] = to_numpy(std::move(cloud.positions), {n, 3});
    d["rotations"] = to_numpy(std::move(cloud.rotations), {n, 4});
    d["scales"] = to_numpy(std::move(cloud.scales), {n, 3});
    d["opacities"] = to_numpy(std::move(cloud.opacities), {n});
    d["sh"] = to_numpy(std::move(cloud.sh), {n, coeffs, 3});
    return d;
}

raysplats::GaussianCloud cloud_from_arrays(const FloatArray& positions, const FloatArray& rotations,
                                           const FloatArray& scales, const FloatArray& opacities, const FloatArray& sh) {
    const py::ssize_t n = check_shape(positions, "positions", {-1, 3});
    check_shape(rotations, "rotations", {n, 4});
    check_shape(scales, "scales", {n, 3});
    check_shape(opacities, "opacities", {n});
    check_shape(sh, "sh", {n, -1, 3});
    raysplats::GaussianCloud cloud;
    cloud.sh_degree = degree_from_coeffs(sh.shape(1));
    cloud.positions = to_vector<float>(positions);
    cloud.rotations = to_vector<float>(rotations);
    cloud.scales = to_vector<float>(scales);
    cloud.opacities = to_vector<float>(opacities);
    cloud.sh = to_vector<float>(sh);
    return cloud;
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
    const auto n = py::ssize_t(cloud.size());
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
    d["corner_colors"] = to_numpy(std::move(p.corner_colors), {corners, 4});
    d["corner_uvs"] = to_numpy(std::move(p.corner_uvs), {corners, 2});
    return d;
}

raysplats::PolygonMeshView mesh_view_of(const FloatArray& vertex_positions, const IntArray& corner_vertices,
                                        const IntArray& face_corner_start, const IntArray& face_corner_count) {
    raysplats::PolygonMeshView mesh;
    mesh.vertex_count = std::size_t(check_shape(vertex_positions, "vertex_positions", {-1, 3}));
    mesh.vertex_positions = vertex_positions.data();
    mesh.corner_count = std::size_t(check_shape(corner_vertices, "corner_vertices", {-1}));
    mesh.corner_vertices = corner_vertices.data();
    const py::ssize_t faces = check_shape(face_corner_start, "face_corner_start", {-1});
    check_shape(face_corner_count, "face_corner_count", {faces});
    mesh.face_corner_start = face_corner_start.data();
    mesh.face_corner_count = face_corner_count.data();
    mesh.face_count = std::size_t(faces);
    return mesh;
}

py::array_t<std::uint32_t> faces_with_moved_vertices(const FloatArray& previous_positions, const FloatArray& vertex_positions,
                                                     const IntArray& corner_vertices, const IntArray& face_corner_start,
                                                     const IntArray& face_corner_count) {
    const raysplats::PolygonMeshView mesh = mesh_view_of(vertex_positions, corner_vertices, face_corner_start, face_corner_count);
    check_shape(previous_positions, "previous_positions", {py::ssize_t(mesh.vertex_count), 3});
    std::vector<std::uint32_t> faces;
    {
        py::gil_scoped_release release;
        faces = raysplats::faces_with_moved_vertices(mesh, previous_positions.data());
    }
    const py::ssize_t n = py::ssize_t(faces.size());
    return to_numpy(std::move(faces), {n});
}

py::array_t<std::uint32_t> rows_that_differ(const FloatArray& previous, const FloatArray& current) {
    if (previous.ndim() < 1 || previous.ndim() != current.ndim())
        throw raysplats::InvalidArgument("rows_that_differ: the arrays must have the same shape");
    for (py::ssize_t d = 0; d < previous.ndim(); ++d)
        if (previous.shape(d) != current.shape(d))
            throw raysplats::InvalidArgument("rows_that_differ: the arrays must have the same shape");
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

py::dict recover_gaussians(const FloatArray& vertex_positions, const IntArray& corner_vertices,
                           const IntArray& face_corner_start, const IntArray& face_corner_count,
                           int vertices_per_polygon, float radius, const DoubleArray& mesh_to_output,
                           std::optional<FloatArray> opacity, std::optional<FloatArray> thickness,
                           std::optional<FloatArray> sh_local, std::optional<FloatArray> rest_centers,
                           std::optional<FloatArray> rest_rotations, std::optional<FloatArray> rest_scales,
                           std::optional<UintArray> subset) {
    raysplats::PolygonMeshView mesh = mesh_view_of(vertex_positions, corner_vertices, face_corner_start, face_corner_count);
    const py::ssize_t faces = py::ssize_t(mesh.face_count);
    check_shape(mesh_to_output, "mesh_to_output", {4, 4});

    raysplats::SplatFaceAttributesView attr;
    if (opacity) check_shape(*opacity, "opacity", {faces}), attr.opacity = opacity->data();
    if (thickness) check_shape(*thickness, "thickness", {faces}), attr.thickness = thickness->data();
    if (sh_local) {
        check_shape(*sh_local, "sh_local", {faces, -1, 3});
        attr.sh_degree = degree_from_coeffs(sh_local->shape(1));
        attr.sh_local = sh_local->data();
    }
    if (rest_centers) check_shape(*rest_centers, "rest_centers", {faces, 3}), attr.rest_centers = rest_centers->data();
    if (rest_rotations)
        check_shape(*rest_rotations, "rest_rotations", {faces, 4}), attr.rest_rotations = rest_rotations->data();
    if (rest_scales) check_shape(*rest_scales, "rest_scales", {faces, 3}), attr.rest_scales = rest_scales->data();

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
                          "degenerate"_a = stats.degenerate, "dropped"_a = stats.dropped);
    return d;
}

}  // namespace

// mesh_export_bindings.cpp
void register_mesh_export(py::module_& m);

PYBIND11_MODULE(_native, m) {
    m.doc() = "RaySplats native core: splat file I/O, the polygon bridge and mesh export (see DESIGN.md).";

    auto error = py::register_exception<raysplats::Error>(m, "Error", PyExc_RuntimeError);
    py::register_exception<raysplats::FileFormatError>(m, "FileFormatError", error.ptr());
    py::register_exception<raysplats::InvalidArgument>(m, "InvalidArgument", PyExc_ValueError);

    m.def("read_splats", &read_splats, "path"_a, "min_opacity"_a = 0.0f, "max_count"_a = 0,
          "Reads a .ply/.splat/.spz file. Returns a dict of numpy arrays (positions, rotations wxyz, linear "
          "scales, linear opacities, sh [N, coeffs, 3]), sh_degree and warnings.");
    m.def("write_splats", &write_splats, "path"_a, "positions"_a, "rotations"_a, "scales"_a, "opacities"_a, "sh"_a,
          "Writes Gaussians atomically; the format comes from the extension (.ply, .splat, .spz).");
    m.def("gaussians_to_polygons", &gaussians_to_polygons, "positions"_a, "rotations"_a, "scales"_a, "opacities"_a,
          "sh"_a, "vertices_per_polygon"_a = 8, "radius"_a = 3.0f,
          "Flat K-gon per Gaussian with the mesh topology, face attributes and corner colours/UVs (DESIGN §5).");
    m.def("recover_gaussians", &recover_gaussians, "vertex_positions"_a, "corner_vertices"_a, "face_corner_start"_a,
          "face_corner_count"_a, "vertices_per_polygon"_a, "radius"_a, "mesh_to_output"_a, "opacity"_a = py::none(),
          "thickness"_a = py::none(), "sh_local"_a = py::none(), "rest_centers"_a = py::none(),
          "rest_rotations"_a = py::none(), "rest_scales"_a = py::none(), "faces"_a = py::none(),
          "Recovers one Gaussian per polygon by moments (DESIGN §5), in the space of mesh_to_output; with `faces`, "
          "only those (row j is face faces[j], bit-identical to a full recovery's).");
    m.def("rows_that_differ", &rows_that_differ, "previous"_a, "current"_a,
          "Rows (ascending uint32) in which two float arrays of the same shape differ bit for bit.");
    m.def("faces_with_moved_vertices", &faces_with_moved_vertices, "previous_positions"_a, "vertex_positions"_a,
          "corner_vertices"_a, "face_corner_start"_a, "face_corner_count"_a,
          "Faces (ascending uint32) with a corner on a vertex whose position differs bit for bit from "
          "previous_positions (the same mesh before an edit that kept its topology).");
    m.attr("NEW_FACE_OPACITY") = raysplats::kNewFaceOpacity;
    register_render_bindings(m);
    register_mesh_export(m);
}
