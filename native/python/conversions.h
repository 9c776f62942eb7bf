// The one conversion layer between Python values and the core's types. Every binding converts through these
// functions, so wrong input reads the same wherever it comes in:
//   array 'positions' has shape (5,2) but (N,3) was expected
//   unknown render setting 'sample' (known: width, height, samples, ...)
//   'color' must have 3 components (got 2)
// Arrays in are C-contiguous (converted by pybind11 if they are not); arrays out are numpy views of vectors the
// array owns (no copies).
#pragma once

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <array>
#include <cstdint>
#include <initializer_list>
#include <string>
#include <vector>

#include "raysplats/gaussian_cloud.h"
#include "raysplats/render/camera.h"
#include "raysplats/render/film.h"
#include "raysplats/render/parameters.h"
#include "raysplats/render/render_settings.h"
#include "raysplats/render/transform.h"

namespace raysplats::python {

namespace py = pybind11;

using FloatArray = py::array_t<float, py::array::c_style | py::array::forcecast>;
using DoubleArray = py::array_t<double, py::array::c_style | py::array::forcecast>;
using IntArray = py::array_t<std::int32_t, py::array::c_style | py::array::forcecast>;
using UintArray = py::array_t<std::uint32_t, py::array::c_style | py::array::forcecast>;

// Any dimension: the entry -1 in an expected shape.
constexpr py::ssize_t kAnySize = -1;

// Checks array `name`'s shape against `shape` (kAnySize matches any size); returns its first dimension.
py::ssize_t require_shape(const py::array& array, const char* name, std::initializer_list<py::ssize_t> shape);

// "(5,2)": an array's shape as errors print it.
std::string shape_text(const py::array& array);
// For the flat arrays of Blender's foreach_get: checks that array `name` holds `expected` values.
void require_size(const py::array& array, const char* name, py::ssize_t expected);

// Hands a vector to numpy without copying: the array owns the vector through a capsule.
template <typename T, typename Allocator>
py::array_t<T> to_numpy(std::vector<T, Allocator>&& values, std::vector<py::ssize_t> shape) {
    auto* owned = new std::vector<T, Allocator>(std::move(values));
    py::capsule owner(owned, [](void* p) { delete static_cast<std::vector<T, Allocator>*>(p); });
    return py::array_t<T>(shape, owned->data(), owner);
}

// SH degree (0..3) from the coefficients per channel (1, 4, 9, 16) of array `name`.
int sh_degree_from_coefficients(py::ssize_t coefficients, const char* name);

// Gaussians from the arrays of docs/design.md §4: positions (N,3), rotations (N,4) wxyz, scales (N,3) linear,
// opacities (N) linear, sh (N,coeffs,3). The values are copied (the cloud outlives the arrays).
GaussianCloud cloud_from_arrays(const FloatArray& positions, const FloatArray& rotations, const FloatArray& scales,
                                const FloatArray& opacities, const FloatArray& sh);
// The reverse, as numpy arrays under the same names plus "sh_degree".
py::dict cloud_to_dict(GaussianCloud&& cloud);

// A 4x4 matrix (row-major, as numpy shows Blender's matrix_world); None is the identity.
Matrix4 matrix_from(const py::handle& value, const char* name);
// A 1-d array of numbers (a curve's values); None is none.
std::vector<float> floats_from(const py::handle& value, const char* name);
// An (n, 4, 4) array of such matrices (motion steps); None is none.
std::vector<Matrix4> matrices_from(const py::handle& value, const char* name);
// 3 components, or 4 with the 4th (alpha, as in Blender's RGBA colours) ignored.
std::array<float, 3> rgb_from(const py::handle& value, const char* name);

// A Python value as a ParameterValue of its own type (bool, int, float, str, or a 4x4 array); the table then
// checks it against the parameter's type.
// `what` and `name` name it in errors ("render setting", "seed").
ParameterValue parameter_value_from(const py::handle& value, const std::string& name, const char* what);
// Sets every entry of `dict` through `table`: unknown keys and values of the wrong type are errors.
template <typename Target>
void apply_dict(const py::dict& dict, const ParameterTable<Target>& table, Target& target) {
    for (const auto& [key, value] : dict) {
        const std::string name = py::str(key);
        table.find(name);  // an unknown name is the error, whatever its value
        table.set(target, name, parameter_value_from(value, name, table.what()));
    }
}

// The camera of a dict of camera_parameters(), "motion" and "frame_motion" (Camera::motion and frame_motion as
// (n, 4, 4) arrays) and "shutter_curve" (Camera::shutter_curve), validated.
Camera camera_from(const py::dict& camera);
// The settings of a dict of render_setting_parameters(), validated.
RenderSettings settings_from(const py::dict& settings);

// The film as numpy arrays, rows top to bottom, one per film channel (film_channels(): rgba (H,W,4), depth (H,W),
// normal (H,W,3), alpha (H,W), ...), and the statistics (samples: per pixel, see RenderStats::samples).
// A channel the film does not hold (an empty buffer: a snapshot of some channels) is left out.
py::dict film_to_dict(Film&& film);

// The film channel of a key of film_channels() ("rgba", "depth", ...); InvalidArgument naming the known keys.
FilmChannel film_channel_of(const std::string& key);

// "bool", "int", "float", "str", "matrix".
const char* python_type_name(ParameterType type);

// A parameter table as a list of dicts {name, type, description, choices}, and a name table as a list of
// {name, description}: how Python reads the core's vocabularies.
template <typename Target>
py::list describe(const ParameterTable<Target>& table) {
    py::list out;
    for (const auto& p : table.parameters()) {
        py::dict d;
        d["name"] = p.name;
        d["type"] = python_type_name(p.type);
        d["description"] = p.description;
        py::list choices;
        for (const std::string& c : p.choices) choices.append(c);
        d["choices"] = choices;
        out.append(d);
    }
    return out;
}
template <typename Enum>
py::list describe(const NameTable<Enum>& table) {
    py::list out;
    for (const auto& v : table.values) {
        py::dict d;
        d["name"] = v.name;
        d["description"] = v.description;
        out.append(d);
    }
    return out;
}

}  // namespace raysplats::python
