// The Gaussian model of docs/design.md §4, as a structure of arrays that crosses the Python boundary without copies.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace raysplats {

// Number of SH coefficients per colour channel for a degree 0..3: (degree + 1)^2.
constexpr int sh_coeff_count(int degree) { return (degree + 1) * (degree + 1); }

// A set of 3D Gaussians. Gaussian i has
//   centre     positions[3i .. 3i+2]
//   rotation   rotations[4i .. 4i+3], unit quaternion (w, x, y, z), R = rotation matrix of it
//   scales     scales[3i .. 3i+2], linear standard deviations along R's columns: Σ = R diag(s)^2 R^T
//   opacity    opacities[i], linear in [0, 1]
//   colour     sh[(i * sh_coeff_count(sh_degree) + k) * 3 + c], coefficient k (0 = DC) of channel c (RGB),
//              reference-3DGS real SH basis; colour(d) = max(0, 0.5 + Σ_k Y_k(d) sh_k)
// All arrays are float32 to match the file formats and Blender; numerics that need it run in double.
struct GaussianCloud {
    int sh_degree = 0;
    std::vector<float> positions;
    std::vector<float> rotations;
    std::vector<float> scales;
    std::vector<float> opacities;
    std::vector<float> sh;

    std::size_t size() const { return opacities.size(); }
    int coeffs_per_channel() const { return sh_coeff_count(sh_degree); }

    // Allocates every array for n Gaussians of the given SH degree (values zero, rotations identity).
    void resize(std::size_t n, int degree);

    // Throws InvalidArgument if the array sizes disagree with size() and sh_degree.
    void check_consistent() const;

    // Throws InvalidArgument, naming `name` and the first bad Gaussian, if a value is NaN or Inf or a scale is
    // negative (Gaussians [begin, end); end = size() by default).
    void check_values(const std::string& name, std::size_t begin = 0, std::size_t end = ~std::size_t(0)) const;

    // Gaussian rows[j] becomes Gaussian j of `values` (same SH degree). Validates everything first (indices,
    // values: see check_values, naming `name`), so that on a throw nothing has changed.
    void assign_rows(const GaussianCloud& values, const std::uint32_t* rows, const std::string& name);
};

// Things a reader repaired or dropped, for a warning to the user ("3 splats with NaN dropped").
struct LoadReport {
    std::size_t non_finite_dropped = 0;     // splats with NaN/Inf in position, scale or rotation
    std::size_t non_finite_repaired = 0;    // NaN/Inf in opacity or colour, set to 0
    std::size_t zero_rotation_repaired = 0; // zero quaternions replaced by the identity
    std::size_t negative_scale_repaired = 0; // splats with a negative linear scale (.splat), read as its magnitude
    std::vector<std::string> warnings;      // human-readable lines, one per kind of problem
};

}  // namespace raysplats
