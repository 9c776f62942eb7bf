#include "raysplats/render/transform.h"

#include <cmath>
#include <string>

#include "raysplats/errors.h"

namespace raysplats {

Matrix4 Matrix4::translation(float x, float y, float z) {
    Matrix4 r;
    r(0, 3) = x;
    r(1, 3) = y;
    r(2, 3) = z;
    return r;
}

Matrix4 Matrix4::scale(float x, float y, float z) {
    Matrix4 r;
    r(0, 0) = x;
    r(1, 1) = y;
    r(2, 2) = z;
    return r;
}

Matrix4 Matrix4::rotation(float angle, float x, float y, float z) {
    // Rodrigues' formula.
    const float n = std::sqrt(x * x + y * y + z * z);
    x /= n;
    y /= n;
    z /= n;
    const float c = std::cos(angle), s = std::sin(angle), t = 1.0f - c;
    Matrix4 r;
    r(0, 0) = t * x * x + c;
    r(0, 1) = t * x * y - s * z;
    r(0, 2) = t * x * z + s * y;
    r(1, 0) = t * x * y + s * z;
    r(1, 1) = t * y * y + c;
    r(1, 2) = t * y * z - s * x;
    r(2, 0) = t * x * z - s * y;
    r(2, 1) = t * y * z + s * x;
    r(2, 2) = t * z * z + c;
    return r;
}

Matrix4 Matrix4::look_at(const std::array<float, 3>& eye, const std::array<float, 3>& target,
                         const std::array<float, 3>& up) {
    auto sub = [](const std::array<float, 3>& a, const std::array<float, 3>& b) {
        return std::array<float, 3>{a[0] - b[0], a[1] - b[1], a[2] - b[2]};
    };
    auto cross = [](const std::array<float, 3>& a, const std::array<float, 3>& b) {
        return std::array<float, 3>{a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
    };
    auto normalize = [](std::array<float, 3> a) {
        const float n = std::sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
        if (!(n > 0.0f)) throw InvalidArgument("look_at: degenerate direction");
        return std::array<float, 3>{a[0] / n, a[1] / n, a[2] / n};
    };
    const auto z = normalize(sub(eye, target));  // local +Z points away from the target
    const auto x = normalize(cross(up, z));
    const auto y = cross(z, x);
    Matrix4 r;
    for (int i = 0; i < 3; ++i) {
        r(i, 0) = x[i];
        r(i, 1) = y[i];
        r(i, 2) = z[i];
        r(i, 3) = eye[i];
    }
    return r;
}

Matrix4 Matrix4::operator*(const Matrix4& b) const {
    Matrix4 r;
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j) {
            float s = 0.0f;
            for (int k = 0; k < 4; ++k) s += (*this)(i, k) * b(k, j);
            r(i, j) = s;
        }
    return r;
}

std::array<float, 3> Matrix4::transform_point(const std::array<float, 3>& p) const {
    std::array<float, 3> r;
    for (int i = 0; i < 3; ++i) r[i] = (*this)(i, 0) * p[0] + (*this)(i, 1) * p[1] + (*this)(i, 2) * p[2] + (*this)(i, 3);
    return r;
}

std::array<float, 3> Matrix4::transform_direction(const std::array<float, 3>& d) const {
    std::array<float, 3> r;
    for (int i = 0; i < 3; ++i) r[i] = (*this)(i, 0) * d[0] + (*this)(i, 1) * d[1] + (*this)(i, 2) * d[2];
    return r;
}

bool Matrix4::is_finite() const {
    for (float v : m)
        if (!std::isfinite(v)) return false;
    return true;
}

bool Matrix4::is_identity() const { return m == Matrix4{}.m; }

void Matrix4::check_affine(const char* what) const {
    if (!is_finite()) throw InvalidArgument(std::string(what) + ": matrix contains NaN or Inf");
    if (m[12] != 0.0f || m[13] != 0.0f || m[14] != 0.0f || m[15] != 1.0f)
        throw InvalidArgument(std::string(what) + ": matrix is not affine (last row must be 0 0 0 1)");
    const double det = double(m[0]) * (double(m[5]) * m[10] - double(m[6]) * m[9]) -
                       double(m[1]) * (double(m[4]) * m[10] - double(m[6]) * m[8]) +
                       double(m[2]) * (double(m[4]) * m[9] - double(m[5]) * m[8]);
    if (!(std::abs(det) > 1e-30)) throw InvalidArgument(std::string(what) + ": matrix is singular");
}

}  // namespace raysplats
