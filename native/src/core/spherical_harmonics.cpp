#include "raysplats/spherical_harmonics.h"

#include <algorithm>
#include <cmath>
#include <mutex>

#include "raysplats/errors.h"

namespace raysplats {
namespace {

// Constants of the reference 3DGS implementation (utils/sh_utils.py, SH_C2 and SH_C3).
constexpr double kShC2[5] = {1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792,
                             0.5462742152960396};
constexpr double kShC3[7] = {-0.5900435899266435, 2.890611442640554, -0.4570457994644658, 0.3731763325901154,
                             -0.4570457994644658, 1.445305721320277, -0.5900435899266435};

void check_degree(int degree) {
    if (degree < 0 || degree > 3) throw InvalidArgument("SH degree must be 0..3, got " + std::to_string(degree));
}

// Rotation of band l by sampling: for fixed directions d_j (j = 0..2l), A[m][j] = Y_lm(d_j). The rotated
// function f'(d) = f(R^T d) has coefficients c' = D^T c with Y_l(R^T d) = D Y_l(d); sampling at d_j gives
// B = D A with B[m][j] = Y_lm(R^T d_j), so D = B A^-1. A^-1 is computed once. This uses the very basis
// evaluated above, so the rotation matches its sign conventions by construction.
struct BandSampling {
    int l = 0;
    int n = 0;                 // 2l + 1
    double dirs[7][3] = {};    // d_j
    double a_inv[7][7] = {};   // A^-1
};

void invert(int n, double a[7][7], double inv[7][7]) {
    // Gauss-Jordan with partial pivoting; the sampling matrices are small and well conditioned.
    double m[7][14];
    for (int i = 0; i < n; ++i)
        for (int j = 0; j < 2 * n; ++j) m[i][j] = j < n ? a[i][j] : (j - n == i ? 1.0 : 0.0);
    for (int c = 0; c < n; ++c) {
        int p = c;
        for (int r = c + 1; r < n; ++r)
            if (std::abs(m[r][c]) > std::abs(m[p][c])) p = r;
        for (int j = 0; j < 2 * n; ++j) std::swap(m[c][j], m[p][j]);
        const double d = m[c][c];
        for (int j = 0; j < 2 * n; ++j) m[c][j] /= d;
        for (int r = 0; r < n; ++r) {
            if (r == c) continue;
            const double f = m[r][c];
            for (int j = 0; j < 2 * n; ++j) m[r][j] -= f * m[c][j];
        }
    }
    for (int i = 0; i < n; ++i)
        for (int j = 0; j < n; ++j) inv[i][j] = m[i][n + j];
}

const BandSampling* band_samplings() {
    static BandSampling bands[4];
    static std::once_flag once;
    std::call_once(once, [] {
        for (int l = 1; l <= 3; ++l) {
            BandSampling& b = bands[l];
            b.l = l;
            b.n = 2 * l + 1;
            // Directions on a spiral (Fibonacci sphere): distinct and spread, so A is well conditioned.
            for (int j = 0; j < b.n; ++j) {
                const double z = 1.0 - (2.0 * j + 1.0) / b.n * 0.9;
                const double r = std::sqrt(std::max(0.0, 1.0 - z * z));
                const double phi = 2.399963229728653 * j + 0.3 * l;
                b.dirs[j][0] = r * std::cos(phi);
                b.dirs[j][1] = r * std::sin(phi);
                b.dirs[j][2] = z;
            }
            double a[7][7];
            double basis[16];
            for (int j = 0; j < b.n; ++j) {
                sh_basis(l, b.dirs[j][0], b.dirs[j][1], b.dirs[j][2], basis);
                for (int m = 0; m < b.n; ++m) a[m][j] = basis[l * l + m];
            }
            invert(b.n, a, b.a_inv);
        }
    });
    return bands;
}

}  // namespace

void sh_basis(int degree, double x, double y, double z, double* basis) {
    check_degree(degree);
    basis[0] = kShC0;
    if (degree < 1) return;
    basis[1] = -kShC1 * y;
    basis[2] = kShC1 * z;
    basis[3] = -kShC1 * x;
    if (degree < 2) return;
    const double xx = x * x, yy = y * y, zz = z * z, xy = x * y, yz = y * z, xz = x * z;
    basis[4] = kShC2[0] * xy;
    basis[5] = kShC2[1] * yz;
    basis[6] = kShC2[2] * (2.0 * zz - xx - yy);
    basis[7] = kShC2[3] * xz;
    basis[8] = kShC2[4] * (xx - yy);
    if (degree < 3) return;
    basis[9] = kShC3[0] * y * (3.0 * xx - yy);
    basis[10] = kShC3[1] * xy * z;
    basis[11] = kShC3[2] * y * (4.0 * zz - xx - yy);
    basis[12] = kShC3[3] * z * (2.0 * zz - 3.0 * xx - 3.0 * yy);
    basis[13] = kShC3[4] * x * (4.0 * zz - xx - yy);
    basis[14] = kShC3[5] * z * (xx - yy);
    basis[15] = kShC3[6] * x * (xx - 3.0 * yy);
}

std::array<float, 3> evaluate_sh(int degree, const float* coeffs, double x, double y, double z) {
    double basis[16];
    sh_basis(degree, x, y, z, basis);
    const int n = (degree + 1) * (degree + 1);
    double rgb[3] = {0.5, 0.5, 0.5};
    for (int k = 0; k < n; ++k)
        for (int c = 0; c < 3; ++c) rgb[c] += basis[k] * coeffs[3 * k + c];
    return {float(std::max(0.0, rgb[0])), float(std::max(0.0, rgb[1])), float(std::max(0.0, rgb[2]))};
}

void rotate_sh(int degree, const double* r, const float* in, float* out) {
    check_degree(degree);
    for (int c = 0; c < 3; ++c) out[c] = in[c];
    if (degree == 0) return;
    const BandSampling* bands = band_samplings();
    double basis[16];
    for (int l = 1; l <= degree; ++l) {
        const BandSampling& b = bands[l];
        // B[m][j] = Y_lm(R^T d_j)
        double bm[7][7];
        for (int j = 0; j < b.n; ++j) {
            const double* d = b.dirs[j];
            const double x = r[0] * d[0] + r[3] * d[1] + r[6] * d[2];
            const double y = r[1] * d[0] + r[4] * d[1] + r[7] * d[2];
            const double z = r[2] * d[0] + r[5] * d[1] + r[8] * d[2];
            sh_basis(l, x, y, z, basis);
            for (int m = 0; m < b.n; ++m) bm[m][j] = basis[l * l + m];
        }
        // D = B A^-1; c'_k = Σ_m D[m][k] c_m.
        double band_in[7][3];
        for (int m = 0; m < b.n; ++m)
            for (int c = 0; c < 3; ++c) band_in[m][c] = in[3 * (l * l + m) + c];
        for (int k = 0; k < b.n; ++k) {
            double acc[3] = {0, 0, 0};
            for (int m = 0; m < b.n; ++m) {
                double dmk = 0.0;
                for (int j = 0; j < b.n; ++j) dmk += bm[m][j] * b.a_inv[j][k];
                for (int c = 0; c < 3; ++c) acc[c] += dmk * band_in[m][c];
            }
            for (int c = 0; c < 3; ++c) out[3 * (l * l + k) + c] = float(acc[c]);
        }
    }
}

void reflect_sh(int degree, bool flip_x, bool flip_y, bool flip_z, float* coeffs) {
    check_degree(degree);
    // Parity of each basis function of the reference basis (sh_basis above) in x, y and z: bit 0 odd in x, bit 1
    // odd in y, bit 2 odd in z. Band 1: y, z, x; band 2: xy, yz, 2zz-xx-yy, xz, xx-yy; band 3: y(3xx-yy), xyz,
    // y(4zz-xx-yy), z(2zz-3xx-3yy), x(4zz-xx-yy), z(xx-yy), x(xx-3yy).
    static constexpr unsigned char kOdd[16] = {0, 2, 4, 1, 3, 6, 0, 5, 0, 2, 7, 2, 4, 1, 4, 1};
    const unsigned flips = (flip_x ? 1u : 0u) | (flip_y ? 2u : 0u) | (flip_z ? 4u : 0u);
    const int n = (degree + 1) * (degree + 1);
    for (int k = 1; k < n; ++k) {
        unsigned odd = kOdd[k] & flips;
        const bool negate = ((odd & 1u) ^ ((odd >> 1) & 1u) ^ ((odd >> 2) & 1u)) != 0;
        if (negate)
            for (int c = 0; c < 3; ++c) coeffs[3 * k + c] = -coeffs[3 * k + c];
    }
}

}  // namespace raysplats
