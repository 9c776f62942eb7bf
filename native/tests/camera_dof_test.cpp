// Depth of field (Camera::use_dof, Cycles' thin lens): the rays of every camera model meet at the focus, the aperture
// has Cycles' size and shape, and rendered images of a small emitter out of focus are discs (hexagons, ellipses) of
// the size the circle of confusion predicts.
//
// Cycles' thin lens keeps the pinhole's projection (the sensor stays at the focal length f whatever the focus), so a
// point at distance S2 with the focus at S1 is spread over a disc of diameter, in tangent units (sensor / f),
//   c = A |1/S1 - 1/S2| = A |S2 - S1| / (S1 S2),   A = 2 x aperture radius = f / N (f in metres),
// which is the textbook thin lens's c = A f / (S1 - f) |S2 - S1| / S2 (on a sensor at f S1 / (S1 - f)) with the
// magnification f / S1 in place of f / (S1 - f): the two differ by (S1 - f) / S1, 17 % at the S1 = 0.6 m, f = 0.1 m
// used below, so the renders tell them apart.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include <glm/glm.hpp>

#include "raysplats/errors.h"
#include "raysplats/render/camera.h"
#include "raysplats/render/renderer.h"
#include "render_test_util.h"

using namespace raysplats;
using namespace raysplats::testing;

namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr int kSize = 96;             // image width = height (pixels)
constexpr float kLensMm = 100.0f;     // with the 36 mm sensor: kSize * 100 / 36 pixels per tangent unit
constexpr float kFocus = 0.6f;        // S1 (scene units, metres)
constexpr double kPixelsPerTangent = kSize * 100.0 / 36.0;

Camera dof_camera(float fstop, int blades = 0, float ratio = 1.0f) {
    Camera c;  // at the origin looking down -Z
    c.focal_length_mm = kLensMm;
    c.sensor_width_mm = 36.0f;
    c.clip_start = 0.01f;
    c.use_dof = true;
    c.focus_distance = kFocus;
    c.aperture_fstop = fstop;
    c.aperture_blades = blades;
    c.aperture_ratio = ratio;
    return c;
}

// The disc's radius in pixels: half of c above, A = f / N.
double coc_radius_pixels(float fstop, double s2) {
    const double aperture = kLensMm * 1e-3 / fstop;
    return 0.5 * aperture * std::abs(1.0 / kFocus - 1.0 / s2) * kPixelsPerTangent;
}

// Second moments (pixels^2) about their centroid of the film's red channel over the image: the image of a small
// emitter, i.e. the defocus disc blurred by the emitter's own square (side `emitter_pixels`) and the 1-pixel box of
// the jitter, whose variances (s^2 / 12 each) are taken off.
struct Moments {
    double var_x, var_y, total;
};
Moments image_moments(const Film& film, double emitter_pixels) {
    double sum = 0, sx = 0, sy = 0;
    const float* rgba = film.rgba().data();
    for (int j = 0; j < film.height; ++j)
        for (int i = 0; i < film.width; ++i) {
            const double v = rgba[(std::size_t(j) * film.width + i) * 4];
            sum += v;
            sx += v * (i + 0.5);
            sy += v * (j + 0.5);
        }
    const double cx = sx / sum, cy = sy / sum;
    double vx = 0, vy = 0;
    for (int j = 0; j < film.height; ++j)
        for (int i = 0; i < film.width; ++i) {
            const double v = rgba[(std::size_t(j) * film.width + i) * 4];
            vx += v * (i + 0.5 - cx) * (i + 0.5 - cx);
            vy += v * (j + 0.5 - cy) * (j + 0.5 - cy);
        }
    const double blur = (emitter_pixels * emitter_pixels + 1.0) / 12.0;
    return {vx / sum - blur, vy / sum - blur, sum};
}

// A square emitter of `pixels` pixels' width (in the pinhole image) on the view axis at distance s2, on black.
Film render_emitter(const Camera& camera, double s2, double pixels, int samples) {
    Scene scene;
    scene.set_world(black_world());
    scene.add_material(emissive(1.0f, 1.0f, 1.0f));
    const float half = float(0.5 * pixels / kPixelsPerTangent * s2);
    const TestMesh quad = make_quad_z(-half, half, -half, half, float(-s2), 0);
    scene.add_mesh(quad.desc());
    RenderSettings st;
    st.width = st.height = kSize;
    st.samples = samples;
    st.max_bounces = 0;
    st.seed = 7;
    return render(scene, camera, st);
}

// The point where a ray reaches the plane z = -depth.
void point_at_depth(const CameraRay& r, double depth, double p[3]) {
    const double t = (-depth - r.origin[2]) / r.direction[2];
    for (int i = 0; i < 3; ++i) p[i] = r.origin[i] + t * r.direction[i];
}

}  // namespace

// A uniform disc of radius R has per-axis variance R^2 / 4. Behind the focus (S2 = 3) and in front of it (S2 = 0.4),
// f / 1: the measured radius is within 2 % of the prediction (17.8 and 22.2 px); in focus the emitter stays sharp
// (its variance within 0.4 px^2 of the pinhole's).
TEST(CameraDepthOfField, DefocusDiscHasTheCircleOfConfusionsDiameter) {
    for (const double s2 : {3.0, 0.4}) {
        const Film film = render_emitter(dof_camera(1.0f), s2, 3.0, 1024);
        const Moments m = image_moments(film, 3.0);
        const double expected = coc_radius_pixels(1.0f, s2);
        const double radius_x = 2.0 * std::sqrt(m.var_x), radius_y = 2.0 * std::sqrt(m.var_y);
        std::printf("S2 = %.1f: defocus disc radius %.2f px (x), %.2f px (y); circle of confusion %.2f px\n", s2,
                    radius_x, radius_y, expected);
        EXPECT_NEAR(radius_x / expected, 1.0, 0.02) << "S2 = " << s2 << ": " << radius_x << " px vs " << expected;
        EXPECT_NEAR(radius_y / expected, 1.0, 0.02) << "S2 = " << s2 << ": " << radius_y << " px vs " << expected;
        // Not the textbook thin lens's disc, 1 / 0.833 larger here (see the file's comment).
        EXPECT_GT(std::abs(radius_x / (expected * kFocus / (kFocus - kLensMm * 1e-3)) - 1.0), 0.1);
    }
    const Film sharp = render_emitter(dof_camera(1.0f), kFocus, 3.0, 64);
    const Moments m = image_moments(sharp, 3.0);
    // (A sharp 3-pixel square sampled at pixel centres has 0.08 px^2 more than s^2 / 12 + 1 / 12 per axis.)
    std::printf("in focus: variance beyond the emitter's and the pixel's %.3f px^2\n", m.var_x + m.var_y);
    EXPECT_LT(std::abs(m.var_x) + std::abs(m.var_y), 0.4);
}

// Six blades: a regular hexagon of circumradius R (the disc's radius) has per-axis variance 5 R^2 / 24 (a disc 6 R^2
// / 24); 2 % on the radius. Anamorphic ratio 2 halves the disc's width: var_x / var_y = 1 / 4 (3 %).
TEST(CameraDepthOfField, BladesAndRatioShapeTheRenderedDisc) {
    const double s2 = 3.0, expected = coc_radius_pixels(1.0f, s2);
    const Moments hexagon = image_moments(render_emitter(dof_camera(1.0f, 6), s2, 3.0, 1024), 3.0);
    EXPECT_NEAR(std::sqrt(hexagon.var_x * 24.0 / 5.0) / expected, 1.0, 0.02);
    EXPECT_NEAR(std::sqrt(hexagon.var_y * 24.0 / 5.0) / expected, 1.0, 0.02);
    const Moments anamorphic = image_moments(render_emitter(dof_camera(1.0f, 0, 2.0f), s2, 3.0, 1024), 3.0);
    std::printf("hexagon: circumradius %.2f / %.2f px (x / y) for %.2f px; ratio 2: var_x / var_y %.4f, "
                "radius %.2f px\n",
                std::sqrt(hexagon.var_x * 24.0 / 5.0), std::sqrt(hexagon.var_y * 24.0 / 5.0), expected,
                anamorphic.var_x / anamorphic.var_y, 2.0 * std::sqrt(anamorphic.var_y));
    EXPECT_NEAR(anamorphic.var_x / anamorphic.var_y, 0.25, 0.25 * 0.03);
    EXPECT_NEAR(2.0 * std::sqrt(anamorphic.var_y) / expected, 1.0, 0.02);
}

// The defocus disc's outline, from the rays of one pixel over a 1024 x 1024 grid of lens samples: where each meets the
// plane at S2, projected back through the pinhole, lies within the disc's shape. Six blades, rotation 0: corners on
// the Y axis, an edge's normal on the X axis, extents R and R cos 30 (ratio 1 / cos 30 = 1.1547); rotated by 30
// degrees the two swap; ratio 2 halves the X extent. Tolerance 0.5 %.
TEST(CameraDepthOfField, ApertureOutlineFollowsBladesRotationAndRatio) {
    const double s2 = 3.0, radius = coc_radius_pixels(1.0f, s2);
    auto extents = [&](const Camera& c, double& ex, double& ey) {
        const CameraRayGenerator rays(c, kSize, kSize);
        const CameraRay pinhole = rays(kSize / 2.0f, kSize / 2.0f);
        double centre[3];
        point_at_depth(pinhole, s2, centre);
        ex = ey = 0.0;
        for (int a = 0; a < 1024; ++a)
            for (int b = 0; b < 1024; ++b) {
                double p[3];
                point_at_depth(rays(kSize / 2.0f, kSize / 2.0f, (a + 0.5f) / 1024.0f, (b + 0.5f) / 1024.0f), s2, p);
                ex = std::max(ex, std::abs(p[0] - centre[0]) / s2 * kPixelsPerTangent);
                ey = std::max(ey, std::abs(p[1] - centre[1]) / s2 * kPixelsPerTangent);
            }
    };
    const double cos30 = std::cos(kPi / 6.0);
    double ex, ey;
    extents(dof_camera(1.0f, 6), ex, ey);
    std::printf("hexagon outline: extent %.3f px along a corner (Y), %.3f px along an edge's normal (X), ratio %.4f\n",
                ey, ex, ey / ex);
    EXPECT_NEAR(ey / radius, 1.0, 0.005);
    EXPECT_NEAR(ex / radius, cos30, 0.005);
    EXPECT_NEAR(ey / ex, 1.0 / cos30, 0.005 / cos30);
    Camera rotated = dof_camera(1.0f, 6);
    rotated.aperture_rotation = float(kPi / 6.0);
    extents(rotated, ex, ey);
    EXPECT_NEAR(ex / radius, 1.0, 0.005);
    EXPECT_NEAR(ey / radius, cos30, 0.005);
    extents(dof_camera(1.0f), ex, ey);  // a disc
    EXPECT_NEAR(ex / radius, 1.0, 0.005);
    EXPECT_NEAR(ey / radius, 1.0, 0.005);
    extents(dof_camera(1.0f, 0, 2.0f), ex, ey);
    EXPECT_NEAR(ex / radius, 0.5, 0.005);
    EXPECT_NEAR(ey / radius, 1.0, 0.005);
    extents(dof_camera(1.0f, 2), ex, ey);  // fewer than 3 blades: a disc (Cycles)
    EXPECT_NEAR(ey / ex, 1.0, 0.005);
}

// Every camera model: all rays of an image position, whatever the lens sample, pass through the one point in focus
// (perspective and orthographic: where the pinhole ray reaches the plane at the focus distance along the view axis;
// panoramic: the pinhole ray's point at the focus distance), and leave the lens within Cycles' aperture radius of the
// pinhole ray's origin, across it: f (m) / (2 N) for perspective and panoramic (the perspective lens, also for
// fisheyes), 1 / (2 N) for orthographic. The camera is turned and moved so that world and camera axes differ.
// Tolerance 1e-5 scene units.
TEST(CameraDepthOfField, RaysOfEveryModelMeetAtTheFocus) {
    const Matrix4 placement = Matrix4::translation(0.3f, -2.0f, 1.0f) * Matrix4::rotation(1.2f, 1.0f, 0.2f, 0.0f);
    for (const CameraType type : {CameraType::Perspective, CameraType::Orthographic, CameraType::Equirectangular,
                                  CameraType::FisheyeEquidistant, CameraType::FisheyeEquisolid}) {
        Camera c;
        c.type = type;
        c.camera_to_world = placement;
        c.focal_length_mm = 50.0f;
        c.fisheye_lens_mm = 8.0f;
        c.ortho_scale = 2.0f;
        c.use_dof = true;
        c.focus_distance = 4.0f;
        c.aperture_fstop = 2.0f;
        const bool panoramic = type != CameraType::Perspective && type != CameraType::Orthographic;
        const double radius = type == CameraType::Orthographic ? 1.0 / 4.0 : 0.05 / 4.0;
        const CameraRayGenerator rays(c, 64, 48);
        ASSERT_TRUE(rays.depth_of_field());
        const glm::vec3 forward = glm::normalize(glm::vec3(placement(0, 2), placement(1, 2), placement(2, 2))) * -1.0f;
        for (const float x : {5.5f, 32.0f + 1.0f / 3.0f, 50.25f})
            for (const float y : {7.5f, 24.4f, 40.5f}) {
                const CameraRay pin = rays(x, y);
                if (!pin.valid) continue;
                const glm::vec3 po(pin.origin[0], pin.origin[1], pin.origin[2]),
                    pd(pin.direction[0], pin.direction[1], pin.direction[2]);
                const glm::vec3 focus = panoramic ? po + pd * 4.0f : po + pd * (4.0f / glm::dot(pd, forward));
                double largest = 0.0;
                for (int a = 0; a < 16; ++a)
                    for (int b = 0; b < 16; ++b) {
                        const CameraRay r = rays(x, y, (a + 0.5f) / 16.0f, (b + 0.5f) / 16.0f);
                        ASSERT_TRUE(r.valid);
                        const glm::vec3 o(r.origin[0], r.origin[1], r.origin[2]),
                            d(r.direction[0], r.direction[1], r.direction[2]);
                        EXPECT_NEAR(glm::length(d), 1.0, 1e-5);
                        // The distance of the focus point from the ray's line.
                        const glm::vec3 to_focus = focus - o;
                        EXPECT_LT(glm::length(to_focus - d * glm::dot(to_focus, d)), 1e-5)
                            << "model " << int(type) << " at " << x << ", " << y;
                        const glm::vec3 offset = o - po;
                        // On the lens: across the view axis (perspective, orthographic) or the pinhole ray.
                        EXPECT_LT(std::abs(glm::dot(offset, panoramic ? pd : forward)), 1e-6);
                        EXPECT_LE(glm::length(offset), radius * (1.0 + 1e-5));
                        largest = std::max(largest, double(glm::length(offset)));
                    }
                EXPECT_GT(largest, radius * 0.9) << "model " << int(type);
            }
    }
}

// Clipping stays as without depth of field: a perspective ray keeps its pinhole ray's clip distances (Cycles:
// nearclip and cliplength times the pinhole's 1 / cos to the view axis), an orthographic one starts and ends on the
// clip planes perpendicular to the view axis, a panoramic one at the clip distances along itself.
TEST(CameraDepthOfField, ClipDistancesStayAsForThePinhole) {
    for (const CameraType type : {CameraType::Perspective, CameraType::Orthographic, CameraType::Equirectangular}) {
        Camera c = dof_camera(1.4f);
        c.type = type;
        c.clip_start = 0.5f;
        c.clip_end = 20.0f;
        const CameraRayGenerator rays(c, 64, 64);
        const CameraRay pinhole = rays(10.5f, 50.5f);
        for (const float u : {0.1f, 0.5f, 0.93f}) {
            const CameraRay r = rays(10.5f, 50.5f, u, 1.0f - u);
            if (type == CameraType::Orthographic) {
                EXPECT_NEAR(r.origin[2] + r.t_min * r.direction[2], -0.5, 1e-5);
                EXPECT_NEAR(r.origin[2] + r.t_max * r.direction[2], -20.0, 1e-4);
            } else {
                EXPECT_EQ(r.t_min, pinhole.t_min);
                EXPECT_EQ(r.t_max, pinhole.t_max);
            }
        }
    }
}

// Without use_dof (or with a camera that has it off) the lens sample changes nothing: the pinhole ray, bit for bit.
TEST(CameraDepthOfField, OffIsThePinholeBitForBit) {
    Camera c = dof_camera(2.0f);
    c.use_dof = false;
    const CameraRayGenerator rays(c, 40, 30);
    EXPECT_FALSE(rays.depth_of_field());
    const CameraRay a = rays(12.25f, 7.75f), b = rays(12.25f, 7.75f, 0.3f, 0.8f);
    for (int i = 0; i < 3; ++i) {
        EXPECT_EQ(a.origin[i], b.origin[i]);
        EXPECT_EQ(a.direction[i], b.direction[i]);
    }
    EXPECT_EQ(a.t_min, b.t_min);
    EXPECT_EQ(a.t_max, b.t_max);
}

// Blender's ranges: an f-stop of 0 is Cycles' 1e-5 (a huge aperture), not an error; bad values are errors naming
// the setting.
TEST(CameraDepthOfField, ValidationNamesTheSetting) {
    Camera c = dof_camera(0.0f);
    EXPECT_NO_THROW(c.validate());
    c.focus_distance = -1.0f;
    EXPECT_THROW(c.validate(), InvalidArgument);
    c = dof_camera(2.0f);
    c.aperture_ratio = 0.0f;
    try {
        c.validate();
        FAIL() << "a ratio of 0 was accepted";
    } catch (const InvalidArgument& e) {
        EXPECT_NE(std::string(e.what()).find("ratio"), std::string::npos) << e.what();
    }
    c = dof_camera(2.0f);
    c.aperture_blades = -1;
    EXPECT_THROW(c.validate(), InvalidArgument);
    c = dof_camera(2.0f);
    c.aperture_fstop = std::nanf("");
    EXPECT_THROW(c.validate(), InvalidArgument);
}

// Gaussians out of focus: camera-ray splatting (a pinhole's projection) steps aside and says why; the frame is a
// function of the seed (twice the same seed: the same film bit for bit; another seed: another film), and the lens is
// really sampled (the frame differs from the pinhole's).
TEST(CameraDepthOfField, GaussiansAreTracedAndDeterministic) {
    const GaussianCloud cloud = random_cloud(3, 300, 0.8f);  // (the scene refers to it)
    Scene scene;
    scene.set_world(black_world());
    scene.add_gaussians(cloud, Matrix4::translation(0.0f, 0.0f, -4.0f));
    Camera c = dof_camera(1.0f);
    c.focal_length_mm = 35.0f;
    c.focus_distance = 2.5f;
    RenderSettings st;
    st.width = 48;
    st.height = 40;
    st.samples = 4;
    st.camera_ray_splatting = true;
    const Film a = render(scene, c, st), b = render(scene, c, st);
    EXPECT_FALSE(a.stats.camera_ray_splatting);
    EXPECT_EQ(a.stats.camera_rays_traced_reason, "needs a camera without depth of field");
    EXPECT_EQ(a.rgba(), b.rgba());
    st.seed = 1;
    const Film other_seed = render(scene, c, st);
    EXPECT_NE(a.rgba(), other_seed.rgba());
    c.use_dof = false;
    const Film pinhole = render(scene, c, st);
    EXPECT_TRUE(pinhole.stats.camera_ray_splatting);
    EXPECT_TRUE(pinhole.stats.camera_rays_traced_reason.empty());
    EXPECT_NE(pinhole.rgba(), other_seed.rgba());
}
