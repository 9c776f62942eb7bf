#include "raysplats/color_adjustment.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "raysplats/errors.h"
#include "raysplats/spherical_harmonics.h"

namespace raysplats {
namespace {

// Unclamped display colour of degree-3 SH along d.
std::array<double, 3> display(const float* sh, const double d[3]) {
    double basis[16];
    sh_basis(3, d[0], d[1], d[2], basis);
    std::array<double, 3> c = {0.5, 0.5, 0.5};
    for (int k = 0; k < 16; ++k)
        for (int ch = 0; ch < 3; ++ch) c[ch] += basis[k] * sh[3 * k + ch];
    return c;
}

TEST(ColorAdjustment, SHAdjustmentEqualsTheAffineMapOfEveryViewDependentColour) {
    std::mt19937 rng(3);
    std::normal_distribution<float> g(0.0f, 0.4f);
    std::vector<float> sh(16 * 3);
    for (float& v : sh) v = g(rng);
    const ColorAdjustment adjustment{0.7, -0.1, 0.6, 0.15, 0.5};
    const AffineColorMap map = color_adjustment_map(adjustment);
    std::vector<float> adjusted = sh;
    apply_color_adjustment(adjustment, 3, adjusted.data(), 1);
    for (int trial = 0; trial < 20; ++trial) {
        double d[3] = {g(rng), g(rng), g(rng)};
        const double n = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
        for (double& v : d) v /= n;
        const auto before = display(sh.data(), d), after = display(adjusted.data(), d);
        for (int r = 0; r < 3; ++r) {
            const double expected = map.matrix[3 * r] * before[0] + map.matrix[3 * r + 1] * before[1] +
                                    map.matrix[3 * r + 2] * before[2] + map.offset[r];
            EXPECT_NEAR(after[r], expected, 1e-5);
        }
    }
}

TEST(ColorAdjustment, EachAdjustmentDoesWhatItsNameSays) {
    auto apply = [](const ColorAdjustment& a, std::array<double, 3> c) {
        const AffineColorMap m = color_adjustment_map(a);
        std::array<double, 3> out{};
        for (int r = 0; r < 3; ++r)
            out[r] = m.matrix[3 * r] * c[0] + m.matrix[3 * r + 1] * c[1] + m.matrix[3 * r + 2] * c[2] + m.offset[r];
        return out;
    };
    const std::array<double, 3> c = {0.2, 0.4, 0.6};
    EXPECT_NEAR(apply({1.0, 0, 1, 0, 0}, c)[1], 0.8, 1e-12);         // +1 stop doubles
    EXPECT_NEAR(apply({0, 0.1, 1, 0, 0}, c)[2], 0.7, 1e-12);         // brightness adds
    const auto grey = apply({0, 0, 0.0, 0, 0}, c);                    // saturation 0: luma everywhere
    EXPECT_NEAR(grey[0], 0.2126 * 0.2 + 0.7152 * 0.4 + 0.0722 * 0.6, 1e-12);
    EXPECT_NEAR(grey[0], grey[2], 1e-12);
    const auto third = apply({0, 0, 1, 1.0 / 3.0, 0}, c);             // hue 1/3 turn cycles R -> G -> B
    EXPECT_NEAR(third[1], c[0], 1e-12);
    EXPECT_NEAR(third[2], c[1], 1e-12);
    EXPECT_NEAR(third[0], c[2], 1e-12);
    const auto warm = apply({0, 0, 1, 0, 1.0}, c);
    EXPECT_NEAR(warm[0], 0.24, 1e-12);
    EXPECT_NEAR(warm[2], 0.48, 1e-12);
    EXPECT_THROW(color_adjustment_map({NAN, 0, 1, 0, 0}), InvalidArgument);
}

TEST(ColorAdjustment, CornerColoursOfTheIdentityAreTheImportsAndFillEveryCorner) {
    const float dc[6] = {0.0f, 10.0f, -10.0f, 1.0f, 1.0f, 1.0f};
    const float opacity[2] = {0.25f, 0.75f};
    const std::int32_t starts[2] = {0, 3}, counts[2] = {3, 2};
    std::vector<std::uint8_t> rgba(4 * 5, 7);
    splat_corner_colors({}, dc, opacity, 2, starts, counts, 5, rgba.data());
    EXPECT_EQ(rgba[0], 128);    // display 0.5 as an sRGB byte (Blender shows it linear)
    EXPECT_EQ(rgba[1], 255);    // clamped white
    EXPECT_EQ(rgba[2], 0);      // clamped black
    EXPECT_EQ(rgba[3], 64);     // opacity 0.25 x 255, rounded
    EXPECT_EQ(rgba[4 * 2 + 3], 64);
    EXPECT_EQ(rgba[4 * 4 + 3], 191);
    std::vector<float> linear(4 * 5);
    byte_colors_to_linear(rgba.data(), 5, linear.data());
    EXPECT_NEAR(linear[0], std::pow((128 / 255.0 + 0.055) / 1.055, 2.4), 1e-6);
    EXPECT_EQ(linear[1], 1.0f);
    EXPECT_NEAR(linear[3], 64 / 255.0, 1e-7);
    std::vector<std::uint8_t> darker(4 * 5);
    splat_corner_colors({-1.0, 0, 1, 0, 0}, dc, opacity, 2, starts, counts, 5, darker.data());
    EXPECT_LT(darker[4 * 3], rgba[4 * 3]);
    const std::int32_t bad_starts[2] = {0, 4};
    EXPECT_THROW(splat_corner_colors({}, dc, opacity, 2, bad_starts, counts, 5, darker.data()), InvalidArgument);
}

}  // namespace
}  // namespace raysplats
