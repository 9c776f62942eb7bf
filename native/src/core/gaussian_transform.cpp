#include "raysplats/gaussian_transform.h"

#include <tbb/parallel_for.h>

#include <cmath>
#include <string>

#include "linear_algebra.h"
#include "raysplats/errors.h"
#include "raysplats/spherical_harmonics.h"

namespace raysplats {

using la::Mat3;
using la::determinant;
using la::matrix_to_quaternion;
using la::quaternion_to_matrix;
using la::symmetric_eigen;
using la::transpose;

namespace {

// The orthogonal factor Q of A = Q P (P symmetric positive definite) by Newton's iteration Q <- (Q + Q^-T) / 2
// (Higham 1986, "Computing the polar decomposition"), which converges quadratically for invertible A.
Mat3 orthogonal_polar_factor(const Mat3& a) {
    Mat3 q = a;
    for (int iteration = 0; iteration < 100; ++iteration) {
        const double det = determinant(q);
        // q^-T = cofactor(q) / det
        Mat3 inverse_transpose;
        for (int r = 0; r < 3; ++r)
            for (int c = 0; c < 3; ++c) {
                const int r1 = (r + 1) % 3, r2 = (r + 2) % 3, c1 = (c + 1) % 3, c2 = (c + 2) % 3;
                inverse_transpose(r, c) = (q(r1, c1) * q(r2, c2) - q(r1, c2) * q(r2, c1)) / det;
            }
        double change = 0.0;
        for (int r = 0; r < 3; ++r)
            for (int c = 0; c < 3; ++c) {
                const double next = 0.5 * (q(r, c) + inverse_transpose(r, c));
                change = std::max(change, std::abs(next - q(r, c)));
                q(r, c) = next;
            }
        if (change < 1e-15) break;
    }
    return q;
}

bool is_identity(const double m[16]) {
    for (int i = 0; i < 16; ++i)
        if (m[i] != (i % 5 == 0 ? 1.0 : 0.0)) return false;
    return true;
}

}  // namespace

GaussianCloud transform_gaussians(const GaussianCloud& cloud, const double matrix[16]) {
    cloud.check_consistent();
    if (is_identity(matrix)) return cloud;
    for (int i = 0; i < 16; ++i)
        if (!std::isfinite(matrix[i])) throw InvalidArgument("transform_gaussians: the matrix has a NaN or Inf entry");
    Mat3 a;
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) a(r, c) = matrix[r * 4 + c];
    const double det = determinant(a);
    double norm_sq = 0.0;
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) norm_sq += a(r, c) * a(r, c);
    if (!(std::abs(det) > 1e-12 * std::pow(norm_sq / 3.0, 1.5)))
        throw InvalidArgument("transform_gaussians: the matrix is singular (it flattens the Gaussians)");
    const Mat3 q = orthogonal_polar_factor(a);
    // Similarity: A = k Q with k the cube root of |det A|, to float32 precision (Blender keeps matrices in float).
    const double k = std::cbrt(std::abs(det));
    double deviation = 0.0;
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) deviation = std::max(deviation, std::abs(a(r, c) - k * q(r, c)));
    const bool similarity = deviation <= 1e-6 * k;
    // The SH turn: Q itself when proper; a reflection is Q = R_p · diag(-1, 1, 1): mirror in x, then rotate by R_p.
    const bool reflection = determinant(q) < 0;
    Mat3 sh_rotation = q;
    if (reflection)
        for (int r = 0; r < 3; ++r) sh_rotation(r, 0) = -sh_rotation(r, 0);
    double sh_rotation_row_major[9];
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) sh_rotation_row_major[r * 3 + c] = sh_rotation(r, c);

    GaussianCloud out = cloud;
    const int coeffs = cloud.coeffs_per_channel();
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, cloud.size(), 4096), [&](const auto& range) {
        for (std::size_t i = range.begin(); i != range.end(); ++i) {
            const float* p = &cloud.positions[3 * i];
            for (int r = 0; r < 3; ++r)
                out.positions[3 * i + r] =
                    float(matrix[r * 4] * p[0] + matrix[r * 4 + 1] * p[1] + matrix[r * 4 + 2] * p[2] + matrix[r * 4 + 3]);
            const float* qi = &cloud.rotations[4 * i];
            const double qn = std::sqrt(double(qi[0]) * qi[0] + double(qi[1]) * qi[1] + double(qi[2]) * qi[2] +
                                        double(qi[3]) * qi[3]);
            const Mat3 rotation = quaternion_to_matrix(qi[0] / qn, qi[1] / qn, qi[2] / qn, qi[3] / qn);
            const float* s = &cloud.scales[3 * i];
            Mat3 new_rotation;
            double new_scales[3];
            if (similarity) {
                new_rotation = q * rotation;
                for (int c = 0; c < 3; ++c) new_scales[c] = k * s[c];
                if (reflection)  // a proper rotation again: one axis turned round (a Gaussian is symmetric)
                    for (int r = 0; r < 3; ++r) new_rotation(r, 0) = -new_rotation(r, 0);
            } else {
                // Σ' = (A R diag(s)) (A R diag(s))ᵀ
                Mat3 m = a * rotation;
                for (int r = 0; r < 3; ++r)
                    for (int c = 0; c < 3; ++c) m(r, c) *= s[c];
                const Mat3 sigma = m * transpose(m);
                double values[3];
                symmetric_eigen(sigma, values, new_rotation);
                for (int c = 0; c < 3; ++c) new_scales[c] = std::sqrt(std::max(values[c], 0.0));
            }
            double quaternion[4];
            matrix_to_quaternion(new_rotation, quaternion);
            for (int c = 0; c < 4; ++c) out.rotations[4 * i + c] = float(quaternion[c]);
            for (int c = 0; c < 3; ++c) out.scales[3 * i + c] = float(new_scales[c]);
            if (coeffs > 1) {
                float* sh = &out.sh[std::size_t(i) * coeffs * 3];
                if (reflection) reflect_sh(cloud.sh_degree, true, false, false, sh);
                rotate_sh(cloud.sh_degree, sh_rotation_row_major, sh, sh);
            }
        }
    });
    return out;
}

}  // namespace raysplats
