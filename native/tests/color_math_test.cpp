// Colour numerics (src/core/color_math.h): the tabulated sRGB decoding the renderer uses per pixel agrees with the
// exact curve.
#include <gtest/gtest.h>

#include <cmath>

#include "core/color_math.h"

using namespace raysplats;

// Against the IEC 61966-2-1 curve in double precision on a grid 7x finer than the table (so most points fall
// between its entries), across the knee at 0.04045 and beyond 1 (where the exact curve is used): within 2e-7,
// a few float steps near 1.
TEST(ColorMath, TabulatedSrgbDecodingMatchesTheCurve) {
    double worst = 0.0;
    for (int i = -10; i <= 7 * 4096 + 300; ++i) {
        const float c = float(i) / (7.0f * 4096.0f);
        const double x = c;
        const double exact = x <= 0.04045 ? x / 12.92 : std::pow((x + 0.055) / 1.055, 2.4);
        worst = std::max(worst, std::abs(double(srgb_to_linear_tabulated(c)) - exact));
    }
    EXPECT_LT(worst, 2e-7);
    EXPECT_EQ(srgb_to_linear_tabulated(0.0f), 0.0f);
    EXPECT_NEAR(srgb_to_linear_tabulated(1.0f), 1.0f, 1e-7);
    EXPECT_TRUE(std::isnan(srgb_to_linear_tabulated(std::nanf(""))));
}
