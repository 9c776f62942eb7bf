#include "raysplats/spherical_harmonics.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "raysplats/errors.h"

namespace raysplats {
namespace {

void random_rotation(std::mt19937& rng, double r[9]) {
    std::normal_distribution<double> g;
    double q[4] = {g(rng), g(rng), g(rng), g(rng)};
    const double n = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    for (double& v : q) v /= n;
    const double w = q[0], x = q[1], y = q[2], z = q[3];
    const double m[9] = {1 - 2 * (y * y + z * z), 2 * (x * y - w * z),     2 * (x * z + w * y),
                         2 * (x * y + w * z),     1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
                         2 * (x * z - w * y),     2 * (y * z + w * x),     1 - 2 * (x * x + y * y)};
    for (int i = 0; i < 9; ++i) r[i] = m[i];
}

void random_direction(std::mt19937& rng, double d[3]) {
    std::normal_distribution<double> g;
    d[0] = g(rng), d[1] = g(rng), d[2] = g(rng);
    const double n = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    for (int i = 0; i < 3; ++i) d[i] /= n;
}

// Raw SH sum without the +0.5 offset and clamp, so the comparison sees every coefficient.
double sh_sum(int degree, const float* c, const double d[3], int channel) {
    double basis[16];
    sh_basis(degree, d[0], d[1], d[2], basis);
    double s = 0;
    for (int k = 0; k < (degree + 1) * (degree + 1); ++k) s += basis[k] * c[3 * k + channel];
    return s;
}

TEST(SphericalHarmonics, DegreeZeroIsConstantDcTerm) {
    const float dc[3] = {1.0f, -0.5f, 0.25f};
    const auto rgb = evaluate_sh(0, dc, 0.0, 0.0, 1.0);
    EXPECT_NEAR(rgb[0], 0.5 + kShC0 * 1.0, 1e-6);
    EXPECT_NEAR(rgb[1], 0.5 - kShC0 * 0.5, 1e-6);
    EXPECT_NEAR(rgb[2], 0.5 + kShC0 * 0.25, 1e-6);
}

TEST(SphericalHarmonics, BandOneMatchesReferenceSigns) {
    // Reference 3DGS: result = C0*sh0 - C1*y*sh1 + C1*z*sh2 - C1*x*sh3.
    float c[12] = {0};
    c[3 * 1] = 1.0f;  // sh1, red
    EXPECT_NEAR(evaluate_sh(1, c, 0, 1, 0)[0], std::max(0.0, 0.5 - kShC1), 1e-6);
    c[3 * 1] = 0.0f;
    c[3 * 3] = 0.4f;  // sh3, red
    EXPECT_NEAR(evaluate_sh(1, c, -1, 0, 0)[0], 0.5 + kShC1 * 0.4, 1e-6);
}

TEST(SphericalHarmonics, BasisIsOrthonormalOverTheSphere) {
    // Monte Carlo: (4π/N) Σ Y_a Y_b ≈ δ_ab for the real orthonormal basis.
    std::mt19937 rng(7);
    const int n = 200000;
    double gram[16][16] = {};
    double basis[16], d[3];
    for (int s = 0; s < n; ++s) {
        random_direction(rng, d);
        sh_basis(3, d[0], d[1], d[2], basis);
        for (int a = 0; a < 16; ++a)
            for (int b = 0; b < 16; ++b) gram[a][b] += basis[a] * basis[b];
    }
    for (int a = 0; a < 16; ++a)
        for (int b = 0; b < 16; ++b) EXPECT_NEAR(gram[a][b] * 4 * M_PI / n, a == b ? 1.0 : 0.0, 0.02) << a << "," << b;
}

TEST(SphericalHarmonics, RotatedCoefficientsEqualOriginalInRotatedDirection) {
    std::mt19937 rng(42);
    std::uniform_real_distribution<float> u(-1.0f, 1.0f);
    for (int degree = 1; degree <= 3; ++degree) {
        for (int trial = 0; trial < 50; ++trial) {
            float c[48], rotated[48];
            for (float& v : c) v = u(rng);
            double r[9];
            random_rotation(rng, r);
            rotate_sh(degree, r, c, rotated);
            for (int s = 0; s < 10; ++s) {
                double d[3];
                random_direction(rng, d);
                const double rt_d[3] = {r[0] * d[0] + r[3] * d[1] + r[6] * d[2], r[1] * d[0] + r[4] * d[1] + r[7] * d[2],
                                        r[2] * d[0] + r[5] * d[1] + r[8] * d[2]};
                for (int ch = 0; ch < 3; ++ch)
                    ASSERT_NEAR(sh_sum(degree, rotated, d, ch), sh_sum(degree, c, rt_d, ch), 2e-5)
                        << "degree " << degree << " trial " << trial;
            }
        }
    }
}

TEST(SphericalHarmonics, RotationThenInverseIsIdentity) {
    std::mt19937 rng(3);
    std::uniform_real_distribution<float> u(-1.0f, 1.0f);
    float c[48], there[48], back[48];
    for (float& v : c) v = u(rng);
    double r[9], rt[9];
    random_rotation(rng, r);
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) rt[3 * i + j] = r[3 * j + i];
    rotate_sh(3, r, c, there);
    rotate_sh(3, rt, there, back);
    for (int i = 0; i < 48; ++i) EXPECT_NEAR(back[i], c[i], 1e-5);
}

TEST(SphericalHarmonics, BadDegreeThrows) {
    double basis[16];
    EXPECT_THROW(sh_basis(4, 0, 0, 1, basis), InvalidArgument);
}

}  // namespace
}  // namespace raysplats

namespace raysplats {
namespace {

// reflect_sh must give the function seen through the mirror: f'(d) = f(d with the flipped coordinates negated).
TEST(SphericalHarmonics, ReflectionNegatesTheFlippedCoordinates) {
    std::mt19937 rng(11);
    std::normal_distribution<float> g(0.0f, 0.3f);
    float sh[16 * 3];
    for (float& v : sh) v = g(rng);
    for (int flips = 1; flips < 8; ++flips) {
        const bool fx = flips & 1, fy = flips & 2, fz = flips & 4;
        float reflected[16 * 3];
        std::copy(sh, sh + 48, reflected);
        reflect_sh(3, fx, fy, fz, reflected);
        for (int trial = 0; trial < 10; ++trial) {
            double d[3];
            random_direction(rng, d);
            const auto expected = evaluate_sh(3, sh, fx ? -d[0] : d[0], fy ? -d[1] : d[1], fz ? -d[2] : d[2]);
            const auto actual = evaluate_sh(3, reflected, d[0], d[1], d[2]);
            for (int c = 0; c < 3; ++c) EXPECT_NEAR(actual[c], expected[c], 1e-5) << "flips " << flips;
        }
    }
    EXPECT_THROW(reflect_sh(4, true, false, false, sh), InvalidArgument);
}

}  // namespace
}  // namespace raysplats
