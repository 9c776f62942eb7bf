#include "raysplats/polygon_bridge.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>

#include "core/linear_algebra.h"
#include "raysplats/errors.h"
#include "raysplats/spherical_harmonics.h"

namespace raysplats {
namespace {

using la::Mat3;

// Random Gaussians with centres in [-2, 2]^3, log-uniform scales in [0.05, 1], random rotations. Scales are
// kept comparable to the centres so that the float32 vertex positions (as Blender stores them) resolve the
// polygon to ~1e-7: the tests then measure the recovery, not float32 storage.
GaussianCloud random_cloud(std::size_t n, int degree, unsigned seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> pos(-2.0f, 2.0f), logs(-3.0f, 0.0f), op(0.05f, 1.0f), sh(-0.5f, 0.5f);
    std::normal_distribution<float> g;
    GaussianCloud c;
    c.resize(n, degree);
    for (std::size_t i = 0; i < n; ++i) {
        for (int k = 0; k < 3; ++k) c.positions[3 * i + k] = pos(rng), c.scales[3 * i + k] = std::exp(logs(rng));
        float q[4] = {g(rng), g(rng), g(rng), g(rng)};
        const float qn = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
        for (int k = 0; k < 4; ++k) c.rotations[4 * i + k] = q[k] / qn;
        c.opacities[i] = op(rng);
    }
    for (float& v : c.sh) v = sh(rng);
    return c;
}

// rho_i of docs/design.md §5, written out independently of the bridge: a·exp(-r²/2) = 1/255 at r = sqrt(2 ln(255 a)).
double expected_visible_radius(double opacity, double rho) {
    return opacity * 255.0 > 1.0 ? std::min(rho, std::sqrt(2.0 * std::log(255.0 * opacity))) : 0.0;
}

Mat3 covariance(const float q[4], const float s[3]) {
    const Mat3 r = la::quaternion_to_matrix(q[0], q[1], q[2], q[3]);
    Mat3 c;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) {
            double acc = 0;
            for (int k = 0; k < 3; ++k) acc += r(i, k) * double(s[k]) * s[k] * r(j, k);
            c(i, j) = acc;
        }
    return c;
}

// Covariance restricted to the two largest axes: the part a flat polygon carries.
Mat3 planar_covariance(const float q[4], const float s[3]) {
    float t[3] = {s[0], s[1], s[2]};
    int smallest = 0;
    for (int k = 1; k < 3; ++k)
        if (s[k] < s[smallest]) smallest = k;
    t[smallest] = 0;
    return covariance(q, t);
}

double relative_difference(const Mat3& a, const Mat3& b) {
    double diff = 0, ref = 0;
    for (int i = 0; i < 9; ++i) diff += (a.m[i] - b.m[i]) * (a.m[i] - b.m[i]), ref += b.m[i] * b.m[i];
    return std::sqrt(diff / ref);
}

Mat3 random_affine(std::mt19937& rng, bool reflect) {
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    Mat3 a;
    do {
        for (double& x : a.m) x = u(rng);
        for (int i = 0; i < 3; ++i) a(i, i) += 1.5;
    } while (std::abs(la::determinant(a)) < 0.2);
    if ((la::determinant(a) < 0) != reflect) a.set_column(0, -a.column(0));
    return a;
}

TEST(PolygonBridge, VisibleRadiusIsWhereTheGaussianFallsTo1Over255) {
    EXPECT_EQ(visible_polygon_radius(1.0f, 3.0f), 3.0f);   // opaque: capped at rho, bit for bit
    EXPECT_EQ(visible_polygon_radius(0.36f, 3.0f), 3.0f);  // the cap holds down to a = exp(4.5)/255 = 0.3529
    EXPECT_LT(visible_polygon_radius(0.35f, 3.0f), 3.0f);
    for (float a : {0.35f, 0.1f, 0.02f, 0.005f, 0.0040f}) {
        const float r = visible_polygon_radius(a, 3.0f);
        EXPECT_NEAR(r, std::sqrt(2 * std::log(255.0 * a)), 1e-6) << a;
        EXPECT_NEAR(a * std::exp(-0.5 * double(r) * r), 1.0 / 255, 1e-6 / 255) << a;  // the rim is at the threshold
    }
    // Nothing visible: below 1/255 (the nearest float to 1/255 lies above it), zero, negative, NaN.
    EXPECT_GT(visible_polygon_radius(1.0f / 255.0f, 3.0f), 0.0f);
    EXPECT_EQ(visible_polygon_radius(std::nextafter(1.0f / 255.0f, 0.0f), 3.0f), 0.0f);
    for (float a : {0.0f, -0.5f, float(NAN)}) EXPECT_EQ(visible_polygon_radius(a, 3.0f), 0.0f) << a;
    EXPECT_EQ(visible_polygon_radius(0.1f, 1.5f), 1.5f);
}

TEST(PolygonBridge, PolygonVerticesLieOnTheirVisibleRadiusEllipse) {
    GaussianCloud c = random_cloud(50, 0, 1);
    for (std::size_t i = 0; i < 50; i += 5) c.opacities[i] = 1.0f;  // some at rho itself
    PolygonSettings settings{8, 3.0f};
    SplatPolygons p = gaussians_to_polygons(c, settings);
    ASSERT_EQ(p.vertex_positions.size(), 50u * 8 * 3);
    std::size_t smaller = 0;
    for (std::size_t i = 0; i < 50; ++i) {
        const double rho_i = expected_visible_radius(c.opacities[i], 3.0);
        EXPECT_NEAR(p.polygon_radius[i], rho_i, 1e-6);
        smaller += rho_i < 3.0;
        // Mahalanobis distance of each vertex from the centre, in the polygon's plane, is rho_i.
        const Mat3 r = la::quaternion_to_matrix(c.rotations[4 * i], c.rotations[4 * i + 1], c.rotations[4 * i + 2],
                                                c.rotations[4 * i + 3]);
        for (int k = 0; k < 8; ++k) {
            la::Vec3 d(p.vertex_positions[3 * (8 * i + k)] - c.positions[3 * i],
                       p.vertex_positions[3 * (8 * i + k) + 1] - c.positions[3 * i + 1],
                       p.vertex_positions[3 * (8 * i + k) + 2] - c.positions[3 * i + 2]);
            double m2 = 0;
            for (int a = 0; a < 3; ++a) {
                const double proj = la::dot(d, r.column(a)) / c.scales[3 * i + a];
                m2 += proj * proj;
            }
            EXPECT_NEAR(std::sqrt(m2), rho_i, 1e-3);
            // The corner's UV is its local polygon coordinate (|uv| = rho_i) and its colour's alpha the opacity, so
            // the material's a·exp(-|uv|²/2) is the Gaussian's value there: 1/255 on the rim of a faint one.
            const float* uv = &p.corner_uvs[2 * (8 * i + k)];
            EXPECT_NEAR(std::hypot(uv[0], uv[1]), rho_i, 1e-6);
            EXPECT_NEAR(std::atan2(uv[1], uv[0]), std::remainder(2 * M_PI * k / 8, 2 * M_PI), 1e-6);
            // (The colour's alpha is a byte: the opacity to 1/510.)
            const double alpha = p.corner_colors[4 * (8 * i + k) + 3] / 255.0;
            EXPECT_NEAR(alpha, c.opacities[i], 0.5 / 255 + 1e-9);
            const double rim = c.opacities[i] * std::exp(-0.5 * (double(uv[0]) * uv[0] + double(uv[1]) * uv[1]));
            EXPECT_NEAR(rim, std::max(1.0 / 255, c.opacities[i] * std::exp(-4.5)), 1e-8);
        }
    }
    EXPECT_GT(smaller, 8u);  // the test covers faint Gaussians (opacities 0.05..1: about a third)
}

TEST(PolygonBridge, RecoveryIsExactForEveryK) {
    for (int k : {3, 4, 5, 8, 17, 64}) {
        GaussianCloud c = random_cloud(200, 0, 100 + k);
        PolygonSettings settings{k, 2.5f};
        SplatPolygons p = gaussians_to_polygons(c, settings);
        SplatFaceAttributesView attr;
        attr.thickness = p.thickness.data();
        attr.polygon_radius = p.polygon_radius.data();
        RecoveryOptions options;
        options.polygon = settings;
        RecoveryStats stats;
        GaussianCloud r = recover_gaussians_from_polygons(mesh_view(p), attr, options, &stats);
        ASSERT_EQ(r.size(), c.size());
        EXPECT_EQ(stats.recovered, 200u);
        for (std::size_t i = 0; i < c.size(); ++i) {
            EXPECT_LT(relative_difference(covariance(&r.rotations[4 * i], &r.scales[3 * i]),
                                          covariance(&c.rotations[4 * i], &c.scales[3 * i])),
                      1e-5)
                << "K=" << k << " face " << i;
            for (int a = 0; a < 3; ++a) EXPECT_NEAR(r.positions[3 * i + a], c.positions[3 * i + a], 1e-6);
        }
    }
}

// Imports store no thickness: recovery takes each face's from its rest scales, so an edited face (here every
// face, moved) comes back exactly as with the thickness stored; without rest scales either, the polygon is flat.
TEST(PolygonBridge, RecoveryWithoutThicknessTakesItFromTheRestScales) {
    GaussianCloud c = random_cloud(100, 0, 77);
    PolygonSettings settings{4, 3.0f};
    SplatPolygons p = gaussians_to_polygons(c, settings);
    for (float& v : p.vertex_positions) v += 0.25f;
    SplatFaceAttributesView attr = attributes_view(p);
    RecoveryOptions options;
    options.polygon = settings;
    RecoveryStats stats;
    const GaussianCloud stored = recover_gaussians_from_polygons(mesh_view(p), attr, options, &stats);
    EXPECT_EQ(stats.recovered, 100u);
    attr.thickness = nullptr;
    const GaussianCloud recomputed = recover_gaussians_from_polygons(mesh_view(p), attr, options);
    EXPECT_EQ(recomputed.scales, stored.scales);
    EXPECT_EQ(recomputed.rotations, stored.rotations);
    attr.rest_scales = nullptr;
    const GaussianCloud flat = recover_gaussians_from_polygons(mesh_view(p), attr, options);
    EXPECT_NE(flat.scales, stored.scales);
}

// The per-face radius comes back from the polygon UVs bit for bit (imports keep no radius attribute), for every K, also
// with a face's corners reversed (a reflection); a face without such a corner gives 0 (the object's rho).
TEST(PolygonBridge, PolygonRadiusComesBackFromTheUvsExactly) {
    for (int k : {3, 4, 8, 17}) {
        GaussianCloud c = random_cloud(300, 0, 40 + k);
        for (std::size_t i = 0; i < c.size(); ++i) c.opacities[i] = 0.01f + 0.99f * float(i) / float(c.size());
        const SplatPolygons p = gaussians_to_polygons(c, {k, 3.0f});
        std::vector<float> uvs = p.corner_uvs;
        // Face 0's corners reversed, face 1's UVs zero (a face the user drew).
        for (int a = 0; a < k / 2; ++a)
            for (int b = 0; b < 2; ++b) std::swap(uvs[2 * a + b], uvs[2 * (k - 1 - a) + b]);
        for (int a = 0; a < 2 * k; ++a) uvs[2 * k + a] = 0.0f;
        const std::vector<float> radius = polygon_radius_from_uvs(mesh_view(p), uvs.data());
        ASSERT_EQ(radius.size(), p.polygon_radius.size());
        EXPECT_EQ(radius[0], p.polygon_radius[0]);
        EXPECT_EQ(radius[1], 0.0f);
        for (std::size_t f = 2; f < radius.size(); ++f) EXPECT_EQ(radius[f], p.polygon_radius[f]) << "K=" << k;
    }
}

// The core property of docs/design.md §5: an affine image of the polygon is the polygon of the affinely transformed
// Gaussian, whatever the face's own radius rho_i. Applied to the mesh vertices (as a lattice or an edit would),
// including reflections; opacities down to 0.01 give radii rho_i from 1.6 to rho.
TEST(PolygonBridge, RecoveryIsExactUnderAffineMapsOfTheVerticesWithPerFaceRadii) {
    std::mt19937 rng(11);
    std::uniform_real_distribution<float> log_opacity(std::log(0.01f), 0.0f);
    for (bool reflect : {false, true}) {
        GaussianCloud c = random_cloud(300, 0, reflect ? 5 : 6);
        for (float& a : c.opacities) a = std::exp(log_opacity(rng));
        PolygonSettings settings{8, 3.0f};
        SplatPolygons p = gaussians_to_polygons(c, settings);
        ASSERT_EQ(p.face_corner_start.size(), c.size());
        const float smallest = *std::min_element(p.polygon_radius.begin(), p.polygon_radius.end());
        const std::size_t capped = std::count(p.polygon_radius.begin(), p.polygon_radius.end(), 3.0f);
        EXPECT_LT(smallest, 1.8f);
        EXPECT_GT(capped, 10u);
        EXPECT_LT(capped, 150u);
        std::vector<Mat3> maps(c.size());
        for (std::size_t i = 0; i < c.size(); ++i) {
            maps[i] = random_affine(rng, reflect);
            for (int k = 0; k < 8; ++k) {
                float* v = &p.vertex_positions[3 * (8 * i + k)];
                const la::Vec3 x = maps[i] * la::Vec3(v[0], v[1], v[2]);
                v[0] = float(x.x + 0.3), v[1] = float(x.y - 0.2), v[2] = float(x.z + 0.1);
            }
        }
        RecoveryOptions options;
        options.polygon = settings;
        SplatFaceAttributesView attr;
        attr.polygon_radius = p.polygon_radius.data();
        GaussianCloud r = recover_gaussians_from_polygons(mesh_view(p), attr, options);
        for (std::size_t i = 0; i < c.size(); ++i) {
            const float* q = &r.rotations[4 * i];
            const Mat3 rot = la::quaternion_to_matrix(q[0], q[1], q[2], q[3]);
            EXPECT_NEAR(la::determinant(rot), 1.0, 1e-6);
            const Mat3 expected = maps[i] * planar_covariance(&c.rotations[4 * i], &c.scales[3 * i]) * la::transpose(maps[i]);
            EXPECT_LT(relative_difference(planar_covariance(q, &r.scales[3 * i]), expected), 1e-5) << "face " << i;
            const la::Vec3 m = maps[i] * la::Vec3(c.positions[3 * i], c.positions[3 * i + 1], c.positions[3 * i + 2]);
            EXPECT_NEAR(r.positions[3 * i], m.x + 0.3, 1e-5);
            EXPECT_NEAR(r.positions[3 * i + 2], m.z + 0.1, 1e-5);
        }
    }
}

// Unedited faces give back the imported Gaussian bit for bit; an object-level affine map transforms the full
// 3D covariance exactly: Σ' = A Σ A^T.
TEST(PolygonBridge, UneditedFacesAreExactAndObjectTransformsApplyToTheFullCovariance) {
    GaussianCloud c = random_cloud(400, 0, 21);
    PolygonSettings settings{8, 3.0f};
    SplatPolygons p = gaussians_to_polygons(c, settings);
    // The face attributes are the cloud's own values (every Gaussian of random_cloud is visible).
    ASSERT_EQ(p.invisible_skipped, 0u);
    EXPECT_EQ(p.opacity, c.opacities);
    EXPECT_EQ(p.rest_centers, c.positions);
    EXPECT_EQ(p.rest_rotations, c.rotations);
    EXPECT_EQ(p.rest_scales, c.scales);
    const SplatFaceAttributesView attr = attributes_view(p);
    RecoveryOptions options;
    options.polygon = settings;
    RecoveryStats stats;
    GaussianCloud same = recover_gaussians_from_polygons(mesh_view(p), attr, options, &stats);
    EXPECT_EQ(stats.unedited, 400u);
    EXPECT_EQ(same.positions, c.positions);
    EXPECT_EQ(same.rotations, c.rotations);
    EXPECT_EQ(same.scales, c.scales);
    EXPECT_EQ(same.opacities, c.opacities);

    std::mt19937 rng(4);
    for (int trial = 0; trial < 4; ++trial) {
        Mat3 a = random_affine(rng, trial % 2 == 1);
        if (trial == 2) {  // a pure rotation with uniform scale: the similarity path
            a = la::quaternion_to_matrix(0.5, 0.5, -0.5, 0.5);
            for (double& x : a.m) x *= 2.0;
        }
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j) options.mesh_to_output[4 * i + j] = a(i, j);
        options.mesh_to_output[3] = 1.0, options.mesh_to_output[7] = -2.0, options.mesh_to_output[11] = 0.5;
        GaussianCloud t = recover_gaussians_from_polygons(mesh_view(p), attr, options, &stats);
        EXPECT_EQ(stats.unedited, 400u);
        for (std::size_t i = 0; i < c.size(); ++i) {
            const Mat3 expected = a * covariance(&c.rotations[4 * i], &c.scales[3 * i]) * la::transpose(a);
            EXPECT_LT(relative_difference(covariance(&t.rotations[4 * i], &t.scales[3 * i]), expected), 1e-5);
            const la::Vec3 m = a * la::Vec3(c.positions[3 * i], c.positions[3 * i + 1], c.positions[3 * i + 2]);
            EXPECT_NEAR(t.positions[3 * i + 1], m.y - 2.0, 1e-5);
        }
    }
}

// A stored rest rotation holding NaN (or zero) was exported unchanged when the face matched the polygon of the
// identity rotation (rotation_of() takes a non-rotation as the identity). Now such a face is recovered from its
// polygon, and counted.
TEST(PolygonBridge, NonFiniteRestRotationIsRecoveredNotExported) {
    GaussianCloud c = random_cloud(4, 0, 5);
    c.rotations[0] = 1, c.rotations[1] = c.rotations[2] = c.rotations[3] = 0;  // face 0: the identity's polygon
    c.rotations[4] = 1, c.rotations[5] = c.rotations[6] = c.rotations[7] = 0;  // face 1 likewise
    const PolygonSettings settings{8, 3.0f};
    const SplatPolygons p = gaussians_to_polygons(c, settings);
    std::vector<float> rest_rotations = c.rotations;
    const float nan = std::numeric_limits<float>::quiet_NaN();
    std::fill(rest_rotations.begin(), rest_rotations.begin() + 4, nan);
    std::fill(rest_rotations.begin() + 4, rest_rotations.begin() + 8, 0.0f);
    SplatFaceAttributesView attr = attributes_view(p);  // with each face's own radius
    attr.rest_rotations = rest_rotations.data();
    RecoveryOptions options;
    options.polygon = settings;
    RecoveryStats stats;
    const GaussianCloud out = recover_gaussians_from_polygons(mesh_view(p), attr, options, &stats);
    ASSERT_EQ(out.size(), 4u);
    EXPECT_EQ(stats.invalid_rest_rotation, 2u);
    EXPECT_EQ(stats.unedited, 2u);
    EXPECT_EQ(stats.recovered, 2u);
    for (float v : out.rotations) EXPECT_TRUE(std::isfinite(v));
    for (int i = 0; i < 2; ++i)  // the polygon's Gaussian: the identity rotation's covariance in the polygon plane
        EXPECT_LT(relative_difference(planar_covariance(&out.rotations[4 * i], &out.scales[3 * i]),
                                      planar_covariance(&c.rotations[4 * i], &c.scales[3 * i])), 1e-4) << i;
}

// The viewport's partial recovery: faces_with_moved_vertices finds exactly the faces an edit touched, and
// recovering only them gives the same rows as a full recovery, bit for bit (SH degree 3 and an object transform,
// so the moment recovery, the SH rotation and the unedited pass-through all run).
// Found by fuzzing (native/fuzz/fuzz_polygon_bridge.cpp): a stored rest scale that is negative matched its face's
// polygon exactly (the polygon of -s is that of s turned half a turn), so the negative scale was exported as stored
// and the recovered cloud failed its own check. Such a face is recovered from its polygon, and counted.
TEST(PolygonBridge, NegativeRestScaleIsRecoveredNotExported) {
    GaussianCloud c = random_cloud(3, 1, 11);
    c.scales[0] = -c.scales[0];  // Gaussian 0: the polygon and the rest scales made from a negative scale
    const PolygonSettings settings{8, 3.0f};
    const SplatPolygons p = gaussians_to_polygons(c, settings);
    ASSERT_EQ(p.opacity.size(), 3u);
    std::vector<float> rest_scales = p.rest_scales;
    rest_scales[3 * 2 + 1] = std::numeric_limits<float>::quiet_NaN();  // Gaussian 2: a NaN rest scale
    SplatFaceAttributesView attr = attributes_view(p);
    attr.rest_scales = rest_scales.data();
    RecoveryOptions options;
    options.polygon = settings;
    RecoveryStats stats;
    const GaussianCloud out = recover_gaussians_from_polygons(mesh_view(p), attr, options, &stats);
    ASSERT_EQ(out.size(), 3u);
    EXPECT_EQ(stats.invalid_rest_scale, 2u);
    EXPECT_EQ(stats.unedited, 1u);
    EXPECT_EQ(stats.recovered, 2u);
    EXPECT_NO_THROW(out.check_values("recovered"));
    // Face 0's Gaussian from its polygon: the same covariance in the polygon's plane (a sign of a scale means nothing).
    const float magnitudes[3] = {std::fabs(c.scales[0]), c.scales[1], c.scales[2]};
    EXPECT_LT(relative_difference(planar_covariance(&out.rotations[0], &out.scales[0]),
                                  planar_covariance(&c.rotations[0], magnitudes)), 1e-4);
}

// Found by fuzzing: a face whose Gaussian overflows float32 (a corner 5e18 away and a stored polygon radius of 2e-38,
// so a scale near 1e56) was exported with an infinite scale. It is dropped and counted instead.
TEST(PolygonBridge, GaussianBeyondFloatRangeIsDroppedNotExported) {
    const float positions[] = {0, 0, 0, 1, 0, -4.8e18f, 0, 0, 0, 0, 1, 0,   // face 0: far out
                               0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0};          // face 1: a unit square
    const std::int32_t corners[] = {0, 1, 2, 3, 4, 5, 6, 7}, starts[] = {0, 4}, counts[] = {4, 4};
    PolygonMeshView mesh;
    mesh.vertex_positions = positions, mesh.vertex_count = 8;
    mesh.corner_vertices = corners, mesh.corner_count = 8;
    mesh.face_corner_start = starts, mesh.face_corner_count = counts, mesh.face_count = 2;
    const float radius[] = {2.35e-38f, 0.0f};  // 0: the object's rho
    SplatFaceAttributesView attr;
    attr.polygon_radius = radius;
    RecoveryOptions options;
    options.polygon = PolygonSettings{4, 2.5f};
    RecoveryStats stats;
    GaussianCloud out = recover_gaussians_from_polygons(mesh, attr, options, &stats);
    EXPECT_EQ(stats.dropped, 1u);
    EXPECT_EQ(stats.recovered, 1u);
    ASSERT_EQ(out.size(), 1u);
    EXPECT_NO_THROW(out.check_values("recovered"));
    EXPECT_NEAR(out.positions[0], 0.5f, 1e-6);  // the unit square's Gaussian is what is left
    attr.polygon_radius = nullptr;  // at the object's rho the far face's scales (~1e18) fit
    out = recover_gaussians_from_polygons(mesh, attr, options, &stats);
    EXPECT_EQ(stats.dropped, 0u);
    EXPECT_EQ(stats.recovered, 2u);
    EXPECT_NO_THROW(out.check_values("recovered"));
}

TEST(PolygonBridge, SubsetRecoveryEqualsTheFullRecoveryOfEditedFaces) {
    GaussianCloud c = random_cloud(300, 3, 31);
    PolygonSettings settings{8, 3.0f};
    SplatPolygons p = gaussians_to_polygons(c, settings);
    const std::vector<float> before = p.vertex_positions;
    // Edit: one vertex of face 10 and all of face 200 (each face owns its 8 vertices here).
    p.vertex_positions[3 * (8 * 10 + 3) + 1] += 0.01f;
    for (int k = 0; k < 8; ++k) p.vertex_positions[3 * (8 * 200 + k)] += 0.5f;
    p.vertex_positions[3 * (8 * 77 + 5) + 2] = p.vertex_positions[3 * (8 * 77 + 5) + 2];  // rewritten, unchanged
    const std::vector<std::uint32_t> moved = faces_with_moved_vertices(mesh_view(p), before.data());
    EXPECT_EQ(moved, (std::vector<std::uint32_t>{10, 200}));

    const SplatFaceAttributesView attr = attributes_view(p);
    EXPECT_EQ(attr.sh_degree, 3);
    RecoveryOptions options;
    options.polygon = settings;
    options.mesh_to_output[0] = 2.0, options.mesh_to_output[3] = 0.5, options.mesh_to_output[6] = 0.3;
    const GaussianCloud full = recover_gaussians_from_polygons(mesh_view(p), attr, options);
    const std::uint32_t faces[] = {200, 10, 11};  // any order; 11 is unedited
    RecoveryStats stats;
    const GaussianCloud part = recover_gaussians_from_polygons(mesh_view(p), attr, options, &stats, faces, 3);
    ASSERT_EQ(part.size(), 3u);
    EXPECT_EQ(stats.recovered, 2u);
    EXPECT_EQ(stats.unedited, 1u);
    const std::size_t k = std::size_t(full.coeffs_per_channel()) * 3;
    for (std::size_t o = 0; o < 3; ++o) {
        const std::size_t f = faces[o];
        for (int j = 0; j < 3; ++j) EXPECT_EQ(part.positions[3 * o + j], full.positions[3 * f + j]);
        for (int j = 0; j < 4; ++j) EXPECT_EQ(part.rotations[4 * o + j], full.rotations[4 * f + j]);
        for (int j = 0; j < 3; ++j) EXPECT_EQ(part.scales[3 * o + j], full.scales[3 * f + j]);
        EXPECT_EQ(part.opacities[o], full.opacities[f]);
        for (std::size_t j = 0; j < k; ++j) EXPECT_EQ(part.sh[k * o + j], full.sh[k * f + j]);
    }
    const std::uint32_t missing[] = {300};
    EXPECT_THROW(recover_gaussians_from_polygons(mesh_view(p), attr, options, nullptr, missing, 1), InvalidArgument);
}

// Gaussians nothing of which is visible (opacity below 1/255) get no face and are counted; the faces of the others
// carry their own Gaussian, in order, and an untouched recovery gives exactly those back.
TEST(PolygonBridge, InvisibleGaussiansGetNoFaceAndAreCounted) {
    GaussianCloud c = random_cloud(8, 2, 41);
    const float just_below = std::nextafter(1.0f / 255.0f, 0.0f);
    const float opacities[8] = {0.5f, just_below, 0.0f, 0.002f, 1.0f / 255.0f, 0.9f, 0.01f, 0.003f};
    std::copy(opacities, opacities + 8, c.opacities.begin());
    const std::size_t visible[] = {0, 4, 5, 6};
    const PolygonSettings settings{6, 3.0f};
    SplatPolygons p = gaussians_to_polygons(c, settings);
    EXPECT_EQ(p.invisible_skipped, 4u);
    ASSERT_EQ(p.face_corner_start.size(), 4u);
    ASSERT_EQ(p.vertex_positions.size(), 4u * 6 * 3);
    ASSERT_EQ(p.sh_local.size(), 4u * 9 * 3);
    for (std::size_t f = 0; f < 4; ++f) {
        const std::size_t i = visible[f];
        EXPECT_EQ(p.face_corner_start[f], std::int32_t(6 * f));
        EXPECT_EQ(p.opacity[f], c.opacities[i]);
        EXPECT_NEAR(p.polygon_radius[f], expected_visible_radius(c.opacities[i], 3.0), 1e-6);
        EXPECT_GT(p.polygon_radius[f], 0.0f);
        for (int k = 0; k < 3; ++k) EXPECT_EQ(p.rest_centers[3 * f + k], c.positions[3 * i + k]);
        for (int k = 0; k < 4; ++k) EXPECT_EQ(p.rest_rotations[4 * f + k], c.rotations[4 * i + k]);
        for (int k = 0; k < 3; ++k) EXPECT_EQ(p.rest_scales[3 * f + k], c.scales[3 * i + k]);
        EXPECT_EQ(p.corner_colors[4 * 6 * f + 3], std::uint8_t(c.opacities[i] * 255.0 + 0.5));
        EXPECT_EQ(p.thickness[f], gaussian_thickness(&c.scales[3 * i]));
        // The face's polygon is the one gaussian_polygon() makes at rho_i, bit for bit.
        float polygon[3 * 6];
        gaussian_polygon(&c.positions[3 * i], &c.rotations[4 * i], &c.scales[3 * i], {6, p.polygon_radius[f]}, polygon);
        for (int k = 0; k < 18; ++k) EXPECT_EQ(p.vertex_positions[18 * f + k], polygon[k]);
    }
    EXPECT_EQ(p.polygon_radius[0], 3.0f);

    const SplatFaceAttributesView attr = attributes_view(p);
    RecoveryOptions options;
    options.polygon = settings;
    RecoveryStats stats;
    const GaussianCloud r = recover_gaussians_from_polygons(mesh_view(p), attr, options, &stats);
    EXPECT_EQ(stats.unedited, 4u);
    for (std::size_t f = 0; f < 4; ++f) {
        const std::size_t i = visible[f];
        for (int k = 0; k < 3; ++k) EXPECT_EQ(r.positions[3 * f + k], c.positions[3 * i + k]);
        for (int k = 0; k < 3; ++k) EXPECT_EQ(r.scales[3 * f + k], c.scales[3 * i + k]);
        EXPECT_EQ(r.opacities[f], c.opacities[i]);
        for (int k = 0; k < 27; ++k) EXPECT_NEAR(r.sh[27 * f + k], c.sh[27 * i + k], 1e-6);
    }
}

// Faces made before per-face radii (polygons at the object's rho, no rho_i attribute) and faces the user adds
// (rho_i = 0, what Blender gives a new face) are recovered with the object's rho: still unedited, still exact.
TEST(PolygonBridge, FacesWithoutTheirOwnRadiusUseTheObjectsRho) {
    GaussianCloud c = random_cloud(200, 0, 51);
    const PolygonSettings settings{8, 2.5f};
    SplatPolygons p = gaussians_to_polygons(c, settings);
    // The same Gaussians as polygons at rho, as imports before rho_i made them.
    gaussian_polygons(c, 0, c.size(), settings, p.vertex_positions.data(), 3 * 8);
    SplatFaceAttributesView attr;
    attr.thickness = p.thickness.data();
    attr.rest_centers = c.positions.data();
    attr.rest_rotations = c.rotations.data();
    attr.rest_scales = c.scales.data();
    RecoveryOptions options;
    options.polygon = settings;
    const std::vector<float> zero_radii(c.size(), 0.0f);
    for (const float* radii : {static_cast<const float*>(nullptr), zero_radii.data()}) {
        attr.polygon_radius = radii;
        RecoveryStats stats;
        GaussianCloud r = recover_gaussians_from_polygons(mesh_view(p), attr, options, &stats);
        EXPECT_EQ(stats.unedited, 200u);
        EXPECT_EQ(r.scales, c.scales);
        attr.rest_scales = nullptr;  // moments: divides by rho
        r = recover_gaussians_from_polygons(mesh_view(p), attr, options, &stats);
        EXPECT_EQ(stats.recovered, 200u);
        for (std::size_t i = 0; i < c.size(); ++i)
            EXPECT_LT(relative_difference(planar_covariance(&r.rotations[4 * i], &r.scales[3 * i]),
                                          planar_covariance(&c.rotations[4 * i], &c.scales[3 * i])),
                      1e-5);
        attr.rest_scales = c.scales.data();
    }
}

TEST(PolygonBridge, DegenerateFacesDoNotCrashAndAreCounted) {
    // Face 0: collinear; face 1: all vertices coincident; face 2: NaN vertex; face 3: a triangle; face 4:
    // corner index out of range.
    std::vector<float> v = {0, 0, 0, 1, 0, 0, 2, 0, 0, 3, 0, 0,  // collinear
                            5, 5, 5, 5, 5, 5, 5, 5, 5, 5, 5, 5,  // coincident
                            0, 0, 0, 1, 0, 0, NAN, 1, 0, 0, 1, 0,  // NaN
                            0, 0, 0, 1, 0, 0, 0, 1, 0};            // triangle
    std::vector<std::int32_t> corners(v.size() / 3);
    for (std::size_t i = 0; i < corners.size(); ++i) corners[i] = std::int32_t(i);
    corners.push_back(999);
    corners.push_back(0);
    corners.push_back(1);
    std::vector<std::int32_t> start = {0, 4, 8, 12, 15}, count = {4, 4, 4, 3, 3};
    PolygonMeshView mesh{v.data(), v.size() / 3, corners.data(), corners.size(), start.data(), count.data(), 5};
    RecoveryOptions options;
    RecoveryStats stats;
    GaussianCloud r = recover_gaussians_from_polygons(mesh, {}, options, &stats);
    EXPECT_EQ(r.size(), 3u);
    EXPECT_EQ(stats.dropped, 2u);
    EXPECT_EQ(stats.degenerate, 2u);
    EXPECT_EQ(stats.recovered, 3u);
    for (float x : r.scales) EXPECT_TRUE(std::isfinite(x) && x > 0);
    for (float x : r.rotations) EXPECT_TRUE(std::isfinite(x));
    EXPECT_NEAR(r.positions[3 * 1], 5.0f, 1e-6);
    // The triangle: without stored attributes a Gaussian with the default opacity, centred at the centroid.
    EXPECT_FLOAT_EQ(r.opacities[2], kNewFaceOpacity);
    EXPECT_NEAR(r.positions[3 * 2], 1.0 / 3, 1e-6);
}

TEST(PolygonBridge, ViewDependentColourFollowsARotatedPolygon) {
    GaussianCloud c = random_cloud(100, 3, 8);
    PolygonSettings settings{8, 3.0f};
    SplatPolygons p = gaussians_to_polygons(c, settings);
    // Rotate every polygon about its own centre by Q (as Blender's R in individual-origins mode would).
    const Mat3 q = la::quaternion_to_matrix(std::cos(0.6), 0.3 * std::sin(0.6), -0.9 * std::sin(0.6),
                                            std::sqrt(1 - 0.81 - 0.09) * std::sin(0.6));
    for (std::size_t i = 0; i < c.size(); ++i)
        for (int k = 0; k < 8; ++k) {
            float* v = &p.vertex_positions[3 * (8 * i + k)];
            const la::Vec3 centre(c.positions[3 * i], c.positions[3 * i + 1], c.positions[3 * i + 2]);
            const la::Vec3 x = q * (la::Vec3(v[0], v[1], v[2]) - centre) + centre;
            v[0] = float(x.x), v[1] = float(x.y), v[2] = float(x.z);
        }
    SplatFaceAttributesView attr;
    attr.sh_degree = 3;
    attr.sh_local = p.sh_local.data();
    attr.opacity = c.opacities.data();
    RecoveryOptions options;
    options.polygon = settings;
    GaussianCloud r = recover_gaussians_from_polygons(mesh_view(p), attr, options);
    std::mt19937 rng(2);
    std::normal_distribution<double> g;
    for (std::size_t i = 0; i < c.size(); ++i)
        for (int s = 0; s < 5; ++s) {
            la::Vec3 d = la::normalized(la::Vec3(g(rng), g(rng), g(rng)));
            const la::Vec3 back = la::transpose(q) * d;
            const auto seen = evaluate_sh(3, &r.sh[48 * i], d.x, d.y, d.z);
            const auto original = evaluate_sh(3, &c.sh[48 * i], back.x, back.y, back.z);
            for (int ch = 0; ch < 3; ++ch) EXPECT_NEAR(seen[ch], original[ch], 1e-4) << "face " << i;
        }
}

TEST(PolygonBridge, UntouchedSphericalHarmonicsSurviveTheRoundTrip) {
    GaussianCloud c = random_cloud(100, 2, 9);
    PolygonSettings settings{6, 3.0f};
    SplatPolygons p = gaussians_to_polygons(c, settings);
    SplatFaceAttributesView attr;
    attr.sh_degree = 2;
    attr.sh_local = p.sh_local.data();
    RecoveryOptions options;
    options.polygon = settings;
    GaussianCloud r = recover_gaussians_from_polygons(mesh_view(p), attr, options);
    for (std::size_t i = 0; i < c.sh.size(); ++i) EXPECT_NEAR(r.sh[i], c.sh[i], 1e-6 * (1 + std::abs(c.sh[i])));
}

TEST(PolygonBridge, BadSettingsThrow) {
    GaussianCloud c = random_cloud(2, 0, 1);
    EXPECT_THROW(gaussians_to_polygons(c, {2, 3.0f}), InvalidArgument);
    EXPECT_THROW(gaussians_to_polygons(c, {65, 3.0f}), InvalidArgument);
    EXPECT_THROW(gaussians_to_polygons(c, {8, 0.0f}), InvalidArgument);
    EXPECT_THROW(gaussians_to_polygons(c, {8, NAN}), InvalidArgument);
    RecoveryOptions options;
    options.mesh_to_output[5] = NAN;
    EXPECT_THROW(recover_gaussians_from_polygons({}, {}, options), InvalidArgument);
}

}  // namespace
}  // namespace raysplats
