// Python <-> core conversions (conversions.h).
#include "conversions.h"

#include <algorithm>

#include "raysplats/errors.h"
#include "raysplats/render/camera_parameters.h"

namespace raysplats::python {

namespace {

std::string shape_text(const std::vector<std::string>& sizes) {
    std::string s = "(";
    for (std::size_t i = 0; i < sizes.size(); ++i) s += (i ? "," : "") + sizes[i];
    return s + ")";
}

}  // namespace

std::string shape_text(const py::array& array) {
    std::vector<std::string> sizes;
    for (py::ssize_t d = 0; d < array.ndim(); ++d) sizes.push_back(std::to_string(array.shape(d)));
    return shape_text(sizes);
}

void require_size(const py::array& array, const char* name, py::ssize_t expected) {
    if (array.size() != expected)
        throw InvalidArgument(std::string("array '") + name + "' has " + std::to_string(array.size()) +
                              " values but " + std::to_string(expected) + " were expected");
}

py::ssize_t require_shape(const py::array& array, const char* name, std::initializer_list<py::ssize_t> shape) {
    bool ok = array.ndim() == py::ssize_t(shape.size());
    std::vector<std::string> want;
    py::ssize_t i = 0;
    for (const py::ssize_t size : shape) {
        ok = ok && (size == kAnySize || array.shape(i) == size);
        want.push_back(size == kAnySize ? "N" : std::to_string(size));
        ++i;
    }
    if (!ok)
        throw InvalidArgument(std::string("array '") + name + "' has shape " + shape_text(array) + " but " +
                              shape_text(want) + " was expected");
    return array.ndim() ? array.shape(0) : 0;
}

int sh_degree_from_coefficients(py::ssize_t coefficients, const char* name) {
    for (int degree = 0; degree <= 3; ++degree)
        if (sh_coeff_count(degree) == coefficients) return degree;
    throw InvalidArgument(std::string("array '") + name + "' has " + std::to_string(coefficients) +
                          " SH coefficients per channel but 1, 4, 9 or 16 were expected");
}

GaussianCloud cloud_from_arrays(const FloatArray& positions, const FloatArray& rotations, const FloatArray& scales,
                                const FloatArray& opacities, const FloatArray& sh) {
    const py::ssize_t n = require_shape(positions, "positions", {kAnySize, 3});
    require_shape(rotations, "rotations", {n, 4});
    require_shape(scales, "scales", {n, 3});
    require_shape(opacities, "opacities", {n});
    require_shape(sh, "sh", {n, kAnySize, 3});
    GaussianCloud cloud;
    cloud.sh_degree = sh_degree_from_coefficients(sh.shape(1), "sh");
    auto copy = [](const FloatArray& a, std::vector<float>& to) { to.assign(a.data(), a.data() + a.size()); };
    copy(positions, cloud.positions);
    copy(rotations, cloud.rotations);
    copy(scales, cloud.scales);
    copy(opacities, cloud.opacities);
    copy(sh, cloud.sh);
    return cloud;
}

py::dict cloud_to_dict(GaussianCloud&& cloud) {
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

Matrix4 matrix_from(const py::handle& value, const char* name) {
    Matrix4 m;
    if (value.is_none()) return m;
    const FloatArray a = FloatArray::ensure(value);
    if (!a) throw InvalidArgument(std::string("'") + name + "' must be a 4x4 matrix");
    require_shape(a, name, {4, 4});
    std::copy(a.data(), a.data() + 16, m.m.begin());
    return m;
}

std::array<float, 3> rgb_from(const py::handle& value, const char* name) {
    const FloatArray a = FloatArray::ensure(value);
    if (!a || a.ndim() != 1 || (a.size() != 3 && a.size() != 4))
        throw InvalidArgument(std::string("'") + name + "' must have 3 components (or 4, the 4th ignored); got " +
                              std::string(py::repr(value)));
    return {a.data()[0], a.data()[1], a.data()[2]};
}

ParameterValue parameter_value_from(const py::handle& value, const std::string& name, const char* what) {
    // bool before int: Python's bool is an int. numpy scalars count as what they hold.
    if (py::isinstance<py::bool_>(value) || py::isinstance(value, py::module_::import("numpy").attr("bool_")))
        return value.cast<bool>();
    if (py::isinstance<py::str>(value)) return value.cast<std::string>();
    if (py::isinstance<py::float_>(value) ||
        py::isinstance(value, py::module_::import("numpy").attr("floating")))
        return value.cast<double>();
    // Arrays before integers: numpy arrays have __index__ (for 0-d integer arrays).
    if (py::isinstance<py::array>(value) || py::isinstance<py::sequence>(value))
        return matrix_from(value, name.c_str());
    if (PyIndex_Check(value.ptr())) return value.cast<std::int64_t>();
    throw InvalidArgument(std::string(what) + " '" + name + "' cannot be a " +
                          std::string(py::str(value.get_type().attr("__name__"))));
}

const char* python_type_name(ParameterType type) {
    switch (type) {
        case ParameterType::Bool: return "bool";
        case ParameterType::Integer: return "int";
        case ParameterType::Real: return "float";
        case ParameterType::Name: return "str";
        case ParameterType::Matrix: return "matrix";
    }
    return "?";
}

std::vector<Matrix4> matrices_from(const py::handle& value, const char* name) {
    std::vector<Matrix4> out;
    if (value.is_none()) return out;
    const FloatArray a = FloatArray::ensure(value);
    if (!a) throw InvalidArgument(std::string("'") + name + "' must be an array of 4x4 matrices");
    const py::ssize_t n = require_shape(a, name, {kAnySize, 4, 4});
    out.resize(std::size_t(n));
    for (py::ssize_t k = 0; k < n; ++k) std::copy(a.data() + 16 * k, a.data() + 16 * (k + 1), out[k].m.begin());
    return out;
}

std::vector<float> floats_from(const py::handle& value, const char* name) {
    if (value.is_none()) return {};
    const FloatArray a = FloatArray::ensure(value);
    if (!a) throw InvalidArgument(std::string("'") + name + "' must be an array of numbers");
    const py::ssize_t n = require_shape(a, name, {kAnySize});
    return std::vector<float>(a.data(), a.data() + n);
}

Camera camera_from(const py::dict& camera) {
    Camera c;
    // "motion" and "frame_motion" (Camera::motion and frame_motion, (n, 4, 4) arrays) and "shutter_curve" (n
    // values) are lists, which the parameter table's values are not: taken here, the rest through the table.
    py::dict parameters;
    for (const auto& [key, value] : camera) {
        const std::string name = py::str(key);
        if (name == "motion") c.motion = matrices_from(value, "motion");
        else if (name == "frame_motion") c.frame_motion = matrices_from(value, "frame_motion");
        else if (name == "shutter_curve") c.shutter_curve = floats_from(value, "shutter_curve");
        else parameters[key] = value;
    }
    apply_dict(parameters, camera_parameters(), c);
    c.validate();
    return c;
}

RenderSettings settings_from(const py::dict& settings) {
    RenderSettings s;
    apply_dict(settings, render_setting_parameters(), s);
    s.validate();
    return s;
}

FilmChannel film_channel_of(const std::string& key) {
    std::vector<std::string> keys;
    for (const FilmChannelInfo& info : film_channels()) {
        if (key == info.key) return info.channel;
        keys.emplace_back(info.key);
    }
    throw_unknown_name("film channel", key, keys);
}

py::dict film_to_dict(Film&& film) {
    const py::ssize_t h = film.height, w = film.width;
    py::dict d;
    d["cancelled"] = film.stats.cancelled;
    d["samples"] = film.stats.samples;
    d["render_seconds"] = film.stats.render_seconds;
    d["camera_rays"] = film.stats.camera_rays;
    d["gaussian_hits"] = film.stats.gaussian_hits;
    d["gaussian_candidates"] = film.stats.gaussian_candidates;
    d["gaussian_group_candidates"] = film.stats.gaussian_group_candidates;
    d["camera_ray_splatting"] = film.stats.camera_ray_splatting;
    d["camera_rays_traced_reason"] = film.stats.camera_rays_traced_reason;
    d["splat_prepass_seconds"] = film.stats.splat_prepass_seconds;
    d["splat_prepass_cpu_seconds"] = film.stats.splat_prepass_cpu_seconds;
    d["build_seconds"] = film.stats.build_seconds;
    d["build_cpu_seconds"] = film.stats.build_cpu_seconds;
    d["sample_seconds"] = film.stats.sample_seconds;
    d["sample_cpu_seconds"] = film.stats.sample_cpu_seconds;
    d["film_seconds"] = film.stats.film_seconds;
    d["film_cpu_seconds"] = film.stats.film_cpu_seconds;
    d["splats"] = film.stats.splats;
    d["splat_tile_entries"] = film.stats.splat_tile_entries;
    d["splat_bytes"] = film.stats.splat_bytes;
    // One array per film channel, (h, w) for one component and (h, w, c) for more.
    for (const FilmChannelInfo& info : film_channels()) {
        const int c = info.component_count();
        if (film[info.channel].empty() && film.pixel_count() > 0) continue;
        d[info.key] = c == 1 ? to_numpy(std::move(film[info.channel]), {h, w})
                             : to_numpy(std::move(film[info.channel]), {h, w, py::ssize_t(c)});
    }
    // The Cryptomatte passes the render filled: (h, w, layers, 4), layer k the RGBA of pass "<prefix>%02d" % k.
    for (std::size_t t = 0; t < kCryptomatteTypes; ++t) {
        if (film.cryptomatte[t].empty()) continue;
        const py::ssize_t layers = film.cryptomatte_ranks / 2;
        d[cryptomatte_key(CryptomatteType(t))] = to_numpy(std::move(film.cryptomatte[t]), {h, w, layers, 4});
    }
    return d;
}

}  // namespace raysplats::python
