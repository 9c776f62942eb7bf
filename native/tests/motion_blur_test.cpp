// Motion blur (Scene::set_mesh_motion / set_gaussians_motion, Camera::motion): each camera ray draws a shutter time,
// uniform over [0, 1], and sees every object where its motion places it then. An object moving at constant speed
// by D pixels over the shutter is its still image convolved with a box of length D along the motion, so the image's
// variance along the motion grows by exactly D^2 / 12 (variances of independent offsets add) and its total stays the
// still image's; the same holds when the camera moves by the opposite amount instead.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <random>
#include <vector>

#include "raysplats/errors.h"
#include "raysplats/render/camera.h"
#include "raysplats/render/renderer.h"
#include "render/gaussian_primitives.h"
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

namespace {

// Deformation blur (Scene::set_mesh_deformation): the bar's vertices at the steps of `shifts` (x offsets), step
// after step, as one array.
std::vector<float> shifted_bar_steps(const TestMesh& bar, const std::vector<float>& shifts) {
    std::vector<float> steps;
    for (float dx : shifts)
        for (std::size_t i = 0; i < bar.vertex_count(); ++i)
            steps.insert(steps.end(), {bar.vertices[3 * i] + dx, bar.vertices[3 * i + 1], bar.vertices[3 * i + 2]});
    return steps;
}

TestMesh thin_bar() {
    const float half_w = float(1.0 / kPixelsPerUnit), half_h = float(20.0 / kPixelsPerUnit);
    return make_quad_z(-half_w, half_w, -half_h, half_h, -kDepth, 0);
}

}  // namespace

// A bar whose vertices (not its matrix) move D = 30 px over the shutter smears as the moving bar does: the variance
// along the motion grows by D^2 / 12 (within 2 %) and the total stays (1 %); inside a moving object's own motion the
// two add (the bar deformed by +D while its object moves by +D: (2D)^2 / 12).
TEST(DeformationBlur, DeformedBarSmearsBySpeedTimesShutter) {
    const TestMesh bar = thin_bar();
    const std::vector<float> steps = shifted_bar_steps(bar, {-0.5f * kTravel, 0.0f, 0.5f * kTravel});
    Scene scene;
    scene.set_world(black_world());
    scene.add_material(emissive(1.0f, 1.0f, 1.0f));
    scene.add_mesh(bar.desc());
    RenderSettings st = test_settings(64);
    const Spread still = spread_x(render(scene, test_camera(), st));
    scene.set_mesh_deformation(0, steps.data(), 3, bar.vertex_count());
    EXPECT_TRUE(scene.has_motion());
    st.samples = 256;
    const Spread deformed = spread_x(render(scene, test_camera(), st));
    scene.set_mesh_motion(0, sliding(kTravel));
    const Spread both = spread_x(render(scene, test_camera(), st));
    const double expected = kTravelPixels * kTravelPixels / 12.0;
    std::printf("deformed bar: variance growth %.3f px^2 (D^2/12 = %.3f); deformed and moving %.3f (%.3f); totals "
                "%.2f %.2f\n", deformed.var_x - still.var_x, expected, both.var_x - still.var_x, 4.0 * expected,
                still.total, deformed.total);
    EXPECT_NEAR(deformed.var_x - still.var_x, expected, 0.02 * expected);
    EXPECT_NEAR(deformed.total, still.total, 0.01 * still.total);
    EXPECT_NEAR(deformed.mean_x, still.mean_x, 0.3);
    EXPECT_NEAR(both.var_x - still.var_x, 4.0 * expected, 0.02 * 4.0 * expected);
}

// A ray of time t sees the triangles where the linear interpolation of the two steps around t puts them: with a
// shutter curve open only around one time (a spike of width 1/100 of the shutter), the bar's image centre is at the
// interpolated place within 0.3 px, for three steps at -D/2, +D/2 and 0 (so that a wrong step order or slot shows).
TEST(DeformationBlur, TrianglesAreWhereTheRaysTimePutsThem) {
    const TestMesh bar = thin_bar();
    const std::vector<float> shifts = {-0.5f * kTravel, 0.5f * kTravel, 0.0f};
    const std::vector<float> steps = shifted_bar_steps(bar, shifts);
    Scene scene;
    scene.set_world(black_world());
    scene.add_material(emissive(1.0f, 1.0f, 1.0f));
    scene.add_mesh(bar.desc());
    const Spread still = spread_x(render(scene, test_camera(), test_settings(16)));
    scene.set_mesh_deformation(0, steps.data(), 3, bar.vertex_count());
    for (float t : {0.0f, 0.25f, 0.5f, 0.75f, 1.0f}) {
        Camera c = test_camera();
        c.shutter_curve.assign(201, 0.0f);
        c.shutter_curve[std::size_t(std::lround(t * 200.0f))] = 1.0f;
        const Spread at = spread_x(render(scene, c, test_settings(16)));
        const float f = t * 2.0f;
        const std::size_t k = std::min<std::size_t>(std::size_t(f), 1);
        const double shift = ((1.0f - (f - k)) * shifts[k] + (f - k) * shifts[k + 1]) * kPixelsPerUnit;
        std::printf("time %.2f: centre moved %.3f px (expected %.3f)\n", t, at.mean_x - still.mean_x, shift);
        EXPECT_NEAR(at.mean_x - still.mean_x, shift, 0.3) << "time " << t;
        EXPECT_NEAR(at.total, still.total, 0.02 * still.total) << "time " << t;
    }
}

// The frame is a function of the seed; taking the deformation back gives the still film bit for bit; camera-ray
// splatting steps aside for a deforming mesh as for a moving one.
TEST(DeformationBlur, DeterministicAndStillWithout) {
    const TestMesh bar = thin_bar();
    const std::vector<float> steps = shifted_bar_steps(bar, {0.0f, kTravel});
    Scene scene;
    scene.set_world(black_world());
    scene.add_material(emissive(1.0f, 1.0f, 1.0f));
    scene.add_mesh(bar.desc());
    RenderSettings st = test_settings(4);
    st.camera_ray_splatting = true;
    const Film still = render(scene, test_camera(), st);
    scene.set_mesh_deformation(0, steps.data(), 2, bar.vertex_count());
    const Film a = render(scene, test_camera(), st), b = render(scene, test_camera(), st);
    EXPECT_EQ(a.rgba(), b.rgba());
    EXPECT_NE(a.rgba(), still.rgba());
    EXPECT_EQ(a.stats.camera_rays_traced_reason, "needs a scene without motion blur");
    scene.set_mesh_deformation(0, nullptr, 0, 0);
    EXPECT_FALSE(scene.has_motion());
    EXPECT_EQ(render(scene, test_camera(), st).rgba(), still.rgba());
    // An update of the mesh drops its deformation.
    scene.set_mesh_deformation(0, steps.data(), 2, bar.vertex_count());
    scene.update_mesh(0, bar.desc());
    EXPECT_FALSE(scene.has_motion());
    EXPECT_EQ(render(scene, test_camera(), st).rgba(), still.rgba());
}

// A bad deformation is an error naming the mesh, the step and the vertex.
TEST(DeformationBlur, ValidationNamesTheVertex) {
    const TestMesh bar = thin_bar();
    std::vector<float> steps = shifted_bar_steps(bar, {0.0f, 1.0f});
    Scene scene;
    scene.add_material(emissive(1, 1, 1));
    scene.add_mesh(bar.desc());
    steps[3 * bar.vertex_count() + 4] = std::nanf("");
    try {
        scene.set_mesh_deformation(0, steps.data(), 2, bar.vertex_count());
        FAIL() << "a NaN deformation was taken";
    } catch (const InvalidArgument& e) {
        EXPECT_NE(std::string(e.what()).find("mesh 0: deformation step 1 vertex 1"), std::string::npos) << e.what();
    }
    EXPECT_FALSE(scene.has_motion());
    steps[3 * bar.vertex_count() + 4] = 0.0f;
    EXPECT_THROW(scene.set_mesh_deformation(0, steps.data(), 2, bar.vertex_count() + 1), InvalidArgument);
    EXPECT_THROW(scene.set_mesh_deformation(1, steps.data(), 2, bar.vertex_count()), InvalidArgument);
    EXPECT_THROW(scene.set_mesh_deformation(0, nullptr, 2, bar.vertex_count()), InvalidArgument);
    std::vector<float> many(130 * 3 * bar.vertex_count(), 0.0f);
    EXPECT_THROW(scene.set_mesh_deformation(0, many.data(), 130, bar.vertex_count()), InvalidArgument);
}

namespace {

// A deformation of `cloud` (Scene::set_gaussians_deformation's arrays): each step's positions, rotations, scales.
struct CloudSteps {
    std::vector<float> positions, rotations, scales;
    std::size_t steps = 0;
    void add(const GaussianCloud& step) {
        positions.insert(positions.end(), step.positions.begin(), step.positions.end());
        rotations.insert(rotations.end(), step.rotations.begin(), step.rotations.end());
        scales.insert(scales.end(), step.scales.begin(), step.scales.end());
        ++steps;
    }
    void give(Scene& scene, std::uint32_t index, std::size_t count) const {
        scene.set_gaussians_deformation(index, steps, positions.data(), rotations.data(), scales.data(), count);
    }
};

// `cloud` moved by dx along X.
GaussianCloud shifted(GaussianCloud cloud, float dx) {
    for (std::size_t i = 0; i < cloud.size(); ++i) cloud.positions[3 * i] += dx;
    return cloud;
}

// Image covariance (pixels^2) of the red channel: xx, yy, xy.
std::array<double, 3> image_covariance(const Film& film) {
    const float* rgba = film.rgba().data();
    double total = 0, sx = 0, sy = 0, sxx = 0, syy = 0, sxy = 0;
    for (int j = 0; j < film.height; ++j)
        for (int i = 0; i < film.width; ++i) {
            const double v = rgba[(std::size_t(j) * film.width + i) * 4], x = i + 0.5, y = j + 0.5;
            total += v, sx += v * x, sy += v * y, sxx += v * x * x, syy += v * y * y, sxy += v * x * y;
        }
    const double mx = sx / total, my = sy / total;
    return {sxx / total - mx * mx, syy / total - my * my, sxy / total - mx * my};
}

}  // namespace

// Gaussians whose centres (not their cloud's matrix) move D = 30 px over the shutter smear as a moving cloud does:
// the variance along the motion grows by D^2 / 12 within 2 %, flat and volumetric, and the total stays (2 %).
TEST(RenderGaussianDeformation, DeformedGaussiansSmearBySpeedTimesShutter) {
    GaussianCloud cloud;
    cloud.sh_degree = 0;
    const float p[3] = {0.0f, 0.0f, 0.0f}, q[4] = {1, 0, 0, 0}, rgb[3] = {1.0f, 1.0f, 1.0f};
    const float sigma = float(1.5 / kPixelsPerUnit);
    const float s[3] = {sigma, sigma, 0.2f * sigma};
    add_gaussian(cloud, p, q, s, 0.9f, rgb);
    CloudSteps steps;
    for (float dx : {-0.5f * kTravel, 0.0f, 0.5f * kTravel}) steps.add(shifted(cloud, dx));
    for (GaussianMode mode : {GaussianMode::Flat, GaussianMode::Volumetric}) {
        Scene scene;
        scene.set_world(black_world());
        scene.add_gaussians(cloud, Matrix4::translation(0.0f, 0.0f, -kDepth));
        RenderSettings st = test_settings(64);
        st.gaussian_mode = mode;
        const Spread still = spread_x(render(scene, test_camera(), st));
        steps.give(scene, 0, cloud.size());
        EXPECT_TRUE(scene.has_motion());
        st.samples = 256;
        const Spread moving = spread_x(render(scene, test_camera(), st));
        const double expected = kTravelPixels * kTravelPixels / 12.0;
        std::printf("%s deformed: variance growth %.3f px^2 (D^2/12 = %.3f); totals %.4f %.4f\n",
                    mode == GaussianMode::Flat ? "flat" : "volumetric", moving.var_x - still.var_x, expected,
                    still.total, moving.total);
        EXPECT_NEAR(moving.var_x - still.var_x, expected, 0.02 * expected);
        EXPECT_NEAR(moving.total, still.total, 0.02 * still.total);
    }
}

// A ray of time t sees a Gaussian interpolated between the steps around t: with the shutter open only around t (a
// spike 1/100 of the shutter wide), a small Gaussian's image centre is where the interpolated centre projects
// (0.3 px), for steps at -D/2, +D/2, 0; and an elongated Gaussian turned by 90 degrees in three steps is seen at
// t = 1/2 turned by 45 degrees with its shape kept (normalised quaternion interpolation): the image's covariance has
// its principal axis at 45 degrees (|xy| = (major - minor) / 2 within 5 %) and the same major and minor variances as at t = 0
// (5 %), which it would not if the bounds at the steps did not hold it in between (a clipped image is narrower); the
// same Gaussian given with its axes named otherwise at one step stays as it is.
TEST(RenderGaussianDeformation, GaussiansAreWhereTheRaysTimePutsThem) {
    GaussianCloud cloud;
    cloud.sh_degree = 0;
    const float p[3] = {0.0f, 0.0f, 0.0f}, q[4] = {1, 0, 0, 0}, rgb[3] = {1.0f, 1.0f, 1.0f};
    const float sigma = float(1.0 / kPixelsPerUnit);
    const float s[3] = {sigma, sigma, 0.2f * sigma};
    add_gaussian(cloud, p, q, s, 0.9f, rgb);
    const std::vector<float> shifts = {-0.5f * kTravel, 0.5f * kTravel, 0.0f};
    CloudSteps steps;
    for (float dx : shifts) steps.add(shifted(cloud, dx));
    Scene scene;
    scene.set_world(black_world());
    scene.add_gaussians(cloud, Matrix4::translation(0.0f, 0.0f, -kDepth));
    const Spread still = spread_x(render(scene, test_camera(), test_settings(16)));
    steps.give(scene, 0, cloud.size());
    for (float t : {0.0f, 0.25f, 0.5f, 0.75f, 1.0f}) {
        Camera c = test_camera();
        c.shutter_curve.assign(201, 0.0f);
        c.shutter_curve[std::size_t(std::lround(t * 200.0f))] = 1.0f;
        const Spread at = spread_x(render(scene, c, test_settings(16)));
        const float f = t * 2.0f;
        const std::size_t k = std::min<std::size_t>(std::size_t(f), 1);
        const double shift = ((1.0f - (f - k)) * shifts[k] + (f - k) * shifts[k + 1]) * kPixelsPerUnit;
        std::printf("Gaussian at time %.2f: centre moved %.3f px (expected %.3f)\n", t, at.mean_x - still.mean_x,
                    shift);
        EXPECT_NEAR(at.mean_x - still.mean_x, shift, 0.3) << "time " << t;
    }
    // Turning: 6 x 1.5 px, its long axis along X at step 0 and along Y at step 1.
    GaussianCloud long_one;
    long_one.sh_degree = 0;
    const float ls[3] = {float(6.0 / kPixelsPerUnit), float(1.5 / kPixelsPerUnit), 0.2f * sigma};
    add_gaussian(long_one, p, q, ls, 0.9f, rgb);
    // Four steps 30 degrees apart about Z (a turn of more than 45 degrees between two steps would be taken the
    // short way, by the other axis: see the renamed axes below).
    CloudSteps turn;
    GaussianCloud turned = long_one;
    for (int k = 0; k < 4; ++k) {
        const float angle = float(k) * float(M_PI) / 6.0f;
        turned.rotations = {std::cos(0.5f * angle), 0.0f, 0.0f, std::sin(0.5f * angle)};
        turn.add(turned);
    }
    for (GaussianMode mode : {GaussianMode::Flat, GaussianMode::Volumetric}) {
        Scene turning;
        turning.set_world(black_world());
        turning.add_gaussians(long_one, Matrix4::translation(0.0f, 0.0f, -kDepth));
        turn.give(turning, 0, long_one.size());
        RenderSettings st = test_settings(64);
        st.gaussian_mode = mode;
        Camera c = test_camera();
        c.shutter_curve.assign(201, 0.0f);
        c.shutter_curve[0] = 1.0f;
        const std::array<double, 3> start = image_covariance(render(turning, c, st));
        c.shutter_curve[0] = 0.0f;
        c.shutter_curve[100] = 1.0f;
        const std::array<double, 3> middle = image_covariance(render(turning, c, st));
        auto eigen = [](const std::array<double, 3>& m) {
            const double mean = 0.5 * (m[0] + m[1]), d = std::sqrt(0.25 * (m[0] - m[1]) * (m[0] - m[1]) + m[2] * m[2]);
            return std::array<double, 2>{mean + d, mean - d};
        };
        const auto a = eigen(start), b = eigen(middle);
        std::printf("%s turning Gaussian: covariance at 0 (%.2f %.2f %.2f), at 1/2 (%.2f %.2f %.2f) px^2\n",
                    mode == GaussianMode::Flat ? "flat" : "volumetric", start[0], start[1], start[2], middle[0],
                    middle[1], middle[2]);
        EXPECT_GT(start[0], 4.0 * start[1]) << "long along X at the shutter's opening";
        // (|xy|: the film's rows run down the image, which flips the sign of a turn about the view axis.)
        EXPECT_NEAR(std::abs(middle[2]), 0.5 * (a[0] - a[1]), 0.05 * 0.5 * (a[0] - a[1])) << "turned by 45 degrees";
        EXPECT_NEAR(b[0], a[0], 0.05 * a[0]);
        EXPECT_NEAR(b[1], a[1], 0.05 * a[1]);
        // The same Gaussian given at step 1 with its axes named otherwise (turned by 90 degrees, its X and Y scales
        // swapped): it does not turn or change in between (the steps' axes are aligned).
        GaussianCloud renamed = turned;
        std::swap(renamed.scales[0], renamed.scales[1]);
        CloudSteps same;
        same.add(long_one);
        same.add(renamed);
        same.give(turning, 0, long_one.size());
        const std::array<double, 3> kept = image_covariance(render(turning, c, st));
        std::printf("renamed axes: covariance at 1/2 (%.2f %.2f %.2f) px^2\n", kept[0], kept[1], kept[2]);
        for (int k = 0; k < 3; ++k) EXPECT_NEAR(kept[k], start[k], 0.05 * start[0]) << k;
    }
}

// The bounds Embree is given at each time step, interpolated linearly, hold every Gaussian of their group at every
// time between (its support box: centre +- sqrt(support) times the box of its axes), for Gaussians that move, turn
// and change scale by much during one step.
TEST(RenderGaussianDeformation, BoundsAtTheStepsHoldTheGaussiansBetween) {
    const GaussianCloud cloud = random_cloud(7, 200, 1.0f);
    std::mt19937 rng(5);
    std::uniform_real_distribution<float> u(-1.0f, 1.0f);
    for (bool flat : {true, false}) {
        GaussianSet set;
        set.cloud = &cloud;
        set.prepare(flat ? GaussianMode::Flat : GaussianMode::Volumetric, false);
        GaussianChunk chunk;
        chunk.set = &set;
        chunk.count = std::uint32_t(cloud.size());
        set.build_groups(chunk);
        set.deformation.steps = 3;
        for (std::size_t k = 0; k < 3; ++k)
            for (std::size_t i = 0; i < cloud.size(); ++i) {
                for (int a = 0; a < 3; ++a) {
                    set.deformation.positions.push_back(cloud.positions[3 * i + a] + 0.3f * u(rng));
                    set.deformation.scales.push_back(cloud.scales[3 * i + a] * (1.0f + 0.5f * u(rng)));
                }
                glm::vec4 q(u(rng), u(rng), u(rng), u(rng));
                q = glm::normalize(q);
                if (k > 0) {
                    const float* prev = &set.deformation.rotations[4 * ((k - 1) * cloud.size() + i)];
                    if (glm::dot(q, glm::vec4(prev[0], prev[1], prev[2], prev[3])) < 0.0f) q = -q;
                }
                for (int a = 0; a < 4; ++a) set.deformation.rotations.push_back(q[a]);
            }
        set.build_deformation(chunk);
        const std::size_t groups = chunk.groups.size();
        ASSERT_EQ(chunk.deformed_bounds.size(), 3 * groups);
        int checked = 0;
        for (int step = 0; step <= 40; ++step) {
            const float t = float(step) / 40.0f;
            const float f = t * 2.0f;
            const std::size_t k = std::min<std::size_t>(std::size_t(f), 1);
            const float w = f - float(k);
            for (std::uint32_t gi = 0; gi < groups; ++gi) {
                GaussianGroup g;
                set.deformed_group(chunk, gi, t, g);
                const RTCBounds& a = chunk.deformed_bounds[k * groups + gi];
                const RTCBounds& b = chunk.deformed_bounds[(k + 1) * groups + gi];
                const glm::vec3 lower = (1 - w) * glm::vec3(a.lower_x, a.lower_y, a.lower_z) +
                                        w * glm::vec3(b.lower_x, b.lower_y, b.lower_z);
                const glm::vec3 upper = (1 - w) * glm::vec3(a.upper_x, a.upper_y, a.upper_z) +
                                        w * glm::vec3(b.upper_x, b.upper_y, b.upper_z);
                for (std::uint32_t lane = 0; lane < g.count; ++lane) {
                    glm::mat3 m;  // rows 0..2 (glm: m[column][row])
                    for (int r = 0; r < 3; ++r)
                        for (int c = 0; c < 3; ++c) m[c][r] = g.row[3 * r + c][lane];
                    const glm::mat3 l = glm::inverse(m);
                    const float radius = std::sqrt(g.support[lane]);
                    for (int j = 0; j < 3; ++j) {
                        float extent = l[0][j] * l[0][j] + l[1][j] * l[1][j];
                        if (!flat) extent += l[2][j] * l[2][j];
                        const float half = radius * std::sqrt(extent);
                        const float centre = g.center[j][lane];
                        const float slack = 1e-4f * (1.0f + std::abs(centre) + half);
                        EXPECT_GE(centre - half, lower[j] - slack) << "time " << t << " group " << gi;
                        EXPECT_LE(centre + half, upper[j] + slack) << "time " << t << " group " << gi;
                        ++checked;
                    }
                }
            }
        }
        EXPECT_GT(checked, 1000);
    }
}

// Steps that move every Gaussian alike render what the same motion of their cloud's matrix renders (many overlapping
// flat and volumetric Gaussians, sorted and stochastic; a ray of each time sees the same Gaussians, so only
// rounding differs: mean absolute difference under 0.1 % of the mean pixel): no Gaussian is lost to its bounds or
// to the group it is tested in, and the shutter times are drawn alike.
TEST(RenderGaussianDeformation, MovingEveryGaussianAlikeRendersAsMovingTheCloud) {
    const GaussianCloud cloud = random_cloud(3, 2000, 0.8f);
    const float travel = 0.4f;
    CloudSteps steps;
    for (float dx : {-0.5f * travel, 0.0f, 0.5f * travel}) steps.add(shifted(cloud, dx));
    std::vector<Matrix4> motion = sliding(travel);
    for (Matrix4& m : motion) m = Matrix4::translation(0.0f, 0.0f, -3.0f) * m;
    Camera c = test_camera();
    c.focal_length_mm = 35.0f;
    for (GaussianMode mode : {GaussianMode::Flat, GaussianMode::Volumetric})
        for (bool stochastic : {false, true}) {
            RenderSettings st;
            st.width = st.height = 48;
            st.samples = 16;
            st.gaussian_mode = mode;
            if (stochastic) st.compositing = Compositing::Stochastic;
            Scene moved, deformed;
            for (Scene* scene : {&moved, &deformed}) {
                scene->set_world(black_world());
                scene->add_gaussians(cloud, Matrix4::translation(0.0f, 0.0f, -3.0f));
            }
            moved.set_gaussians_motion(0, motion);
            steps.give(deformed, 0, cloud.size());
            const Film a = render(moved, c, st), b = render(deformed, c, st);
            double diff = 0.0, total = 0.0;
            for (std::size_t i = 0; i < a.rgba().size(); ++i) {
                diff += std::abs(double(b.rgba()[i]) - a.rgba()[i]);
                total += a.rgba()[i];
            }
            std::printf("%s %s: mean |difference| %.4f %% of the mean\n",
                        mode == GaussianMode::Flat ? "flat" : "volumetric", stochastic ? "stochastic" : "sorted",
                        100.0 * diff / total);
            EXPECT_LT(diff, 1e-3 * total);
        }
}

// Gaussian deformation: one frame per seed, the still film without it (and after update_gaussians drops it), and
// bad input named.
TEST(RenderGaussianDeformation, DeterministicStillWithoutAndValidated) {
    const GaussianCloud cloud = random_cloud(3, 300, 0.8f);
    CloudSteps steps;
    steps.add(cloud);
    steps.add(shifted(cloud, 0.3f));
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
    steps.give(scene, 0, cloud.size());
    const Film a = render(scene, c, st), b = render(scene, c, st);
    EXPECT_EQ(a.stats.camera_rays_traced_reason, "needs a scene without motion blur");
    EXPECT_EQ(a.rgba(), b.rgba());
    EXPECT_NE(a.rgba(), still.rgba());
    scene.set_gaussians_deformation(0, 0, nullptr, nullptr, nullptr, 0);
    EXPECT_FALSE(scene.has_motion());
    EXPECT_EQ(render(scene, c, st).rgba(), still.rgba());
    steps.give(scene, 0, cloud.size());
    scene.update_gaussians(0, cloud, Matrix4::translation(0.0f, 0.0f, -4.0f));
    EXPECT_FALSE(scene.has_motion());
    EXPECT_EQ(render(scene, c, st).rgba(), still.rgba());

    CloudSteps bad = steps;
    bad.scales[3 * cloud.size() + 7] = -1.0f;  // step 1, Gaussian 2
    try {
        bad.give(scene, 0, cloud.size());
        FAIL() << "a negative scale was taken";
    } catch (const InvalidArgument& e) {
        EXPECT_NE(std::string(e.what()).find("Gaussian cloud 0: deformation step 1 Gaussian 2"), std::string::npos)
            << e.what();
    }
    bad = steps;
    std::fill(bad.rotations.begin(), bad.rotations.begin() + 4, 0.0f);
    EXPECT_THROW(bad.give(scene, 0, cloud.size()), InvalidArgument);
    EXPECT_THROW(steps.give(scene, 0, cloud.size() - 1), InvalidArgument);
    EXPECT_THROW(steps.give(scene, 1, cloud.size()), InvalidArgument);
    EXPECT_FALSE(scene.has_motion());
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

// A deforming mesh's Vector (Scene::set_mesh_frame_deformation): its vertices D px to the left at the previous
// frame and D to the right at the next, under a still camera, read (-D, 0, -D, 0) wherever it is seen; on a mesh
// whose object also moves D px a frame, both add: (-2D, 0, -2D, 0); a vertex that stays still while the others move
// gives each point of a triangle its barycentric share (the plane's vertices 0 and 1 moved, 2 and 3 still: the
// vector grows linearly from the still edge); without it the object's matrices alone count.
TEST(MotionVectors, DeformingMeshGivesItsVerticesMotion) {
    const TestMesh plane = make_quad_z(-0.1f, 0.1f, -0.1f, 0.1f, -kDepth, 0);
    const float d = float(10.0 / kPixelsPerUnit);
    const std::vector<float> previous = shifted_bar_steps(plane, {-d}), next = shifted_bar_steps(plane, {d});
    Camera c = test_camera();
    c.frame_motion = {Matrix4{}, Matrix4{}};
    RenderSettings st = test_settings(1);
    auto max_error = [&](const Film& film, float expected_x) {
        double error = 0.0;
        std::size_t seen = 0;
        for (std::size_t px = 0; px < film.pixel_count(); ++px) {
            if (std::isinf(film.depth()[px])) continue;
            ++seen;
            const float* v = &film[FilmChannel::Vector][4 * px];
            const float expected[4] = {expected_x, 0.0f, expected_x, 0.0f};
            for (int k = 0; k < 4; ++k) error = std::max(error, double(std::abs(v[k] - expected[k])));
        }
        EXPECT_GT(seen, 100u);
        return error;
    };
    Scene scene;
    scene.set_world(black_world());
    scene.add_material(emissive(1, 1, 1));
    scene.add_mesh(plane.desc());
    EXPECT_LT(max_error(render(scene, c, st), 0.0f), 1e-6) << "still";
    scene.set_mesh_frame_deformation(0, previous.data(), next.data(), plane.vertex_count());
    const double deformed = max_error(render(scene, c, st), -10.0f);
    scene.set_mesh_frame_motion(0, Matrix4::translation(-d, 0, 0), Matrix4::translation(d, 0, 0));
    const double both = max_error(render(scene, c, st), -20.0f);
    std::printf("deforming mesh: max |vector error| %.2e px, deforming and moving %.2e px\n", deformed, both);
    EXPECT_LT(deformed, 1e-3);
    EXPECT_LT(both, 1e-3);
    scene.set_mesh_frame_deformation(0, nullptr, nullptr, 0);
    EXPECT_LT(max_error(render(scene, c, st), -10.0f), 1e-3) << "the object's matrices alone";
    // Vertices 0 and 1 (y = -0.1) moved, 2 and 3 (y = +0.1) still: a point's x vector is -D times its share of the
    // moved edge, (0.1 - y) / 0.2, which is linear in the image row.
    scene.set_mesh_frame_motion(0, Matrix4{}, Matrix4{});
    std::vector<float> half_previous = previous, half_next = next;
    for (int i : {2, 3}) half_previous[3 * i] = half_next[3 * i] = plane.vertices[3 * i];
    scene.set_mesh_frame_deformation(0, half_previous.data(), half_next.data(), plane.vertex_count());
    const Film half = render(scene, c, st);
    double error = 0.0;
    for (int j = 0; j < half.height; ++j)
        for (int i = 0; i < half.width; ++i) {
            const std::size_t px = std::size_t(j) * half.width + i;
            if (std::isinf(half.depth()[px])) continue;
            const double y = half[FilmChannel::Position][3 * px + 1];  // the surface point (world)
            const double expected = -10.0 * (0.1 - y) / 0.2;
            error = std::max(error, std::abs(half[FilmChannel::Vector][4 * px] - expected));
        }
    std::printf("half-deformed mesh: max |vector error| %.2e px\n", error);
    EXPECT_LT(error, 1e-3);
    EXPECT_THROW(scene.set_mesh_frame_deformation(0, previous.data(), next.data(), plane.vertex_count() + 1),
                 InvalidArgument);
    EXPECT_THROW(scene.set_mesh_frame_deformation(1, previous.data(), next.data(), plane.vertex_count()),
                 InvalidArgument);
}
