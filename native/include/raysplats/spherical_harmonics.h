// Real spherical harmonics of degree 0..3 in the basis and sign convention of the reference 3DGS
// implementation (Kerbl et al. 2023, utils/sh_utils.py), and their rotation.
#pragma once

#include <array>

namespace raysplats {

// SH basis constants of the reference implementation.
constexpr double kShC0 = 0.28209479177387814;
constexpr double kShC1 = 0.4886025119029199;

// Fills basis[0 .. (degree+1)^2 - 1] with Y_k(d) for a unit direction d = (x, y, z).
void sh_basis(int degree, double x, double y, double z, double* basis);

// Colour of one Gaussian seen along unit direction d (from the camera to the Gaussian):
// rgb = max(0, 0.5 + Σ_k Y_k(d) coeffs[k]), coeffs laid out [k][rgb].
std::array<float, 3> evaluate_sh(int degree, const float* coeffs, double x, double y, double z);

// Rotation of SH coefficients: given R (3x3, row-major, proper rotation) and coefficients c of a function
// f(d) = Σ Y_k(d) c_k, writes c' with Σ Y_k(d) c'_k = f(R^T d) for every d, i.e. the function rotated by R.
// Bands 1..3 are rotated; band 0 is unchanged. In-place is allowed (in == out). Layout [k][rgb].
void rotate_sh(int degree, const double* rotation_row_major, const float* in, float* out);

// Reflection of SH coefficients across coordinate planes: with flip_x (y, z), writes the coefficients of
// f'(d) = f(d with x (y, z) negated), i.e. negates every coefficient whose basis function is odd in that coordinate.
// In place, layout [k][rgb]. A mirrored Gaussian's view-dependent colour is its original's reflected this way.
void reflect_sh(int degree, bool flip_x, bool flip_y, bool flip_z, float* coeffs);

}  // namespace raysplats
