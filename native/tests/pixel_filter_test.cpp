// The pixel filter's sample distributions (src/render/pixel_filter.h) and its effect on an image.
#include <gtest/gtest.h>

#include <cmath>

#include "raysplats/render/renderer.h"
#include "render/pixel_filter.h"
#include "render/render_math.h"
#include "render_test_util.h"

using namespace raysplats;
using namespace raysplats::testing;

namespace {

// Mean and variance (in pixels^2) of the sample positions over a fine uniform grid of u.
void moments(const PixelFilterSampler& f, double& mean, double& variance, double& lo, double& hi) {
    const int n = 1 << 16;
    double s = 0.0, s2 = 0.0;
    lo = 1e9, hi = -1e9;
    for (int i = 0; i < n; ++i) {
        const double x = f.position((i + 0.5f) / n) - 0.5;
        s += x, s2 += x * x;
        lo = std::min(lo, x), hi = std::max(hi, x);
    }
    mean = s / n;
    variance = s2 / n - mean * mean;
}

}  // namespace

// A box of width 1 is the plain jitter of earlier versions, bit for bit, for every value the sampler draws
// (multiples of 2^-24): the golden films rely on it.
TEST(PixelFilter, UnitBoxIsThePlainJitter) {
    const PixelFilterSampler box(PixelFilter::Box, 1.0f);
    for (std::uint32_t k = 0; k < (1u << 24); k += 997) {
        const float u = u32_to_unit_float(k << 8);
        ASSERT_EQ(box.position(u), u) << k;
    }
    EXPECT_EQ(box.position(u32_to_unit_float(0xffffffffu)), u32_to_unit_float(0xffffffffu));
}

// Variances against closed forms: box w^2 / 12; Gaussian (w / 4)^2 (truncated at 6 sigma: no visible loss);
// Blackman-Harris on [-w, w]: the window's second moment, integrated here with Simpson's rule.
TEST(PixelFilter, DistributionsHaveTheFiltersMoments) {
    double mean, variance, lo, hi;
    moments(PixelFilterSampler(PixelFilter::Box, 2.0f), mean, variance, lo, hi);
    EXPECT_NEAR(mean, 0.0, 1e-6);
    EXPECT_NEAR(variance, 4.0 / 12.0, 1e-4);
    EXPECT_GE(lo, -1.0);
    EXPECT_LE(hi, 1.0);

    moments(PixelFilterSampler(PixelFilter::Gaussian, 1.5f), mean, variance, lo, hi);
    EXPECT_NEAR(mean, 0.0, 1e-4);
    EXPECT_NEAR(variance, (1.5 / 4) * (1.5 / 4), 2e-4);
    EXPECT_GE(lo, -2.25);
    EXPECT_LE(hi, 2.25);

    const double w = 1.5, pi = 3.14159265358979323846;
    auto bh = [&](double x) {
        const double v = 2.0 * pi * (x / (2.0 * w) + 0.5);
        return 0.35875 - 0.48829 * std::cos(v) + 0.14128 * std::cos(2.0 * v) - 0.01168 * std::cos(3.0 * v);
    };
    double m0 = 0.0, m2 = 0.0;
    const int n = 20000;
    for (int i = 0; i <= n; ++i) {
        const double x = -w + 2.0 * w * i / n, k = (i == 0 || i == n) ? 1.0 : (i % 2 ? 4.0 : 2.0);
        m0 += k * bh(x), m2 += k * bh(x) * x * x;
    }
    moments(PixelFilterSampler(PixelFilter::BlackmanHarris, float(w)), mean, variance, lo, hi);
    EXPECT_NEAR(mean, 0.0, 1e-4);
    EXPECT_NEAR(variance, m2 / m0, 2e-4);
    EXPECT_GE(lo, -w);
    EXPECT_LE(hi, w);
}

// A sharp edge (an emissive half plane) seen through a wide filter spreads over more pixels than through the unit
// box: with the box, only the one column the edge crosses is grey.
TEST(PixelFilter, AWideFilterBlursAnEdge) {
    Scene scene;
    scene.add_material(emissive(1.0f, 1.0f, 1.0f));
    const TestMesh half = make_quad_z(-10.0f, 0.0f, -10.0f, 10.0f, 0.0f, 0);
    scene.add_mesh(half.desc());
    scene.set_world(black_world());
    Camera cam;
    cam.type = CameraType::Orthographic;
    cam.ortho_scale = 2.0f;  // 32 pixels over 2 units: the edge x = 0 lies between columns 15 and 16
    cam.camera_to_world = Matrix4::translation(0, 0, 3);
    RenderSettings s;
    s.width = s.height = 32;
    s.samples = 64;
    s.max_bounces = 0;
    auto grey_columns = [&](PixelFilter filter, float width) {
        s.pixel_filter = filter;
        s.filter_width = width;
        const Film film = render(scene, cam, s);
        int grey = 0;
        for (int x = 0; x < 32; ++x) {
            const float v = film.rgba()[4 * (16 * 32 + x)];
            grey += v > 0.02f && v < 0.98f;
        }
        return grey;
    };
    EXPECT_EQ(grey_columns(PixelFilter::Box, 1.0f), 0);  // the edge lies on a pixel boundary
    EXPECT_GE(grey_columns(PixelFilter::BlackmanHarris, 1.5f), 2);
    // sigma = 1.5 px: the columns 0.5, 1.5 and 2.5 px from the edge see 63 %, 84 % and 95 % of one side.
    EXPECT_GE(grey_columns(PixelFilter::Gaussian, 6.0f), 4);
}
