#include "core/polygon_frame.h"

#include <algorithm>
#include <cmath>

namespace raysplats::polygon {

using la::Mat3;
using la::Vec3;

Mat3 rotation_of(const float q[4]) {
    double w = q[0], x = q[1], y = q[2], z = q[3];
    const double n = std::sqrt(w * w + x * x + y * y + z * z);
    if (!(n > 0)) return Mat3();
    return la::quaternion_to_matrix(w / n, x / n, y / n, z / n);
}

PolygonAngles::PolygonAngles(int vertices_per_polygon) : count(vertices_per_polygon) {
    for (int k = 0; k < count; ++k) {
        const double theta = kTwoPi * k / count;
        cos[k] = std::cos(theta);
        sin[k] = std::sin(theta);
    }
}

void polygon_of_gaussian(const float center[3], const float rotation_wxyz[4], const float scales[3],
                         const PolygonAngles& angles, float rho, float* out) {
    const Mat3 r = rotation_of(rotation_wxyz);
    // The two largest axes span the polygon; ties keep the lower index so the choice is deterministic.
    int first = 0;
    if (scales[1] > scales[first]) first = 1;
    if (scales[2] > scales[first]) first = 2;
    int second = first == 0 ? 1 : 0;
    for (int k = 0; k < 3; ++k)
        if (k != first && scales[k] > scales[second]) second = k;
    const Vec3 a1 = r.column(first) * double(scales[first]);
    const Vec3 a2 = r.column(second) * double(scales[second]);
    for (int k = 0; k < angles.count; ++k) {
        const double c = double(rho) * angles.cos[k], s = double(rho) * angles.sin[k];
        out[3 * k + 0] = float(center[0] + c * a1.x + s * a2.x);
        out[3 * k + 1] = float(center[1] + c * a1.y + s * a2.y);
        out[3 * k + 2] = float(center[2] + c * a1.z + s * a2.z);
    }
}

Mat3 polygon_frame(const Vec3* v, int count, const Vec3& center) {
    Vec3 newell;
    for (int k = 0; k < count; ++k) newell = newell + la::cross(v[k] - center, v[(k + 1) % count] - center);
    Vec3 n = la::normalized(newell);
    if (la::norm(n) == 0) n = Vec3(0, 0, 1);
    Vec3 e1 = v[0] - center;
    e1 = la::normalized(e1 - n * la::dot(e1, n));
    if (la::norm(e1) == 0) e1 = la::any_perpendicular(n);
    Mat3 f;
    f.set_column(0, e1);
    f.set_column(1, la::cross(n, e1));
    f.set_column(2, n);
    return f;
}

namespace {

// The vertices' mean m, their covariance C (upper triangle) and their winding (Newell) normal about m.
struct PolygonMoments {
    Vec3 m;
    double c00 = 0, c01 = 0, c02 = 0, c11 = 0, c12 = 0, c22 = 0;
    Vec3 newell;
};

PolygonMoments polygon_moments(const Vec3* v, int count) {
    PolygonMoments p;
    Vec3& m = p.m;
    for (int k = 0; k < count; ++k) m = m + v[k];
    m = m * (1.0 / count);
    for (int k = 0; k < count; ++k) {
        const Vec3 d = v[k] - m;
        p.c00 += d.x * d.x, p.c01 += d.x * d.y, p.c02 += d.x * d.z, p.c11 += d.y * d.y, p.c12 += d.y * d.z,
            p.c22 += d.z * d.z;
        p.newell = p.newell + la::cross(d, v[(k + 1) % count] - m);
    }
    const double inv = 1.0 / count;
    p.c00 *= inv, p.c01 *= inv, p.c02 *= inv, p.c11 *= inv, p.c12 *= inv, p.c22 *= inv;
    return p;
}

// The smallest eigenvalue λ3 of the symmetric C (trigonometric method, Smith 1961).
double smallest_eigenvalue(const PolygonMoments& moments) {
    const double c00 = moments.c00, c01 = moments.c01, c02 = moments.c02, c11 = moments.c11, c12 = moments.c12,
                 c22 = moments.c22;
    const double q = (c00 + c11 + c22) / 3;
    const double p1 = c01 * c01 + c02 * c02 + c12 * c12;
    const double p2 = (c00 - q) * (c00 - q) + (c11 - q) * (c11 - q) + (c22 - q) * (c22 - q) + 2 * p1;
    const double p = std::sqrt(p2 / 6);
    double lambda_min = q;
    if (p > 0) {
        const double b00 = (c00 - q) / p, b11 = (c11 - q) / p, b22 = (c22 - q) / p, b01 = c01 / p, b02 = c02 / p,
                     b12 = c12 / p;
        const double det_b = b00 * (b11 * b22 - b12 * b12) - b01 * (b01 * b22 - b12 * b02) + b02 * (b01 * b12 - b11 * b02);
        const double r = std::min(1.0, std::max(-1.0, det_b / 2));
        const double phi = std::acos(r) / 3;
        lambda_min = q + 2 * p * std::cos(phi + kTwoPi / 3);
    }
    return lambda_min;
}

// The polygon's normal: the eigenvector of C's smallest eigenvalue (from the rows of C - λ3 I), oriented by the
// winding.
Vec3 moments_normal(const PolygonMoments& p, double lambda_min) {
    const double c00 = p.c00, c01 = p.c01, c02 = p.c02, c11 = p.c11, c12 = p.c12, c22 = p.c22;
    // Cross products of rows of C - λ3 I span the null direction; take the best conditioned one.
    const Vec3 r0(c00 - lambda_min, c01, c02), r1(c01, c11 - lambda_min, c12), r2(c02, c12, c22 - lambda_min);
    Vec3 best = la::cross(r0, r1);
    for (const Vec3& cand : {la::cross(r0, r2), la::cross(r1, r2)})
        if (la::dot(cand, cand) > la::dot(best, best)) best = cand;
    const double scale2 = (c00 + c11 + c22) * (c00 + c11 + c22);
    Vec3 n;
    if (la::dot(best, best) > 1e-20 * scale2 * scale2 && std::isfinite(la::dot(best, best))) {
        n = la::normalized(best);
    } else if (la::norm(p.newell) > 0) {
        n = la::normalized(p.newell);  // eigenvector ill-defined (needle-like polygon): use the winding normal
    } else {
        // Collinear or coincident: any plane containing the principal direction.
        Vec3 axis = la::dot(r0, r0) >= la::dot(r1, r1) ? r0 : r1;
        if (la::dot(r2, r2) > la::dot(axis, axis)) axis = r2;
        n = la::norm(axis) > 0 ? la::any_perpendicular(la::normalized(axis)) : Vec3(0, 0, 1);
    }
    if (la::dot(n, p.newell) < 0) n = -n;
    return n;
}

// The in-plane axes from the exact 2x2 problem of C in the plane of normal n, which stays accurate when λ1 ≈ λ2
// (round Gaussians): sets the columns of g.r (a1, n × a1, n) and returns the in-plane eigenvalues l1 >= l2 >= 0.
void in_plane_axes(const PolygonMoments& p, const Vec3& n, FaceGaussian& g, double& l1, double& l2) {
    const double c00 = p.c00, c01 = p.c01, c02 = p.c02, c11 = p.c11, c12 = p.c12, c22 = p.c22;
    // The basis (u, w) of the plane.
    const Vec3 u = la::any_perpendicular(n), w = la::cross(n, u);
    auto quad = [&](const Vec3& a, const Vec3& b) {
        return a.x * (c00 * b.x + c01 * b.y + c02 * b.z) + a.y * (c01 * b.x + c11 * b.y + c12 * b.z) +
               a.z * (c02 * b.x + c12 * b.y + c22 * b.z);
    };
    const double a = quad(u, u), b = quad(u, w), c = quad(w, w);
    const double mean = 0.5 * (a + c), radius = std::sqrt(0.25 * (a - c) * (a - c) + b * b);
    l1 = mean + radius, l2 = std::max(0.0, mean - radius);
    // Eigenvector of [[a, b], [b, c]] for l1: (b, l1 - a) or (l1 - c, b), whichever is better conditioned.
    double eu = b, ew = l1 - a;
    if (std::abs(l1 - c) > std::abs(ew)) eu = l1 - c, ew = b;
    const double en = std::sqrt(eu * eu + ew * ew);
    const Vec3 a1 = en > 0 ? u * (eu / en) + w * (ew / en) : u;
    g.r.set_column(0, a1);
    g.r.set_column(1, la::cross(n, a1));
    g.r.set_column(2, n);
}

// s = sqrt(2 λ) / rho (the face's rho_i), because (1/K) Σ cos²θ_k = 1/2 for every regular K-gon with K >= 3; the
// third scale thickness · sqrt(s1 s2). Sets g.s; false where the scales had to be clamped.
bool scales_of_eigenvalues(double l1, double l2, double rho, double thickness, FaceGaussian& g) {
    double s1 = std::sqrt(2 * l1) / rho, s2 = std::sqrt(2 * l2) / rho;
    bool ok = std::isfinite(s1) && s1 > kMinAbsoluteScale && s2 >= kMinRelativeScale * s1;
    if (!std::isfinite(s1)) s1 = kMinAbsoluteScale;
    s1 = std::max(s1, kMinAbsoluteScale);
    s2 = std::max({s2, kMinRelativeScale * s1, kMinAbsoluteScale});
    g.s[0] = s1, g.s[1] = s2;
    g.s[2] = std::max(kMinAbsoluteScale, (std::isfinite(thickness) ? std::max(0.0, thickness) : 0.0) * std::sqrt(s1 * s2));
    return ok;
}

}  // namespace

bool gaussian_of_polygon(const Vec3* v, int count, double rho, double thickness, FaceGaussian& g) {
    const PolygonMoments moments = polygon_moments(v, count);
    g.center = moments.m;
    const Vec3 n = moments_normal(moments, smallest_eigenvalue(moments));
    double l1 = 0, l2 = 0;
    in_plane_axes(moments, n, g, l1, l2);
    return scales_of_eigenvalues(l1, l2, rho, thickness, g);
}

}  // namespace raysplats::polygon
