// Relightable splats (gaussian_shading LIT / BAKED_SHADOWED) against closed forms: Lambert's cosine law on a lit
// splat patch, the analytic shadow of a mesh edge (hard and with the penumbra of a sun of finite angle), Gaussians
// shadowing Gaussians, the per-object override, and a furnace test (energy never grows with bounces).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "raysplats/errors.h"
#include "raysplats/render/renderer.h"
#include "render_test_util.h"

using namespace raysplats;
using namespace raysplats::testing;

namespace {

constexpr double kPi = 3.14159265358979323846;

// A square patch of flat Gaussians in the plane z = z0 (normal +Z), overlapping so densely that the composited
// opacity reaches 1 - 1e-3 (the transmittance threshold) everywhere inside it, away from its rim.
GaussianCloud splat_floor(float half, float z0, float display_grey, float spacing = 0.1f) {
    GaussianCloud cloud;
    cloud.sh_degree = 0;
    const float q[4] = {1, 0, 0, 0}, s[3] = {0.15f, 0.15f, 0.001f};
    const float rgb[3] = {display_grey, display_grey, display_grey};
    const int n = int(std::lround(2 * half / spacing));
    for (int a = 0; a <= n; ++a)
        for (int b = 0; b <= n; ++b) {
            const float p[3] = {-half + a * spacing, -half + b * spacing, z0};
            add_gaussian(cloud, p, q, s, 1.0f, rgb);
        }
    return cloud;
}

// The same patch stood up in the plane x = x0 (normal +X): rotated 90 degrees about Y.
GaussianCloud splat_wall(float half, float x0, float display_grey) {
    GaussianCloud cloud = splat_floor(half, 0.0f, display_grey);
    const float h = float(std::sqrt(0.5));
    for (std::size_t i = 0; i < cloud.size(); ++i) {
        float* p = &cloud.positions[3 * i];
        const float x = p[0], z = p[2];
        p[0] = x0 + z;
        p[2] = half + x;  // the wall stands on z = 0 and rises to 2 half
        float* q = &cloud.rotations[4 * i];
        q[0] = h, q[1] = 0.0f, q[2] = h, q[3] = 0.0f;  // 90 degrees about Y: the smallest axis (z) becomes x
    }
    return cloud;
}

Camera ortho(float x, float y, float z, float scale, bool looking_up = false) {
    Camera c;
    c.type = CameraType::Orthographic;
    c.ortho_scale = scale;
    c.camera_to_world = Matrix4::translation(x, y, z);
    if (looking_up) c.camera_to_world = c.camera_to_world * Matrix4::rotation(float(kPi), 1, 0, 0);
    c.clip_start = 0.01f;
    return c;
}

RenderSettings settings(int w, int h, int spp, GaussianShading shading) {
    RenderSettings s;
    s.width = w;
    s.height = h;
    s.samples = spp;
    s.jitter = false;
    s.max_bounces = 0;
    s.gaussian_shading = shading;
    // Lit and shadowed splats are shaded in linear light; the baked references here composite linearly too (the
    // display blend of baked splats is render_gaussian_test's).
    s.blend_space = BlendSpace::Linear;
    return s;
}

Light sun(float strength, const Matrix4& to_world, float angle = 0.0f) {
    Light l;
    l.type = LightType::Sun;
    l.power = strength;
    l.light_to_world = to_world;
    l.sun_angle = angle;
    return l;
}

double red(const Film& film, int i, int j) { return film.rgba()[4 * (std::size_t(j) * film.width + i)]; }

// Grey-world delighting of a uniformly grey object: albedo = kGreyWorldAlbedo (0.5) whatever its grey.
constexpr double kUniformAlbedo = 0.5;

}  // namespace

// L = rho / pi * S * cos(theta) (Lambert) for a sun at theta = 0, 30, 60 and 80 degrees from the patch's normal, on
// both sides of the patch (two-sided), and 0 when the sun is on the side the camera does not see. The composited
// albedo is (1 - T) rho with T <= 1e-3; tolerance 2 % relative (what a lit splat surface was required to meet), and the
// law itself to 0.5 %.
TEST(RenderGaussianShading, LitPatchFollowsLambertsCosineLaw) {
    const GaussianCloud floor = splat_floor(3.0f, 0.0f, 0.35f);
    Scene scene;
    scene.set_world(black_world());
    scene.add_gaussians(floor);
    scene.add_light(sun(3.0f, Matrix4{}));
    const double degrees[] = {0.0, 30.0, 60.0, 80.0};
    for (bool from_below : {false, true}) {
        for (double deg : degrees) {
            const double theta = deg * kPi / 180.0;
            Scene s2;
            s2.set_world(black_world());
            s2.add_gaussians(floor);
            // Rotating about X tilts the direction towards the sun (+Z) by theta; from below, flip it through the plane.
            const float angle = float(from_below ? kPi - theta : theta);
            s2.add_light(sun(3.0f, Matrix4::rotation(angle, 1, 0, 0)));
            const Film film = render(s2, ortho(0, 0, from_below ? -2.0f : 2.0f, 2.0f, from_below),
                                     settings(8, 8, 1, GaussianShading::Lit));
            const double expected = kUniformAlbedo / kPi * 3.0 * std::cos(theta);
            for (int j = 0; j < 8; ++j)
                for (int i = 0; i < 8; ++i) {
                    ASSERT_NEAR(red(film, i, j), expected, 0.02 * expected) << deg << " degrees, below " << from_below;
                    ASSERT_NEAR(red(film, i, j) / (kUniformAlbedo / kPi * 3.0), std::cos(theta),
                                0.005 * std::cos(theta) + 2e-3);
                }
            // The camera on the other side sees the unlit face.
            const Film back = render(s2, ortho(0, 0, from_below ? 2.0f : -2.0f, 2.0f, !from_below),
                                     settings(4, 4, 1, GaussianShading::Lit));
            for (int p = 0; p < 16; ++p) ASSERT_EQ(back.rgba()[4 * p], 0.0f) << deg;
        }
    }
    // BAKED (the default) keeps the captured colour whatever the light: srgb_to_linear(0.35).
    const Film baked = render(scene, ortho(0, 0, 2.0f, 2.0f), settings(4, 4, 1, GaussianShading::Baked));
    EXPECT_NEAR(baked.rgba()[0], srgb_to_linear_ref(0.35), 1e-3);
}

// Grey-world delighting: the albedo is the colour over twice the object's opacity-weighted mean luminance, so a
// patch whose left half is twice as bright (linear) as its right half gets albedos 2/3 and 1/3.
TEST(RenderGaussianShading, AlbedoDividesOutTheObjectsMeanLuminance) {
    GaussianCloud cloud = splat_floor(3.0f, 0.0f, 0.5f);
    const double bright = srgb_to_linear_ref(0.6), dark = bright / 2;
    // Display grey whose linear value is `dark`.
    const double dark_display = 1.055 * std::pow(dark, 1 / 2.4) - 0.055;
    for (std::size_t i = 0; i < cloud.size(); ++i) {
        const double g = cloud.positions[3 * i] < 0.0f ? 0.6 : dark_display;
        for (int c = 0; c < 3; ++c) cloud.sh[3 * i + c] = dc_for(float(g));
    }
    std::size_t left = 0;
    for (std::size_t i = 0; i < cloud.size(); ++i) left += cloud.positions[3 * i] < 0.0f;
    const double mean = (left * bright + (cloud.size() - left) * dark) / double(cloud.size());
    Scene scene;
    scene.set_world(black_world());
    scene.add_gaussians(cloud);
    scene.add_light(sun(kPi, Matrix4{}));  // L = rho
    const Film film = render(scene, ortho(0, 0, 2.0f, 4.0f), settings(8, 2, 1, GaussianShading::Lit));
    EXPECT_NEAR(red(film, 1, 0), 0.5 * bright / mean, 0.01);  // x = -1.25
    EXPECT_NEAR(red(film, 6, 0), 0.5 * dark / mean, 0.01);    // x = +1.25
}

// A mesh half-plane (x < 0) at height h between a sun tilted 30 degrees towards +x and a lit splat floor: the shadow
// ends at x = -h tan 30 (hard sun: a step within one pixel); with a sun of angular diameter 10 degrees each point
// sees the part of the sun's disk beyond the edge, the circular-segment fraction (acos d - d sqrt(1 - d^2)) / pi,
// d = (atan(-x / h) - 30 deg) / 5 deg. The camera sits between the half-plane and the floor.
TEST(RenderGaussianShading, MeshCastsAnalyticShadowAndPenumbraOnLitSplats) {
    const double h = 2.0, theta = kPi / 6;
    const double edge = -h * std::tan(theta);
    const GaussianCloud floor = splat_floor(4.0f, 0.0f, 0.5f);
    const TestMesh blocker = make_quad_z(-20.0f, 0.0f, -20.0f, 20.0f, float(h), 0);
    const double lit = kUniformAlbedo / kPi * 2.0 * std::cos(theta);
    const int n = 128;
    const float scale = 1.5f;
    auto pixel_x = [&](int i) { return edge + ((i + 0.5) / n - 0.5) * scale; };
    for (float sun_angle : {0.0f, float(10.0 * kPi / 180.0)}) {
        Scene scene;
        scene.set_world(black_world());
        Material m;
        m.base_color = {0.5f, 0.5f, 0.5f};
        scene.add_material(m);
        scene.add_mesh(blocker.desc());
        scene.add_gaussians(floor);
        scene.add_light(sun(2.0f, Matrix4::rotation(float(theta), 0, 1, 0), sun_angle));
        const int rows = sun_angle > 0 ? 8 : 1, spp = sun_angle > 0 ? 256 : 1;
        const Film film = render(scene, ortho(float(edge), 0, 1.0f, scale), settings(n, rows, spp, GaussianShading::Lit));
        std::vector<double> fraction(n, 0.0);
        for (int i = 0; i < n; ++i) {
            for (int j = 0; j < rows; ++j) fraction[i] += red(film, i, j) / lit / rows;
        }
        if (sun_angle == 0.0f) {
            const double pixel = scale / n;
            for (int i = 0; i < n; ++i) {
                const double x = pixel_x(i);
                if (std::abs(x - edge) < pixel) continue;
                ASSERT_NEAR(fraction[i], x < edge ? 0.0 : 1.0, 0.02) << "x = " << x;
            }
        } else {
            const double r = 0.5 * sun_angle;
            double worst = 0.0;
            for (int i = 0; i < n; ++i) {
                const double x = pixel_x(i);
                const double d = std::clamp((std::atan(-x / h) - theta) / r, -1.0, 1.0);
                const double expected = (std::acos(d) - d * std::sqrt(1 - d * d)) / kPi;
                worst = std::max(worst, std::abs(fraction[i] - expected));
                ASSERT_NEAR(fraction[i], expected, 0.06) << "x = " << x;
            }
            // The penumbra is as wide as geometry says: the fraction crosses 0.1 and 0.9 where the formula does.
            auto crossing = [&](double level) {
                for (int i = 1; i < n; ++i)
                    if (fraction[i - 1] < level && fraction[i] >= level) return pixel_x(i);
                return 1e9;
            };
            auto predicted = [&](double level) {  // solve (acos d - d sqrt(1 - d^2)) / pi = level by bisection
                double lo = -1, hi = 1;
                for (int k = 0; k < 60; ++k) {
                    const double d = 0.5 * (lo + hi);
                    ((std::acos(d) - d * std::sqrt(1 - d * d)) / kPi > level ? lo : hi) = d;
                }
                return -h * std::tan(theta + 0.5 * (lo + hi) * r);
            };
            EXPECT_NEAR(crossing(0.1), predicted(0.1), 3 * scale / n);
            EXPECT_NEAR(crossing(0.9), predicted(0.9), 3 * scale / n);
            std::printf("penumbra: worst |fraction - analytic| = %.4f\n", worst);
        }
    }
}

// Gaussians shadow Gaussians (semi-transparently), and the per-object override: a BAKED sheet of opacity 0.6 (scale
// 20: alpha ~ 0.6 near its centre) above a floor that is BAKED_SHADOWED (the scene setting) passes (1 - 0.6 G) of a
// vertical sun; with the floor overridden to BAKED it keeps its colour, overridden to LIT it is rho / pi S (1 - 0.6 G).
TEST(RenderGaussianShading, GaussiansShadowGaussiansAndObjectsOverrideTheSceneShading) {
    const GaussianCloud floor = splat_floor(2.0f, 0.0f, 0.6f);
    GaussianCloud sheet;
    const float q[4] = {1, 0, 0, 0}, s[3] = {20.0f, 20.0f, 0.001f}, rgb[3] = {1, 0, 0}, p[3] = {0, 0, 1.0f};
    add_gaussian(sheet, p, q, s, 0.6f, rgb);
    Scene scene;
    scene.set_world(black_world());
    const std::uint32_t floor_index = scene.add_gaussians(floor);
    const std::uint32_t sheet_index = scene.add_gaussians(sheet);
    scene.set_gaussian_shading(sheet_index, GaussianShading::Baked);
    scene.add_light(sun(2.0f, Matrix4{}));
    RenderSettings st = settings(8, 8, 1, GaussianShading::BakedShadowed);
    const Camera camera = ortho(0, 0, 0.5f, 2.0f);  // between the sheet and the floor
    auto transmitted = [&](int i, int j) {
        const double x = ((i + 0.5) / 8 - 0.5) * 2.0, y = (0.5 - (j + 0.5) / 8) * 2.0;
        return 1.0 - 0.6 * std::exp(-(x * x + y * y) / (2 * 20.0 * 20.0));
    };
    const double baked = srgb_to_linear_ref(0.6);
    const Film shadowed = render(scene, camera, st);
    scene.set_gaussian_shading(floor_index, GaussianShading::Baked);
    const Film kept = render(scene, camera, st);
    scene.set_gaussian_shading(floor_index, GaussianShading::Lit);
    const Film lit = render(scene, camera, st);
    for (int j = 0; j < 8; ++j)
        for (int i = 0; i < 8; ++i) {
            ASSERT_NEAR(red(shadowed, i, j), baked * transmitted(i, j), 0.01 * baked);
            ASSERT_NEAR(red(kept, i, j), baked, 1e-3 * baked);
            ASSERT_NEAR(red(lit, i, j), kUniformAlbedo / kPi * 2.0 * transmitted(i, j), 0.01);
        }
    EXPECT_THROW(scene.set_gaussian_shading(7, GaussianShading::Lit), InvalidArgument);
}

// Furnace: a lit splat corner (floor and wall, albedo 0.5 each) in a uniform white world of radiance 1. A lit point
// reflects at most rho times what reaches it, and what reaches it is at most 1 (the world, or another such point),
// so no pixel can exceed rho = 0.5 however many bounces are followed; each added bounce adds light, never removes
// it, and the bounces beyond the first add less than rho^2 of the world (the corner sees itself at most half).
TEST(RenderGaussianShading, FurnaceEnergyNeverGrowsPastTheBoundWithBounces) {
    const GaussianCloud floor = splat_floor(3.0f, 0.0f, 0.5f);
    const GaussianCloud wall = splat_wall(3.0f, 0.0f, 0.5f);
    Scene scene;
    World white;
    white.color = {1.0f, 1.0f, 1.0f};
    scene.set_world(white);
    scene.add_gaussians(floor);
    scene.add_gaussians(wall);
    Camera camera;
    camera.type = CameraType::Perspective;
    // Looking at the corner from (-3, 0, 2) towards (0, 0, 0.5): x forward, down a little.
    const double pitch = std::atan2(1.5, 3.0);
    camera.camera_to_world = Matrix4::translation(-3.0f, 0.0f, 2.0f) * Matrix4::rotation(float(-kPi / 2), 0, 0, 1) *
                             Matrix4::rotation(float(kPi / 2 - pitch), 1, 0, 0);
    const int n = 16;
    std::vector<double> means;
    for (int bounces : {0, 1, 2, 4, 8}) {
        RenderSettings st = settings(n, n, 256, GaussianShading::Lit);
        st.max_bounces = bounces;
        const Film film = render(scene, camera, st);
        double mean = 0.0;
        for (std::size_t p = 0; p < film.pixel_count(); ++p) {
            ASSERT_EQ(film.alpha()[p], 1.0f) << "the corner fills the view";
            ASSERT_LE(film.rgba()[4 * p], kUniformAlbedo + 0.05) << bounces << " bounces, pixel " << p;
            mean += film.rgba()[4 * p] / double(film.pixel_count());
        }
        std::printf("furnace: %d bounces, mean radiance %.4f (bound %.2f)\n", bounces, mean, kUniformAlbedo);
        ASSERT_LE(mean, kUniformAlbedo);
        if (!means.empty()) {
            EXPECT_GE(mean, means.back() - 0.005) << bounces << " bounces";
        }
        means.push_back(mean);
    }
    EXPECT_GT(means[1], means[0] + 0.01) << "the first bounce off the other plane adds light";
    EXPECT_LT(means.back() - means[1], 0.25 * 0.5 * 1.1);
}

// Lit splats are seen in mirrors as directly: a camera looking along -x at a perfect mirror tilted 45 degrees sees
// the lit splat floor below it (out of the mirror's shadow) with the radiance rho / pi * S * cos 30 it has when seen
// directly (metallic mirror of base colour 1: reflectance 1). Tolerance 2 %.
TEST(RenderGaussianShading, LitSplatsAreSeenInMirrors) {
    const GaussianCloud floor = splat_floor(3.0f, 0.0f, 0.5f);
    Material mirror;
    mirror.metallic = 1.0f;
    mirror.roughness = 0.0f;
    mirror.base_color = {1, 1, 1};
    TestMesh glass = make_quad_z(-0.5f, 0.5f, -0.5f, 0.5f, 0.0f, 0);
    // Normal (sin 135, 0, cos 135): facing the camera (+x) and the floor (-z).
    glass.object_to_world = Matrix4::translation(0, 0, 2) * Matrix4::rotation(float(0.75 * kPi), 0, 1, 0);
    Scene scene;
    scene.set_world(black_world());
    scene.add_material(mirror);
    scene.add_mesh(glass.desc());
    scene.add_gaussians(floor);
    scene.add_light(sun(2.0f, Matrix4::rotation(float(kPi / 6), 0, 1, 0)));
    Camera camera = ortho(5.0f, 0.0f, 2.0f, 0.4f);
    camera.camera_to_world = Matrix4::translation(5.0f, 0.0f, 2.0f) * Matrix4::rotation(float(kPi / 2), 0, 1, 0);
    RenderSettings st = settings(8, 8, 1, GaussianShading::Lit);
    st.max_bounces = 2;
    const Film film = render(scene, camera, st);
    const double expected = kUniformAlbedo / kPi * 2.0 * std::cos(kPi / 6);
    for (int j = 0; j < 8; ++j)
        for (int i = 0; i < 8; ++i) ASSERT_NEAR(red(film, i, j), expected, 0.02 * expected) << i << "," << j;
}
