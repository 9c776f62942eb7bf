// The geometry of one face of the editing bridge (design.md §5), shared by the forward bridge (polygon_bridge.cpp)
// and the recovery (polygon_recovery.cpp): where a Gaussian's K vertices lie, the local frame its SH are kept in, and
// the Gaussian the moments of a polygon's vertices give back. Internal to the core.
//
//   v_k = m + rho_i (s1 cos θ_k a1 + s2 sin θ_k a2),  θ_k = 2πk/K               (polygon_of_gaussian)
//   C = (1/K) Σ (v_k - m)(v_k - m)^T = (rho_i²/2)(s1² a1a1^T + s2² a2a2^T)      (gaussian_of_polygon)
#pragma once

#include <cstddef>

#include "core/linear_algebra.h"
#include "raysplats/polygon_bridge.h"

namespace raysplats::polygon {

constexpr double kTwoPi = 6.283185307179586;
// Faces per task of the bridge's parallel loops over faces.
constexpr std::size_t kFacesPerTask = 4096;

// The rotation of a quaternion (w x y z) after normalising it; the identity for a zero or NaN quaternion.
la::Mat3 rotation_of(const float q[4]);

// cos θ_k and sin θ_k for every vertex of the polygon, computed once per call.
struct PolygonAngles {
    int count = 0;
    double cos[kMaxPolygonVertices];
    double sin[kMaxPolygonVertices];
    explicit PolygonAngles(int vertices_per_polygon);
};

// The polygon of one Gaussian at radius rho (a float, as stored per face): angles.count vertices, 3 floats each, to
// `out`. Import, recovery's unedited-face check and the mesh exporters all come here, so that the same Gaussian and
// rho give the same float vertices bit for bit (rho·cos θ_k in double, as the angle tables with rho folded in did
// before per-face radii: old files still match).
void polygon_of_gaussian(const float center[3], const float rotation_wxyz[4], const float scales[3],
                         const PolygonAngles& angles, float rho, float* out);

// Local SH frame F = [e1, e2, n] of a polygon: e1 from the centre towards vertex 0 (made perpendicular to n),
// n the winding (Newell) normal. Always a proper rotation.
la::Mat3 polygon_frame(const la::Vec3* v, int count, const la::Vec3& center);

// The Gaussian of one face while it is being recovered: centre, axes (columns of r), scales along them.
struct FaceGaussian {
    la::Vec3 center;
    la::Mat3 r;
    double s[3] = {0, 0, 0};
};

// Moments recovery of design.md §5: the Gaussian whose polygon at radius rho has the vertices v (any affine image
// of one), with third scale thickness · sqrt(s1 s2). Returns false for degenerate faces (scales clamped).
bool gaussian_of_polygon(const la::Vec3* v, int count, double rho, double thickness, FaceGaussian& g);

}  // namespace raysplats::polygon
