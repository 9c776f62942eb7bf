// transform_gaussians: the covariance is mapped exactly (A Σ Aᵀ, computed here independently in double), similarities
// keep each axis' scale, view-dependent colour turns (and mirrors) with the Gaussian, the identity changes nothing.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "raysplats/errors.h"
#include "raysplats/gaussian_transform.h"
#include "raysplats/spherical_harmonics.h"
#include "render_test_util.h"

namespace raysplats {
namespace {

using Matrix3 = std::array<std::array<double, 3>, 3>;

Matrix3 rotation_of(const float* q) {
    const double w = q[0], x = q[1], y = q[2], z = q[3];
    const double n = std::sqrt(w * w + x * x + y * y + z * z);
    const double a = w / n, b = x / n, c = y / n, d = z / n;
    return {{{1 - 2 * (c * c + d * d), 2 * (b * c - a * d), 2 * (b * d + a * c)},
             {2 * (b * c + a * d), 1 - 2 * (b * b + d * d), 2 * (c * d - a * b)},
             {2 * (b * d - a * c), 2 * (c * d + a * b), 1 - 2 * (b * b + c * c)}}};
}

// Σ = R diag(s)² Rᵀ of Gaussian i.
Matrix3 covariance(const GaussianCloud& cloud, std::size_t i) {
    const Matrix3 r = rotation_of(&cloud.rotations[4 * i]);
    Matrix3 sigma{};
    for (int a = 0; a < 3; ++a)
        for (int b = 0; b < 3; ++b)
            for (int k = 0; k < 3; ++k) {
                const double s = cloud.scales[3 * i + k];
                sigma[a][b] += r[a][k] * s * s * r[b][k];
            }
    return sigma;
}

Matrix3 linear_part(const double m[16]) {
    return {{{m[0], m[1], m[2]}, {m[4], m[5], m[6]}, {m[8], m[9], m[10]}}};
}

Matrix3 mapped_covariance(const Matrix3& a, const Matrix3& sigma) {
    Matrix3 out{};
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
            for (int k = 0; k < 3; ++k)
                for (int l = 0; l < 3; ++l) out[i][j] += a[i][k] * sigma[k][l] * a[j][l];
    return out;
}

void expect_covariances_mapped(const GaussianCloud& in, const GaussianCloud& out, const double m[16]) {
    const Matrix3 a = linear_part(m);
    for (std::size_t i = 0; i < in.size(); ++i) {
        const Matrix3 expected = mapped_covariance(a, covariance(in, i));
        const Matrix3 actual = covariance(out, i);
        double scale = 0.0;
        for (int r = 0; r < 3; ++r) scale = std::max(scale, std::abs(expected[r][r]));
        for (int r = 0; r < 3; ++r)
            for (int c = 0; c < 3; ++c)
                ASSERT_NEAR(actual[r][c], expected[r][c], 2e-6 * scale) << "Gaussian " << i << " entry " << r << c;
        for (int r = 0; r < 3; ++r) {
            double p = m[r * 4 + 3];
            for (int c = 0; c < 3; ++c) p += m[r * 4 + c] * in.positions[3 * i + c];
            ASSERT_NEAR(out.positions[3 * i + r], p, 1e-5 * (1.0 + std::abs(p)));
        }
        ASSERT_EQ(out.opacities[i], in.opacities[i]);
    }
}

GaussianCloud cloud_with_sh(std::uint32_t seed, int n) {
    GaussianCloud cloud = testing::random_cloud(seed, n, 2.0f);
    GaussianCloud out;
    out.resize(cloud.size(), 3);
    out.positions = cloud.positions, out.rotations = cloud.rotations, out.scales = cloud.scales;
    out.opacities = cloud.opacities;
    std::mt19937 rng(seed);
    std::normal_distribution<float> normal(0.0f, 0.3f);
    for (float& v : out.sh) v = normal(rng);
    return out;
}

TEST(GaussianTransform, IdentityChangesNothing) {
    const GaussianCloud cloud = cloud_with_sh(1, 50);
    const double identity[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
    const GaussianCloud out = transform_gaussians(cloud, identity);
    EXPECT_EQ(out.positions, cloud.positions);
    EXPECT_EQ(out.rotations, cloud.rotations);
    EXPECT_EQ(out.scales, cloud.scales);
    EXPECT_EQ(out.sh, cloud.sh);
}

TEST(GaussianTransform, GeneralAffineMapsTheCovarianceExactly) {
    const GaussianCloud cloud = cloud_with_sh(2, 200);
    // Non-uniform scale, shear and a rotation, with a translation.
    const double m[16] = {1.3, 0.4, -0.2, 5.0, -0.1, 0.7, 0.3, -2.0, 0.25, -0.35, 2.1, 0.5, 0, 0, 0, 1};
    expect_covariances_mapped(cloud, transform_gaussians(cloud, m), m);
}

TEST(GaussianTransform, SimilarityKeepsEachAxisScale) {
    const GaussianCloud cloud = cloud_with_sh(3, 100);
    // 2.5 × a rotation of 40° about (1, 2, 2)/3, as Blender's float matrices give it.
    const double angle = 40.0 * M_PI / 180.0, c = std::cos(angle), s = std::sin(angle);
    const double x = 1.0 / 3, y = 2.0 / 3, z = 2.0 / 3;
    const double r[9] = {c + x * x * (1 - c),     x * y * (1 - c) - z * s, x * z * (1 - c) + y * s,
                         y * x * (1 - c) + z * s, c + y * y * (1 - c),     y * z * (1 - c) - x * s,
                         z * x * (1 - c) - y * s, z * y * (1 - c) + x * s, c + z * z * (1 - c)};
    double m[16] = {0, 0, 0, 1, 0, 0, 0, -3, 0, 0, 0, 0.5, 0, 0, 0, 1};
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) m[i * 4 + j] = double(float(2.5 * r[i * 3 + j]));
    const GaussianCloud out = transform_gaussians(cloud, m);
    expect_covariances_mapped(cloud, out, m);
    for (std::size_t i = 0; i < 3 * cloud.size(); ++i) ASSERT_NEAR(out.scales[i], 2.5f * cloud.scales[i], 2e-6f);
}

// Colour seen along direction d before equals colour seen along Q d after (Q: the map's rotation or reflection).
void expect_colour_follows(const GaussianCloud& in, const GaussianCloud& out, const double q[9]) {
    std::mt19937 rng(7);
    std::normal_distribution<double> normal;
    for (std::size_t i = 0; i < in.size(); ++i)
        for (int trial = 0; trial < 4; ++trial) {
            double d[3] = {normal(rng), normal(rng), normal(rng)};
            const double n = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
            for (double& v : d) v /= n;
            const double e[3] = {q[0] * d[0] + q[1] * d[1] + q[2] * d[2], q[3] * d[0] + q[4] * d[1] + q[5] * d[2],
                                 q[6] * d[0] + q[7] * d[1] + q[8] * d[2]};
            const auto before = evaluate_sh(3, &in.sh[i * 16 * 3], d[0], d[1], d[2]);
            const auto after = evaluate_sh(3, &out.sh[i * 16 * 3], e[0], e[1], e[2]);
            for (int c = 0; c < 3; ++c) ASSERT_NEAR(after[c], before[c], 1e-4) << "Gaussian " << i;
        }
}

TEST(GaussianTransform, ViewDependentColourTurnsWithTheGaussian) {
    const GaussianCloud cloud = cloud_with_sh(4, 40);
    // A rotation of 90° about z, scaled by 3.
    const double m[16] = {0, -3, 0, 1, 3, 0, 0, 2, 0, 0, 3, 3, 0, 0, 0, 1};
    const double q[9] = {0, -1, 0, 1, 0, 0, 0, 0, 1};
    expect_colour_follows(cloud, transform_gaussians(cloud, m), q);
}

TEST(GaussianTransform, AMirrorMirrorsTheColourAndKeepsRotationsProper) {
    const GaussianCloud cloud = cloud_with_sh(5, 40);
    const double m[16] = {1, 0, 0, 0, 0, -1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};  // y -> -y
    const double q[9] = {1, 0, 0, 0, -1, 0, 0, 0, 1};
    const GaussianCloud out = transform_gaussians(cloud, m);
    expect_colour_follows(cloud, out, q);
    expect_covariances_mapped(cloud, out, m);
    for (std::size_t i = 0; i < out.size(); ++i) {
        const float* r = &out.rotations[4 * i];
        EXPECT_NEAR(r[0] * r[0] + r[1] * r[1] + r[2] * r[2] + r[3] * r[3], 1.0f, 1e-5f);
    }
}

TEST(GaussianTransform, SingularOrNonFiniteMatricesAreRefused) {
    const GaussianCloud cloud = cloud_with_sh(6, 3);
    const double flat[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1};
    EXPECT_THROW(transform_gaussians(cloud, flat), InvalidArgument);
    double nan[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
    nan[3] = std::nan("");
    EXPECT_THROW(transform_gaussians(cloud, nan), InvalidArgument);
}

}  // namespace
}  // namespace raysplats
