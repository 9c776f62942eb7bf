// Bindings of the clean-up tools (splat_selection.h) and colour adjustments (color_adjustment.h): masks come back as
// numpy bool arrays without copies; SH are adjusted in place in the caller's array. No logic lives here.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <array>
#include <optional>
#include <vector>

#include "conversions.h"
#include "raysplats/color_adjustment.h"
#include "raysplats/errors.h"
#include "raysplats/splat_selection.h"

namespace py = pybind11;
using namespace pybind11::literals;
using namespace raysplats::python;

namespace {

py::array_t<bool> mask_to_numpy(raysplats::SelectionMask&& mask) {
    static_assert(sizeof(bool) == sizeof(std::uint8_t), "numpy bool is one byte");
    const py::ssize_t n = py::ssize_t(mask.size());
    auto* owned = new raysplats::SelectionMask(std::move(mask));
    py::capsule owner(owned, [](void* p) { delete static_cast<raysplats::SelectionMask*>(p); });
    return py::array_t<bool>({n}, reinterpret_cast<bool*>(owned->data()), owner);
}

std::array<float, 3> three(const FloatArray& values, const char* name) {
    require_shape(values, name, {3});
    return {values.data()[0], values.data()[1], values.data()[2]};
}

raysplats::ColorAdjustment adjustment_of(double exposure, double brightness, double saturation, double hue,
                                         double temperature) {
    return {exposure, brightness, saturation, hue, temperature};
}

}  // namespace

void register_splat_tools(py::module_& m) {
    m.def("select_by_value_range", [](const FloatArray& values, float min_value, float max_value) {
        const py::ssize_t n = require_shape(values, "values", {kAnySize});
        raysplats::SelectionMask mask;
        {
            py::gil_scoped_release release;
            mask = raysplats::select_by_value_range(values.data(), std::size_t(n), min_value, max_value);
        }
        return mask_to_numpy(std::move(mask));
    }, "values"_a, "min_value"_a, "max_value"_a, "Mask (bool) of values in [min_value, max_value].");

    m.def("select_by_largest_scale", [](const FloatArray& scales, float min_scale, float max_scale) {
        const py::ssize_t n = require_shape(scales, "scales", {kAnySize, 3});
        raysplats::SelectionMask mask;
        {
            py::gil_scoped_release release;
            mask = raysplats::select_by_largest_scale(scales.data(), std::size_t(n), min_scale, max_scale);
        }
        return mask_to_numpy(std::move(mask));
    }, "scales"_a, "min_scale"_a, "max_scale"_a, "Mask of Gaussians whose largest scale is in [min_scale, max_scale].");

    m.def("select_by_color_distance", [](const FloatArray& sh_dc, const FloatArray& target, float max_distance) {
        const py::ssize_t n = require_shape(sh_dc, "sh_dc", {kAnySize, 3});
        const std::array<float, 3> rgb = three(target, "target");
        raysplats::SelectionMask mask;
        {
            py::gil_scoped_release release;
            mask = raysplats::select_by_color_distance(sh_dc.data(), std::size_t(n), rgb.data(), max_distance);
        }
        return mask_to_numpy(std::move(mask));
    }, "sh_dc"_a, "target"_a, "max_distance"_a,
       "Mask of Gaussians whose SH DC display colour (clamped to [0, 1]) is within max_distance of target (RGB).");

    m.def("select_floaters", [](const FloatArray& positions, int k, double std_ratio) {
        const py::ssize_t n = require_shape(positions, "positions", {kAnySize, 3});
        std::vector<float> distances(static_cast<std::size_t>(n));
        raysplats::SelectionMask mask;
        {
            py::gil_scoped_release release;
            mask = raysplats::select_floaters(positions.data(), std::size_t(n), k, std_ratio, distances.data());
        }
        return py::make_tuple(mask_to_numpy(std::move(mask)), to_numpy(std::move(distances), {n}));
    }, "positions"_a, "k"_a, "std_ratio"_a,
       "(mask, mean distance to the k nearest neighbours): floaters are those with a mean distance above "
       "mean + std_ratio * std over all.");

    m.def("select_in_box", [](const FloatArray& positions, const DoubleArray& world_to_box, const FloatArray& box_min,
                              const FloatArray& box_max, bool inside) {
        const py::ssize_t n = require_shape(positions, "positions", {kAnySize, 3});
        require_shape(world_to_box, "world_to_box", {4, 4});
        const std::array<float, 3> lo = three(box_min, "box_min"), hi = three(box_max, "box_max");
        raysplats::SelectionMask mask;
        {
            py::gil_scoped_release release;
            mask = raysplats::select_in_box(positions.data(), std::size_t(n), world_to_box.data(), lo.data(), hi.data(),
                                            inside);
        }
        return mask_to_numpy(std::move(mask));
    }, "positions"_a, "world_to_box"_a, "box_min"_a, "box_max"_a, "inside"_a = true,
       "Mask of centres inside (or outside) the box [box_min, box_max] in the frame of world_to_box (4x4).");

    m.def("select_face_elements", [](const py::array_t<bool, py::array::c_style | py::array::forcecast>& face_mask,
                                     const IntArray& face_corner_start, const IntArray& face_corner_count,
                                     const IntArray& corner_vertices, const IntArray& corner_edges,
                                     std::size_t vertex_count, std::size_t edge_count) {
        const py::ssize_t faces = face_mask.ndim() == 1 ? face_mask.shape(0) : -1;
        if (faces < 0) throw raysplats::InvalidArgument("array 'face_mask' must be one-dimensional");
        require_shape(face_corner_start, "face_corner_start", {faces});
        require_shape(face_corner_count, "face_corner_count", {faces});
        const py::ssize_t corners = require_shape(corner_vertices, "corner_vertices", {kAnySize});
        require_shape(corner_edges, "corner_edges", {corners});
        raysplats::MeshElementSelection selection;
        {
            py::gil_scoped_release release;
            selection = raysplats::select_face_elements(
                reinterpret_cast<const std::uint8_t*>(face_mask.data()), std::size_t(faces), face_corner_start.data(),
                face_corner_count.data(), corner_vertices.data(), corner_edges.data(), std::size_t(corners),
                vertex_count, edge_count);
        }
        return py::make_tuple(mask_to_numpy(std::move(selection.vertices)), mask_to_numpy(std::move(selection.edges)));
    }, "face_mask"_a, "face_corner_start"_a, "face_corner_count"_a, "corner_vertices"_a, "corner_edges"_a,
       "vertex_count"_a, "edge_count"_a, "(vertex mask, edge mask) of the vertices and edges of the selected faces.");

    m.def("color_adjustment_map", [](double exposure, double brightness, double saturation, double hue,
                                     double temperature) {
        const raysplats::AffineColorMap map =
            raysplats::color_adjustment_map(adjustment_of(exposure, brightness, saturation, hue, temperature));
        std::vector<double> matrix(map.matrix, map.matrix + 9), offset(map.offset, map.offset + 3);
        return py::make_tuple(to_numpy(std::move(matrix), {3, 3}), to_numpy(std::move(offset), {3}));
    }, "exposure"_a = 0.0, "brightness"_a = 0.0, "saturation"_a = 1.0, "hue"_a = 0.0, "temperature"_a = 0.0,
       "(matrix 3x3, offset 3): the adjustment as the affine map c' = matrix c + offset of display colours.");

    m.def("apply_color_adjustment", [](py::array_t<float> sh, double exposure, double brightness, double saturation,
                                       double hue, double temperature) {
        // In place: the caller's own float32 C-contiguous array, never a converted copy.
        if (!(sh.flags() & py::array::c_style) || sh.ndim() != 3 || sh.shape(2) != 3 || !sh.writeable())
            throw raysplats::InvalidArgument("array 'sh' must be a writable C-contiguous float32 (N,coeffs,3) array, "
                                             "got shape " + shape_text(sh));
        const int degree = sh_degree_from_coefficients(sh.shape(1), "sh");
        const raysplats::ColorAdjustment adjustment = adjustment_of(exposure, brightness, saturation, hue, temperature);
        float* data = sh.mutable_data();
        const std::size_t n = std::size_t(sh.shape(0));
        py::gil_scoped_release release;
        raysplats::apply_color_adjustment(adjustment, degree, data, n);
    }, "sh"_a.noconvert(), "exposure"_a = 0.0, "brightness"_a = 0.0, "saturation"_a = 1.0, "hue"_a = 0.0,
       "temperature"_a = 0.0, "Adjusts SH coefficients (N, coeffs, 3) in place (color_adjustment.h).");

    m.def("splat_corner_colors", [](const FloatArray& sh_dc, std::optional<FloatArray> opacity,
                                    const IntArray& face_corner_start, const IntArray& face_corner_count,
                                    std::size_t corner_count, double exposure, double brightness, double saturation,
                                    double hue, double temperature) {
        const py::ssize_t faces = require_shape(sh_dc, "sh_dc", {kAnySize, 3});
        if (opacity) require_shape(*opacity, "opacity", {faces});
        require_shape(face_corner_start, "face_corner_start", {faces});
        require_shape(face_corner_count, "face_corner_count", {faces});
        std::vector<std::uint8_t> rgba(4 * corner_count, 0);
        {
            py::gil_scoped_release release;
            raysplats::splat_corner_colors(adjustment_of(exposure, brightness, saturation, hue, temperature),
                                           sh_dc.data(), opacity ? opacity->data() : nullptr, std::size_t(faces),
                                           face_corner_start.data(), face_corner_count.data(), corner_count, rgba.data());
        }
        return to_numpy(std::move(rgba), {py::ssize_t(corner_count), 4});
    }, "sh_dc"_a, "opacity"_a, "face_corner_start"_a, "face_corner_count"_a, "corner_count"_a, "exposure"_a = 0.0,
       "brightness"_a = 0.0, "saturation"_a = 1.0, "hue"_a = 0.0, "temperature"_a = 0.0,
       "The splat colour attribute per corner, (corner_count, 4) uint8: sRGB bytes of the adjusted SH DC, A = opacity "
       "(a byte colour attribute's bytes).");
    m.def("srgb8_to_linear", [](const py::array_t<std::uint8_t, py::array::c_style | py::array::forcecast>& rgba8) {
        const py::ssize_t n = require_shape(rgba8, "rgba8", {kAnySize, 4});
        std::vector<float> out(4 * std::size_t(n));
        raysplats::byte_colors_to_linear(rgba8.data(), std::size_t(n), out.data());
        return to_numpy(std::move(out), {n, 4});
    }, "rgba8"_a, "Byte colours (N, 4) uint8, sRGB RGB and linear A, as linear floats (what Blender's .color gives).");
}
