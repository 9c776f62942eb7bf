// Light transport against closed forms: Cycles light units on a Lambertian plane, hard shadows, Gaussian
// transmittance in shadow rays, a Gaussian seen in a mirror and through a glass slab.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "raysplats/render/renderer.h"
#include "render_test_util.h"

using namespace raysplats;
using namespace raysplats::testing;

namespace {

constexpr double kPi = 3.14159265358979323846;

Material lambert(float albedo) {
    Material m;
    m.base_color = {albedo, albedo, albedo};
    m.specular = 0.0f;
    m.roughness = 1.0f;
    return m;
}

Camera ortho_down(float z, float scale) {
    Camera c;
    c.type = CameraType::Orthographic;
    c.ortho_scale = scale;
    c.camera_to_world = Matrix4::translation(0, 0, z);
    c.clip_start = 0.01f;
    return c;
}

RenderSettings direct_only(int n, int spp = 1) {
    RenderSettings s;
    s.width = n;
    s.height = n;
    s.samples = spp;
    s.jitter = false;
    s.max_bounces = 0;
    return s;
}

// World position of the centre of pixel (i, j) of an orthographic camera looking down -Z from above the origin.
void pixel_xy(int i, int j, int n, float scale, double& x, double& y) {
    x = ((i + 0.5) / n - 0.5) * scale;
    y = (0.5 - (j + 0.5) / n) * scale;
}

}  // namespace

// Sun of strength S at 30 degrees from the normal: L = albedo / pi * S * cos 30. Relative tolerance 1e-4.
TEST(RenderLighting, SunOnLambertianPlaneIsAnalytic) {
    Scene scene;
    scene.set_world(black_world());
    scene.add_material(lambert(0.6f));
    const TestMesh plane = make_quad_z(-10, 10, -10, 10, 0, 0);
    scene.add_mesh(plane.desc());
    Light sun;
    sun.type = LightType::Sun;
    sun.power = 3.0f;
    sun.light_to_world = Matrix4::rotation(float(kPi / 6), 1, 0, 0);
    scene.add_light(sun);
    const Film film = render(scene, ortho_down(5, 4), direct_only(8));
    const double expected = 0.6 / kPi * 3.0 * std::cos(kPi / 6);
    for (std::size_t p = 0; p < film.pixel_count(); ++p) {
        ASSERT_NEAR(film.rgba()[4 * p], expected, 1e-4 * expected);
        ASSERT_EQ(film.alpha()[p], 1.0f);
    }
}

// Point light of P watts: radiant intensity P / (4 pi) (Cycles), so L = albedo / pi * P / (4 pi d^2) * cos.
// Spot light: the same times Cycles' cos(angle) attenuation inside the cone, zero outside. Relative tolerance 1e-3
// (the shading point is offset from the surface by 1e-4).
TEST(RenderLighting, PointAndSpotLightsFollowCyclesUnits) {
    for (LightType type : {LightType::Point, LightType::Spot}) {
        Scene scene;
        scene.set_world(black_world());
        scene.add_material(lambert(0.5f));
        const TestMesh plane = make_quad_z(-10, 10, -10, 10, 0, 0);
        scene.add_mesh(plane.desc());
        Light light;
        light.type = type;
        light.power = 100.0f;
        light.spot_size = float(kPi / 3);  // 30 degree half angle
        light.spot_blend = 0.0f;
        light.light_to_world = Matrix4::translation(0, 0, 2);
        scene.add_light(light);
        const int n = 16;
        const Film film = render(scene, ortho_down(5, 6), direct_only(n));
        for (int j = 0; j < n; ++j)
            for (int i = 0; i < n; ++i) {
                double x, y;
                pixel_xy(i, j, n, 6, x, y);
                const double d2 = x * x + y * y + 4.0, d = std::sqrt(d2), cos_s = 2.0 / d;
                double expected = 0.5 / kPi * 100.0 / (4 * kPi * d2) * cos_s;
                if (type == LightType::Spot) {
                    const double angle = std::acos(cos_s);
                    if (std::abs(angle - kPi / 6) < 0.02) continue;  // cone edge
                    expected = angle < kPi / 6 ? expected * cos_s : 0.0;
                }
                ASSERT_NEAR(film.rgba()[4 * (j * n + i)], expected, 1e-3 * expected + 1e-7) << i << "," << j;
            }
    }
}

// Area light (rectangle, one-sided, power P): radiance P / (4 A) as in Cycles. Irradiance at the point below the
// centre is integrated numerically in the test; Monte Carlo tolerance 2% at 256 spp.
TEST(RenderLighting, AreaLightFollowsCyclesUnits) {
    Scene scene;
    scene.set_world(black_world());
    scene.add_material(lambert(1.0f));
    const TestMesh plane = make_quad_z(-10, 10, -10, 10, 0, 0);
    scene.add_mesh(plane.desc());
    Light area;
    area.type = LightType::AreaRectangle;
    area.power = 100.0f;
    area.size_x = 1.0f;
    area.size_y = 0.5f;
    area.light_to_world = Matrix4::translation(0, 0, 1);
    scene.add_light(area);
    const Film film = render(scene, ortho_down(5, 0.01f), direct_only(2, 1024));
    const double radiance = 100.0 / (4 * 0.5);
    double e = 0;
    const int g = 400;
    for (int a = 0; a < g; ++a)
        for (int b = 0; b < g; ++b) {
            const double x = ((a + 0.5) / g - 0.5) * 1.0, y = ((b + 0.5) / g - 0.5) * 0.5, d2 = x * x + y * y + 1.0;
            e += radiance * (1.0 / d2) * (1.0 / d2) * (0.5 / (double(g) * g));  // cos_s cos_l / d^2 dA, cos = 1/d
        }
    const double expected = 1.0 / kPi * e;
    double mean = 0;
    for (std::size_t p = 0; p < film.pixel_count(); ++p) mean += film.rgba()[4 * p] / film.pixel_count();
    EXPECT_NEAR(mean, expected, 0.02 * expected);
}

// An opaque unit square 2 above the plane under a sun at 45 degrees casts a unit-square shadow displaced by
// 2 tan 45 = 2: exactly the pixels whose centres fall in x in [-2.5, -1.5], y in [-0.5, 0.5] are dark.
TEST(RenderLighting, OpaqueSquareCastsShadowOfRightSizeAndPlace) {
    Scene scene;
    scene.set_world(black_world());
    scene.add_material(lambert(0.5f));
    const TestMesh plane = make_quad_z(-10, 10, -10, 10, 0, 0);
    const TestMesh blocker = make_quad_z(-0.5f, 0.5f, -0.5f, 0.5f, 2.0f, 0);
    scene.add_mesh(plane.desc());
    scene.add_mesh(blocker.desc());
    Light sun;
    sun.type = LightType::Sun;
    sun.power = 1.0f;
    sun.light_to_world = Matrix4::rotation(float(kPi / 4), 0, 1, 0);  // shines along (-sin 45, 0, -cos 45)
    scene.add_light(sun);
    const int n = 64;
    const Film film = render(scene, ortho_down(5, 8), direct_only(n));
    const double lit = 0.5 / kPi * std::cos(kPi / 4);
    int shadowed = 0;
    for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i) {
            double x, y;
            pixel_xy(i, j, n, 8, x, y);
            if (std::abs(x) < 0.6 && std::abs(y) < 0.6) continue;  // the blocker itself
            const bool in_shadow = x > -2.5 && x < -1.5 && y > -0.5 && y < 0.5;
            ASSERT_NEAR(film.rgba()[4 * (j * n + i)], in_shadow ? 0.0 : lit, 1e-4) << "pixel at " << x << "," << y;
            shadowed += in_shadow;
        }
    EXPECT_EQ(shadowed, 64);  // 1 x 1 at 8 pixels per unit
}

// Two splat sheets (opacities 0.6 and 0.3, scale 2) between a vertical sun and the plane transmit
// (1 - 0.6 G)(1 - 0.3 G), G = exp(-r^2 / 8). Both Gaussian modes. Relative tolerance 1e-4.
TEST(RenderLighting, SplatSheetTransmitsPredictedFraction) {
    GaussianCloud cloud;
    const float q[4] = {1, 0, 0, 0}, s[3] = {2.0f, 2.0f, 0.001f}, rgb[3] = {1, 1, 1};
    const float p1[3] = {0, 0, 1.0f}, p2[3] = {0, 0, 1.5f};
    add_gaussian(cloud, p1, q, s, 0.6f, rgb);
    add_gaussian(cloud, p2, q, s, 0.3f, rgb);
    Scene scene;
    scene.set_world(black_world());
    scene.add_material(lambert(0.5f));
    const TestMesh plane = make_quad_z(-10, 10, -10, 10, 0, 0);
    scene.add_mesh(plane.desc());
    scene.add_gaussians(cloud);
    Light sun;
    sun.type = LightType::Sun;
    sun.power = 1.0f;
    scene.add_light(sun);
    for (GaussianMode mode : {GaussianMode::Flat, GaussianMode::Volumetric}) {
        RenderSettings st = direct_only(16);
        st.gaussian_mode = mode;
        st.transmittance_threshold = 0.0f;
        const Film film = render(scene, ortho_down(0.5f, 8), st);  // the camera sits below the sheets
        for (int j = 0; j < 16; ++j)
            for (int i = 0; i < 16; ++i) {
                double x, y;
                pixel_xy(i, j, 16, 8, x, y);
                const double g = std::exp(-(x * x + y * y) / 8.0);
                const double expected = 0.5 / kPi * (1 - 0.6 * g) * (1 - 0.3 * g);
                ASSERT_NEAR(film.rgba()[4 * (j * 16 + i)], expected, 1e-4 * expected) << x << "," << y;
            }
    }
}

namespace {

// Luminance-weighted centroid (pixels) of the red channel.
void red_centroid(const Film& f, double& cx, double& cy, double& total) {
    cx = cy = total = 0;
    for (int j = 0; j < f.height; ++j)
        for (int i = 0; i < f.width; ++i) {
            const double v = f.rgba()[4 * (std::size_t(j) * f.width + i)];
            cx += v * (i + 0.5);
            cy += v * (j + 0.5);
            total += v;
        }
    if (total > 0) cx /= total, cy /= total;
}

}  // namespace

// A perfect mirror at z = -3 shows a Gaussian at z = +1 (behind the camera at the origin) at its mirror image
// z = -7: the image centroid is the pinhole projection of (0.5, 0.3, -7) within 0.25 pixel.
TEST(RenderLighting, MirrorShowsGaussianBehindCamera) {
    GaussianCloud cloud;
    const float q[4] = {1, 0, 0, 0}, s[3] = {0.08f, 0.08f, 0.001f}, rgb[3] = {1.0f, 0.2f, 0.2f}, pos[3] = {0.5f, 0.3f, 1.0f};
    add_gaussian(cloud, pos, q, s, 0.99f, rgb);
    Material mirror;
    mirror.metallic = 1.0f;
    mirror.roughness = 0.0f;
    mirror.base_color = {1, 1, 1};
    const TestMesh wall = make_quad_z(-20, 20, -20, 20, -3.0f, 0);
    Camera cam;  // at the origin looking down -Z
    cam.focal_length_mm = 50;
    cam.sensor_width_mm = 36;
    RenderSettings st = direct_only(64);
    st.max_bounces = 2;
    {
        Scene without;
        without.set_world(black_world());
        without.add_gaussians(cloud);
        const Film f = render(without, cam, st);
        double cx, cy, total;
        red_centroid(f, cx, cy, total);
        EXPECT_EQ(total, 0.0);  // behind the camera: invisible directly
    }
    Scene scene;
    scene.set_world(black_world());
    scene.add_material(mirror);
    scene.add_mesh(wall.desc());
    scene.add_gaussians(cloud);
    const Film f = render(scene, cam, st);
    double cx, cy, total;
    red_centroid(f, cx, cy, total);
    ASSERT_GT(total, 0.5);
    const double half = 18.0 / 50.0;
    const double ex = (0.5 / 7.0 / half + 1) / 2 * 64, ey = (1 - 0.3 / 7.0 / half) / 2 * 64;
    EXPECT_NEAR(cx, ex, 0.25);
    EXPECT_NEAR(cy, ey, 0.25);
}

// A glass slab (thickness 1, IOR 1.5) tilted 40 degrees shifts what is behind it sideways by
// d sin(theta - theta_t) / cos(theta_t) (Snell). Orthographic view, centroid within 0.5 pixel (1/32 unit / 2).
TEST(RenderLighting, GlassSlabShiftsImageBySnell) {
    GaussianCloud cloud;
    const float q[4] = {1, 0, 0, 0}, s[3] = {0.05f, 0.05f, 0.001f}, rgb[3] = {1, 1, 1}, pos[3] = {0, 0, -5};
    add_gaussian(cloud, pos, q, s, 0.99f, rgb);
    Material glass;
    glass.transmission = 1.0f;
    glass.roughness = 0.0f;
    glass.ior = 1.5f;
    glass.base_color = {1, 1, 1};
    const float lo[3] = {-3, -3, -0.5f}, hi[3] = {3, 3, 0.5f};
    TestMesh slab = make_box(lo, hi, 0);
    const double theta = 40.0 * kPi / 180.0;
    slab.object_to_world = Matrix4::rotation(float(theta), 0, 1, 0);
    Scene scene;
    scene.set_world(black_world());
    scene.add_material(glass);
    scene.add_mesh(slab.desc());
    scene.add_gaussians(cloud);
    RenderSettings st = direct_only(64, 16);
    st.max_bounces = 8;
    const Film f = render(scene, ortho_down(5, 2), st);
    double cx, cy, total;
    red_centroid(f, cx, cy, total);
    ASSERT_GT(total, 1.0);
    const double theta_t = std::asin(std::sin(theta) / 1.5);
    const double shift = std::sin(theta - theta_t) / std::cos(theta_t);  // world units
    const double x_world = (cx / 64 - 0.5) * 2.0;
    EXPECT_NEAR(x_world, shift, 1.0 / 64.0);
    EXPECT_NEAR(cy, 32.0, 0.5);
}

// Cycles 3.x principled diffuse (bsdf_principled_diffuse.h) against its closed form: camera along the normal
// (FV = 0), sun at theta: L = base / pi * S cos(theta) * [(1 - FL / 2) + RR FL], FL = (1 - cos)^5,
// RR = roughness (1 + cos(theta)). Exact up to float rounding.
TEST(RenderLighting, PrincipledDiffuseMatchesClosedForm) {
    for (float roughness : {0.0f, 0.5f, 1.0f}) {
        Scene scene;
        scene.set_world(black_world());
        Material m = lambert(0.6f);
        m.diffuse_model = DiffuseModel::Principled;
        m.roughness = roughness;
        scene.add_material(m);
        const TestMesh plane = make_quad_z(-10, 10, -10, 10, 0, 0);
        scene.add_mesh(plane.desc());
        Light sun;
        sun.type = LightType::Sun;
        sun.power = 3.0f;
        const float theta = 1.0f;  // radians from the normal
        sun.light_to_world = Matrix4::rotation(theta, 0, 1, 0);  // local +Z (towards the sun) tilted in xz
        scene.add_light(sun);
        const Film film = render(scene, ortho_down(5, 1), direct_only(2));
        const double c = std::cos(double(theta)), fl = std::pow(1 - c, 5), rr = roughness * (1 + c);
        const double expected = 0.6 / kPi * 3.0 * c * ((1 - 0.5 * fl) + rr * fl);
        for (std::size_t p = 0; p < film.pixel_count(); ++p)
            EXPECT_NEAR(film.rgba()[4 * p], expected, 1e-4 * expected) << "roughness " << roughness;
    }
}

namespace {

Material mirror_material() {
    Material m;
    m.base_color = {1, 1, 1};
    m.metallic = 1.0f;
    m.roughness = 0.0f;
    return m;
}

}  // namespace

// Area lights are seen by rays (Cycles lights_intersect), one-sided, with radiance P / (4 A): a perfect mirror
// below a downward-facing light shows exactly that radiance (the camera ray passes the light's back unseen).
TEST(RenderLighting, AreaLightSeenInMirrorHasItsRadiance) {
    Scene scene;
    scene.set_world(black_world());
    scene.add_material(mirror_material());
    const TestMesh plane = make_quad_z(-10, 10, -10, 10, 0, 0);
    scene.add_mesh(plane.desc());
    Light area;
    area.type = LightType::AreaRectangle;
    area.power = 100.0f;
    area.size_x = 2.0f;
    area.size_y = 1.0f;
    area.light_to_world = Matrix4::translation(0, 0, 2);
    scene.add_light(area);
    const Film film = render(scene, ortho_down(5, 0.8f), direct_only(4));
    for (std::size_t p = 0; p < film.pixel_count(); ++p) EXPECT_NEAR(film.rgba()[4 * p], 100.0 / (4 * 2.0), 1e-4);
}

// Caustics filter (Cycles' caustics tricks): a floor lit only through a mirror above it (an upward-facing area
// light between them, whose back the floor sees) is lit with reflective caustics and black without.
TEST(RenderLighting, ReflectiveCausticsCanBeTurnedOff) {
    Scene scene;
    scene.set_world(black_world());
    scene.add_material(lambert(1.0f));
    scene.add_material(mirror_material());
    const TestMesh floor = make_quad_z(-10, 10, -10, 10, 0, 0);
    const TestMesh mirror = make_quad_z(-10, 10, -10, 10, 2, 1);
    scene.add_mesh(floor.desc());
    scene.add_mesh(mirror.desc());
    Light area;
    area.type = LightType::AreaRectangle;
    area.power = 100.0f;
    area.light_to_world = Matrix4::translation(0, 0, 1) * Matrix4::rotation(3.14159265f, 1, 0, 0);  // emits +Z
    scene.add_light(area);
    RenderSettings st = direct_only(4, 4096);  // about 2200 of the 65536 diffuse rays see the light: 2 % noise
    st.max_bounces = 1;
    const Film on = render(scene, ortho_down(0.5f, 0.2f), st);
    st.caustics_reflective = false;
    const Film off = render(scene, ortho_down(0.5f, 0.2f), st);
    // Irradiance from the mirror image of the light (1 x 1, radiance 25, 3 above the floor), integrated.
    double e = 0;
    const int g = 200;
    for (int a = 0; a < g; ++a)
        for (int b = 0; b < g; ++b) {
            const double x = (a + 0.5) / g - 0.5, y = (b + 0.5) / g - 0.5, d2 = x * x + y * y + 9.0;
            e += 25.0 * 9.0 / (d2 * d2) / (double(g) * g);
        }
    double mean_on = 0, max_off = 0;
    for (std::size_t p = 0; p < on.pixel_count(); ++p) {
        mean_on += on.rgba()[4 * p] / on.pixel_count();
        max_off = std::max(max_off, double(off.rgba()[4 * p]));
    }
    EXPECT_NEAR(mean_on, e / kPi, 0.08 * e / kPi);
    EXPECT_EQ(max_off, 0.0);
}
