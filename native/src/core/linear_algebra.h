// Small fixed-size linear algebra in double for per-Gaussian numerics. Matrices are row-major 3x3 arrays.
// (quaternion_to_rotation is generic: the renderer uses it in float.)
#pragma once

#include <algorithm>
#include <array>
#include <cmath>

namespace raysplats::la {

struct Vec3 {
    double x = 0, y = 0, z = 0;
    Vec3() = default;
    Vec3(double x_, double y_, double z_) : x(x_), y(y_), z(z_) {}
    Vec3 operator+(const Vec3& o) const { return {x + o.x, y + o.y, z + o.z}; }
    Vec3 operator-(const Vec3& o) const { return {x - o.x, y - o.y, z - o.z}; }
    Vec3 operator*(double s) const { return {x * s, y * s, z * s}; }
    Vec3 operator-() const { return {-x, -y, -z}; }
};
inline double dot(const Vec3& a, const Vec3& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
inline Vec3 cross(const Vec3& a, const Vec3& b) {
    return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
inline double norm(const Vec3& a) { return std::sqrt(dot(a, a)); }
inline Vec3 normalized(const Vec3& a) {
    const double n = norm(a);
    return n > 0 ? a * (1.0 / n) : a;
}
// Some unit vector perpendicular to the unit vector n.
inline Vec3 any_perpendicular(const Vec3& n) {
    const Vec3 helper = std::abs(n.x) < 0.6 ? Vec3(1, 0, 0) : (std::abs(n.y) < 0.6 ? Vec3(0, 1, 0) : Vec3(0, 0, 1));
    return normalized(cross(n, helper));
}

struct Mat3 {
    double m[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
    double& operator()(int r, int c) { return m[3 * r + c]; }
    double operator()(int r, int c) const { return m[3 * r + c]; }
    Vec3 column(int c) const { return {m[c], m[3 + c], m[6 + c]}; }
    void set_column(int c, const Vec3& v) { m[c] = v.x, m[3 + c] = v.y, m[6 + c] = v.z; }
};
inline Mat3 operator*(const Mat3& a, const Mat3& b) {
    Mat3 r;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) r(i, j) = a(i, 0) * b(0, j) + a(i, 1) * b(1, j) + a(i, 2) * b(2, j);
    return r;
}
inline Vec3 operator*(const Mat3& a, const Vec3& v) {
    return {a(0, 0) * v.x + a(0, 1) * v.y + a(0, 2) * v.z, a(1, 0) * v.x + a(1, 1) * v.y + a(1, 2) * v.z,
            a(2, 0) * v.x + a(2, 1) * v.y + a(2, 2) * v.z};
}
inline Mat3 transpose(const Mat3& a) {
    Mat3 r;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) r(i, j) = a(j, i);
    return r;
}
inline double determinant(const Mat3& a) {
    return a(0, 0) * (a(1, 1) * a(2, 2) - a(1, 2) * a(2, 1)) - a(0, 1) * (a(1, 0) * a(2, 2) - a(1, 2) * a(2, 0)) +
           a(0, 2) * (a(1, 0) * a(2, 1) - a(1, 1) * a(2, 0));
}

// Rotation matrix, row-major, of a unit quaternion (w, x, y, z) (reference 3DGS build_rotation), computed in T: the
// renderer builds its Gaussians' axes in float (its images depend on that rounding), the polygon bridge in double.
template <class T>
inline std::array<T, 9> quaternion_to_rotation(T w, T x, T y, T z) {
    return {1 - 2 * (y * y + z * z), 2 * (x * y - w * z),     2 * (x * z + w * y),
            2 * (x * y + w * z),     1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
            2 * (x * z - w * y),     2 * (y * z + w * x),     1 - 2 * (x * x + y * y)};
}
inline Mat3 quaternion_to_matrix(double w, double x, double y, double z) {
    Mat3 r;
    const std::array<double, 9> m = quaternion_to_rotation(w, x, y, z);
    std::copy(m.begin(), m.end(), r.m);
    return r;
}

// Unit quaternion (w, x, y, z), w >= 0, of a proper rotation matrix (Shepperd's method: branch on the
// largest diagonal combination for accuracy).
inline void matrix_to_quaternion(const Mat3& r, double q[4]) {
    const double tr = r(0, 0) + r(1, 1) + r(2, 2);
    if (tr > 0) {
        const double s = std::sqrt(tr + 1.0) * 2;
        q[0] = 0.25 * s, q[1] = (r(2, 1) - r(1, 2)) / s, q[2] = (r(0, 2) - r(2, 0)) / s, q[3] = (r(1, 0) - r(0, 1)) / s;
    } else if (r(0, 0) > r(1, 1) && r(0, 0) > r(2, 2)) {
        const double s = std::sqrt(1.0 + r(0, 0) - r(1, 1) - r(2, 2)) * 2;
        q[0] = (r(2, 1) - r(1, 2)) / s, q[1] = 0.25 * s, q[2] = (r(0, 1) + r(1, 0)) / s, q[3] = (r(0, 2) + r(2, 0)) / s;
    } else if (r(1, 1) > r(2, 2)) {
        const double s = std::sqrt(1.0 + r(1, 1) - r(0, 0) - r(2, 2)) * 2;
        q[0] = (r(0, 2) - r(2, 0)) / s, q[1] = (r(0, 1) + r(1, 0)) / s, q[2] = 0.25 * s, q[3] = (r(1, 2) + r(2, 1)) / s;
    } else {
        const double s = std::sqrt(1.0 + r(2, 2) - r(0, 0) - r(1, 1)) * 2;
        q[0] = (r(1, 0) - r(0, 1)) / s, q[1] = (r(0, 2) + r(2, 0)) / s, q[2] = (r(1, 2) + r(2, 1)) / s, q[3] = 0.25 * s;
    }
    const double n = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    const double sign = q[0] < 0 ? -1.0 : 1.0;
    for (int i = 0; i < 4; ++i) q[i] *= sign / n;
}

// Eigen-decomposition of a symmetric 3x3 matrix by cyclic Jacobi rotations (Golub & Van Loan §8.5):
// a = V diag(values) V^T, values sorted descending, V's columns the eigenvectors, det(V) = +1.
inline void symmetric_eigen(const Mat3& a_in, double values[3], Mat3& v) {
    Mat3 a = a_in;
    v = Mat3();
    for (int sweep = 0; sweep < 32; ++sweep) {
        const double off = a(0, 1) * a(0, 1) + a(0, 2) * a(0, 2) + a(1, 2) * a(1, 2);
        const double diag = a(0, 0) * a(0, 0) + a(1, 1) * a(1, 1) + a(2, 2) * a(2, 2);
        if (off <= 1e-30 * diag || off == 0.0) break;
        for (int p = 0; p < 2; ++p)
            for (int q = p + 1; q < 3; ++q) {
                const double apq = a(p, q);
                if (apq == 0.0) continue;
                const double theta = (a(q, q) - a(p, p)) / (2 * apq);
                const double t = (theta >= 0 ? 1.0 : -1.0) / (std::abs(theta) + std::sqrt(theta * theta + 1));
                const double c = 1 / std::sqrt(t * t + 1), s = t * c;
                for (int k = 0; k < 3; ++k) {  // a <- J^T a J
                    const double akp = a(k, p), akq = a(k, q);
                    a(k, p) = c * akp - s * akq;
                    a(k, q) = s * akp + c * akq;
                }
                for (int k = 0; k < 3; ++k) {
                    const double apk = a(p, k), aqk = a(q, k);
                    a(p, k) = c * apk - s * aqk;
                    a(q, k) = s * apk + c * aqk;
                }
                for (int k = 0; k < 3; ++k) {
                    const double vkp = v(k, p), vkq = v(k, q);
                    v(k, p) = c * vkp - s * vkq;
                    v(k, q) = s * vkp + c * vkq;
                }
            }
    }
    int order[3] = {0, 1, 2};
    std::sort(order, order + 3, [&](int i, int j) { return a(i, i) > a(j, j); });
    Mat3 sorted;
    for (int c = 0; c < 3; ++c) {
        values[c] = a(order[c], order[c]);
        sorted.set_column(c, v.column(order[c]));
    }
    if (determinant(sorted) < 0) sorted.set_column(2, -sorted.column(2));
    v = sorted;
}

}  // namespace raysplats::la
