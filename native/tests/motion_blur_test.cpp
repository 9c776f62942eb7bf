// Motion blur (Scene::set_mesh_motion / set_gaussians_motion, Camera::motion): each camera ray draws a shutter time,
// uniform over [0, 1], and sees every object where its motion places it then. An object moving at constant speed
// by D pixels over the shutter is its still image convolved with a box of length D along the motion, so the image's
// variance along the motion grows by exactly D^2 / 12 (variances of independent offsets add) and its total stays the
// still image's; the same holds when the camera moves by the opposite amount instead.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

#include "raysplats/errors.h"
#include "raysplats/render/camera.h"
#include "raysplats/render/renderer.h"
#include "render_test_util.h"

using namespace raysplats;
using namespace raysplats::testing;

namespace {

constexpr int kSize = 96;
constexpr float kDepth = 1.0f;                                // the objects' plane, z = -kDepth
constexpr double kPixelsPerUnit = kSize * 100.0 / 36.0 / kDepth;  // lens 100 mm, sensor 36 mm
constexpr double kTravelPixels = 30.0;                        // D: how far objects move during the shutter
constexpr float kTravel = float(kTravelPixels / kPixelsPerUnit);

Camera test_camera() {
    Camera c;  // at the origin looking down -Z
    c.focal_length_mm = 100.0f;
    c.sensor_width_mm = 36.0f;
    c.clip_start = 0.01f;
    return c;
}

RenderSettings test_settings(int samples) {
    RenderSettings st;
    st.width = st.height = kSize;
    st.samples = samples;
    st.max_bounces = 0;
    st.seed = 11;
    st.blend_space = BlendSpace::Linear;  // the film's mean is the mean of the samples' linear values
    return st;
}

// Moving along X from -travel/2 to +travel/2 over the shutter, in `steps` equally spaced matrices.
std::vector<Matrix4> sliding(float travel, int steps = 3) {
    std::vector<Matrix4> m;
    for (int k = 0; k < steps; ++k) m.push_back(Matrix4::translation(travel * (float(k) / (steps - 1) - 0.5f), 0, 0));
    return m;
}

// Total and variance along X (pixels^2) of the red channel over the image.
struct Spread {
    double total = 0.0, mean_x = 0.0, var_x = 0.0;
};

Spread spread_x(const Film& film) {
    Spread s;
    const float* rgba = film.rgba().data();
    double sx = 0.0, sxx = 0.0;
    for (int j = 0; j < film.height; ++j)
        for (int i = 0; i < film.width; ++i) {
            const double v = rgba[(std::size_t(j) * film.width + i) * 4];
            const double x = i + 0.5;
            s.total += v;
            sx += v * x;
            sxx += v * x * x;
        }
    s.mean_x = sx / s.total;
    s.var_x = sxx / s.total - s.mean_x * s.mean_x;
    return s;
}

// A thin vertical emissive bar (2 x 40 pixels) at the image's centre, moving or not.
Film render_bar(const std::vector<Matrix4>& motion, const Camera& camera, int samples, std::uint32_t seed = 11) {
    Scene scene;
    scene.set_world(black_world());
    scene.add_material(emissive(1.0f, 1.0f, 1.0f));
    const float half_w = float(1.0 / kPixelsPerUnit), half_h = float(20.0 / kPixelsPerUnit);
    const TestMesh bar = make_quad_z(-half_w, half_w, -half_h, half_h, -kDepth, 0);
    scene.add_mesh(bar.desc());
    scene.set_mesh_motion(0, motion);
    RenderSettings st = test_settings(samples);
    st.seed = seed;
    return render(scene, camera, st);
}

}  // namespace

// A bar moving D = 30 px over the shutter: the variance along the motion grows by D^2 / 12 = 75 px^2 (within 2 %),
// the total (the bar's energy) stays within 1 %, the centre stays put, and the smear's extent (pixels of the middle
// row above 10 % of the box's level) is D + the bar's width to within 2 px.
TEST(MotionBlur, MovingBarSmearsBySpeedTimesShutter) {
    const Spread still = spread_x(render_bar({}, test_camera(), 64));
    const Film moving_film = render_bar(sliding(kTravel), test_camera(), 256);
    const Spread moving = spread_x(moving_film);
    const double expected = kTravelPixels * kTravelPixels / 12.0;
    std::printf("variance still %.3f, moving %.3f px^2: growth %.3f (D^2/12 = %.3f); totals %.2f %.2f\n",
                still.var_x, moving.var_x, moving.var_x - still.var_x, expected, still.total, moving.total);
    EXPECT_NEAR(moving.var_x - still.var_x, expected, 0.02 * expected);
    EXPECT_NEAR(moving.total, still.total, 0.01 * still.total);
    EXPECT_NEAR(moving.mean_x, still.mean_x, 0.3);
    // The middle row: the box's level is the bar's width over D (2 / 30 of the bar's own value, 1).
    const float* rgba = moving_film.rgba().data();
    int first = -1, last = -1;
    for (int i = 0; i < kSize; ++i)
        if (rgba[(std::size_t(kSize / 2) * kSize + i) * 4] > 0.1 * 2.0 / kTravelPixels) {
            if (first < 0) first = i;
            last = i;
        }
    std::printf("smear extent %d px (D + width = %.0f)\n", last - first + 1, kTravelPixels + 2.0);
    EXPECT_NEAR(last - first + 1, kTravelPixels + 2.0, 2.0);
}

// The camera moving by -D instead of the bar by +D makes the same smear (position interpolated between its steps),
// and a camera turning about its Y axis by the angle that moves the centre by D smears it by D too (rotation
// interpolated spherically: at the image centre, tan(a) ~ a to 0.1 % for the 6.4 degrees here).
TEST(MotionBlur, MovingCameraSmearsAsTheObjectWould) {
    const Spread still = spread_x(render_bar({}, test_camera(), 64));
    const double expected = kTravelPixels * kTravelPixels / 12.0;
    Camera sliding_camera = test_camera();
    sliding_camera.motion = sliding(-kTravel);
    const Spread slid = spread_x(render_bar({}, sliding_camera, 256));
    Camera turning = test_camera();
    const float angle = float(std::atan(kTravel / kDepth));
    turning.motion = {Matrix4::rotation(-0.5f * angle, 0, 1, 0), Matrix4::rotation(0.5f * angle, 0, 1, 0)};
    const Spread turned = spread_x(render_bar({}, turning, 256));
    std::printf("variance growth: sliding camera %.3f, turning camera %.3f px^2 (D^2/12 = %.3f)\n",
                slid.var_x - still.var_x, turned.var_x - still.var_x, expected);
    EXPECT_NEAR(slid.var_x - still.var_x, expected, 0.02 * expected);
    EXPECT_NEAR(slid.total, still.total, 0.01 * still.total);
    EXPECT_NEAR(turned.var_x - still.var_x, expected, 0.03 * expected);
    EXPECT_NEAR(turned.mean_x, still.mean_x, 0.3);
}

// A triangular shutter curve (closed, fully open at the middle, closed) draws times with a triangular density, whose
// variance is 1/24 of the shutter squared: the bar's variance grows by D^2 / 24 (within 3 %) instead of D^2 / 12.
TEST(MotionBlur, ShutterCurveShapesTheSmear) {
    Camera c = test_camera();
    c.shutter_curve = {0.0f, 1.0f, 0.0f};
    const CameraRayGenerator rays(c, kSize, kSize);
    EXPECT_NEAR(rays.shutter_time(0.0f), 0.0f, 1e-3f);
    EXPECT_NEAR(rays.shutter_time(0.5f), 0.5f, 1e-3f);
    EXPECT_NEAR(rays.shutter_time(0.125f), 0.25f, 2e-3f);  // the integral of the triangle up to 1/4 is 1/8
    EXPECT_NEAR(rays.shutter_time(0.999f), 1.0f, 0.03f);
    const Spread still = spread_x(render_bar({}, test_camera(), 64));
    const Spread moving = spread_x(render_bar(sliding(kTravel), c, 256));
    const double expected = kTravelPixels * kTravelPixels / 24.0;
    std::printf("triangular shutter: variance growth %.3f px^2 (D^2/24 = %.3f)\n", moving.var_x - still.var_x,
                expected);
    EXPECT_NEAR(moving.var_x - still.var_x, expected, 0.03 * expected);
    EXPECT_NEAR(moving.total, still.total, 0.01 * still.total);
    c.shutter_curve = {0.0f, 0.0f};
    EXPECT_THROW(c.validate(), InvalidArgument);
    c.shutter_curve = {1.0f};
    EXPECT_THROW(c.validate(), InvalidArgument);
}

// A Gaussian cloud moves with its instance: the variance of a small blob grows by D^2 / 12 within 2 %, for flat and
// volumetric Gaussians.
TEST(MotionBlur, MovingGaussiansSmearBySpeedTimesShutter) {
    GaussianCloud cloud;
    cloud.sh_degree = 0;
    const float p[3] = {0.0f, 0.0f, 0.0f}, q[4] = {1, 0, 0, 0}, rgb[3] = {1.0f, 1.0f, 1.0f};
    const float sigma = float(1.5 / kPixelsPerUnit);
    const float s[3] = {sigma, sigma, 0.2f * sigma};
    add_gaussian(cloud, p, q, s, 0.9f, rgb);
    for (GaussianMode mode : {GaussianMode::Flat, GaussianMode::Volumetric}) {
        Scene scene;
        scene.set_world(black_world());
        scene.add_gaussians(cloud, Matrix4::translation(0.0f, 0.0f, -kDepth));
        RenderSettings st = test_settings(64);
        st.gaussian_mode = mode;
        const Spread still = spread_x(render(scene, test_camera(), st));
        std::vector<Matrix4> motion = sliding(kTravel);
        for (Matrix4& m : motion) m = Matrix4::translation(0.0f, 0.0f, -kDepth) * m;
        scene.set_gaussians_motion(0, motion);
        EXPECT_TRUE(scene.has_motion());
        st.samples = 256;
        const Spread moving = spread_x(render(scene, test_camera(), st));
        const double expected = kTravelPixels * kTravelPixels / 12.0;
        std::printf("%s: variance still %.3f, growth %.3f px^2 (D^2/12 = %.3f); totals %.4f %.4f\n",
                    mode == GaussianMode::Flat ? "flat" : "volumetric", still.var_x, moving.var_x - still.var_x,
                    expected, still.total, moving.total);
        EXPECT_NEAR(moving.var_x - still.var_x, expected, 0.02 * expected);
        EXPECT_NEAR(moving.total, still.total, 0.02 * still.total);
    }
}

// The frame is a function of the seed; camera-ray splatting (one projection per frame) steps aside and says why;
// taking the motion back gives the still film bit for bit.
TEST(MotionBlur, DeterministicAndSplattingStepsAside) {
    const GaussianCloud cloud = random_cloud(3, 300, 0.8f);  // (the scene refers to it)
    Scene scene;
    scene.set_world(black_world());
    scene.add_gaussians(cloud, Matrix4::translation(0.0f, 0.0f, -4.0f));
    RenderSettings st;
    st.width = 48;
    st.height = 40;
    st.samples = 4;
    st.camera_ray_splatting = true;
    Camera c = test_camera();
    c.focal_length_mm = 35.0f;
    const Film still = render(scene, c, st);
    EXPECT_TRUE(still.stats.camera_ray_splatting);
    std::vector<Matrix4> motion = sliding(0.5f);
    for (Matrix4& m : motion) m = Matrix4::translation(0.0f, 0.0f, -4.0f) * m;
    scene.set_gaussians_motion(0, motion);
    const Film a = render(scene, c, st), b = render(scene, c, st);
    EXPECT_FALSE(a.stats.camera_ray_splatting);
    EXPECT_EQ(a.stats.camera_rays_traced_reason, "needs a scene without motion blur");
    EXPECT_EQ(a.rgba(), b.rgba());
    EXPECT_NE(a.rgba(), still.rgba());
    st.seed = 1;
    EXPECT_NE(render(scene, c, st).rgba(), a.rgba());
    st.seed = 0;
    scene.set_gaussians_motion(0, {});
    EXPECT_FALSE(scene.has_motion());
    EXPECT_EQ(render(scene, c, st).rgba(), still.rgba());
    // A moving camera alone is reason enough.
    c.motion = sliding(0.1f);
    const Film moving_camera = render(scene, c, st);
    EXPECT_EQ(moving_camera.stats.camera_rays_traced_reason, "needs a scene without motion blur");
}

// Bad motion is an error naming the object and the step.
TEST(MotionBlur, ValidationNamesTheStep) {
    Scene scene;
    const TestMesh quad = make_quad_z(-1, 1, -1, 1, -2, 0);
    scene.add_material(emissive(1, 1, 1));
    scene.add_mesh(quad.desc());
    std::vector<Matrix4> motion = sliding(1.0f);
    motion[1](0, 3) = std::nanf("");
    try {
        scene.set_mesh_motion(0, motion);
        FAIL() << "a NaN motion step was taken";
    } catch (const InvalidArgument& e) {
        EXPECT_NE(std::string(e.what()).find("mesh 0 motion step 1"), std::string::npos) << e.what();
    }
    EXPECT_THROW(scene.set_mesh_motion(0, std::vector<Matrix4>(130)), InvalidArgument);
    EXPECT_THROW(scene.set_mesh_motion(1, sliding(1.0f)), InvalidArgument);
    EXPECT_THROW(scene.set_gaussians_motion(0, sliding(1.0f)), InvalidArgument);
    Camera c = test_camera();
    c.motion = std::vector<Matrix4>(2, Matrix4::scale(0, 1, 1));
    EXPECT_THROW(c.validate(), InvalidArgument);
}

// The Vector pass (SampleRecord::vector, Cycles' motion pass): a plane moving D px a frame along +X under a camera
// moving E px a frame along +Y reads (-D, +E, -D, +E) wherever it is seen, 0 on the world, and 0 everywhere without
// the camera's frame motion; a Gaussian cloud reads the same.
TEST(MotionVectors, MovingObjectAndCameraGiveTheirImageMotion) {
    const TestMesh plane = make_quad_z(-0.1f, 0.1f, -0.1f, 0.1f, -kDepth, 0);
    GaussianCloud cloud;
    cloud.sh_degree = 0;
    const float p[3] = {0.0f, 0.0f, 0.0f}, q[4] = {1, 0, 0, 0}, s[3] = {0.03f, 0.03f, 0.003f}, rgb[3] = {1, 1, 1};
    add_gaussian(cloud, p, q, s, 0.99f, rgb);
    const float d = float(10.0 / kPixelsPerUnit), e = float(5.0 / kPixelsPerUnit);
    Camera c = test_camera();
    RenderSettings st = test_settings(1);
    for (bool gaussians : {false, true}) {
        Scene scene;
        scene.set_world(black_world());
        scene.add_material(emissive(1, 1, 1));
        if (gaussians) {
            const Matrix4 at = Matrix4::translation(0.0f, 0.0f, -kDepth);
            scene.add_gaussians(cloud, at);
            scene.set_gaussians_frame_motion(0, Matrix4::translation(-d, 0, 0) * at,
                                             Matrix4::translation(d, 0, 0) * at);
        } else {
            scene.add_mesh(plane.desc());
            scene.set_mesh_frame_motion(0, Matrix4::translation(-d, 0, 0), Matrix4::translation(d, 0, 0));
        }
        c.frame_motion.clear();
        const Film without = render(scene, c, st);
        for (float v : without[FilmChannel::Vector]) ASSERT_EQ(v, 0.0f);
        c.frame_motion = {Matrix4::translation(0, -e, 0), Matrix4::translation(0, e, 0)};
        const Film film = render(scene, c, st);
        const float expected[4] = {-10.0f, 5.0f, -10.0f, 5.0f};
        std::size_t seen = 0;
        double error = 0.0;
        for (std::size_t px = 0; px < film.pixel_count(); ++px) {
            const float* v = &film[FilmChannel::Vector][4 * px];
            if (std::isinf(film.depth()[px])) {
                for (int k = 0; k < 4; ++k) ASSERT_EQ(v[k], 0.0f) << "world pixel " << px;
                continue;
            }
            ++seen;
            for (int k = 0; k < 4; ++k) error = std::max(error, double(std::abs(v[k] - expected[k])));
        }
        std::printf("%s: %zu pixels seen, max |vector error| %.2e px\n", gaussians ? "Gaussians" : "mesh", seen, error);
        EXPECT_GT(seen, 100u);
        EXPECT_LT(error, 1e-3);
    }
}
