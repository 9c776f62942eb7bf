// The compositor's data passes (film.h, SampleRecord): Mist, Position, Object Index and Material Index of a mesh
// floor and of flat Gaussians over it, against a closed-form computation of the scene, whatever the compositing mode.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>

#include "raysplats/errors.h"
#include "raysplats/render/renderer.h"
#include "half_floor_scene.h"
#include "render_test_util.h"

using namespace raysplats;
using namespace raysplats::testing;
using namespace raysplats::testing::half_floor;

namespace {

constexpr float kMistStart = 3.0f, kMistDepth = 8.0f;

// Cycles' mist (kernel/film/data_passes.h).
double mist_of(double distance, double falloff) {
    return std::pow(std::clamp((distance - kMistStart) / kMistDepth, 0.0, 1.0), falloff);
}

// A floor z = 0 over x < 0 (object pass index 3, its material's 5) and one flat Gaussian 8 units below the camera
// at x = 1.5 (its cloud's pass indices 9 and 11); an orthographic camera looking down from z = 10.
struct DataPassScene {
    Scene scene;
    TestMesh floor = make_quad_z(-8.0f, 0.0f, -8.0f, 8.0f, 0.0f, 0);
    GaussianCloud cloud;
    Camera camera;

    explicit DataPassScene(float falloff) {
        Material m;
        m.pass_index = 5;
        scene.add_material(m);
        MeshDesc d = floor.desc();
        d.pass_index = 3;
        scene.add_mesh(d);
        const float pos[3] = {kCentreX, 0.0f, kLayerZ}, q[4] = {1, 0, 0, 0}, s[3] = {kSigma, kSigma, 1e-4f};
        const float rgb[3] = {0.8f, 0.3f, 0.2f};
        add_gaussian(cloud, pos, q, s, kOpacity, rgb);
        // A second one left of the floor's edge, over the floor.
        const float left[3] = {-1.5f, 0.0f, kLayerZ};
        add_gaussian(cloud, left, q, s, kOpacity, rgb);
        scene.add_gaussians(cloud);
        scene.set_gaussian_pass_indices(0, 9, 11);
        World w;
        w.mist_start = kMistStart, w.mist_depth = kMistDepth, w.mist_falloff = falloff;
        scene.set_world(w);
        camera.type = CameraType::Orthographic;
        camera.ortho_scale = kOrthoScale;
        camera.camera_to_world = Matrix4::translation(0.0f, 0.0f, kCameraHeight);
    }
};

struct Checked {
    int gaussian = 0, floor = 0, world = 0;
};

// Checks every pixel of `film` against the closed form; `mist_tolerance`: of the Mist pass (a mean over samples).
Checked check_passes(const Film& film, double falloff, double mist_tolerance) {
    Checked n;
    for_each_pixel([&](const Pixel& px) {
        const std::size_t p = px.index;
        const int i = px.i, j = px.j;
        const double x = px.x, y = px.y, alpha = px.alpha;
        const bool on_floor = px.on_floor;
        // Orthographic: the distance along the view axis. The world contributes mist 1.
        const double behind = on_floor ? 1.0 - mist_of(kCameraHeight, falloff) : 0.0;
        const double mist = 1.0 - alpha * (1.0 - mist_of(kCameraHeight - kLayerZ, falloff)) - (1.0 - alpha) * behind;
        EXPECT_NEAR(film[FilmChannel::Mist][p], mist, mist_tolerance) << i << ", " << j;
        const float* position = &film[FilmChannel::Position][3 * p];
        const float object = film[FilmChannel::ObjectIndex][p], material = film[FilmChannel::MaterialIndex][p];
        if (alpha > 0.52) {  // the Gaussian is the surface where the opacity reaches 0.5
            ++n.gaussian;
            EXPECT_EQ(object, 9.0f);
            EXPECT_EQ(material, 11.0f);
            EXPECT_NEAR(position[0], x, 1e-4);
            EXPECT_NEAR(position[1], y, 1e-4);
            EXPECT_NEAR(position[2], kLayerZ, 1e-4);
        } else if (alpha < 0.48 && on_floor) {
            ++n.floor;
            EXPECT_EQ(object, 3.0f);
            EXPECT_EQ(material, 5.0f);
            EXPECT_NEAR(position[2], 0.0, 1e-4);
        } else if (alpha < 0.48) {
            ++n.world;
            EXPECT_EQ(object, 0.0f);
            EXPECT_EQ(material, 0.0f);
            EXPECT_EQ(position[0], 0.0f);
            EXPECT_EQ(position[2], 0.0f);
        }
    });
    return n;
}

}  // namespace

// The settings of a render with the Mist pass (RenderSettings::mist_pass).
RenderSettings mist_settings(Compositing compositing, int samples) {
    RenderSettings s = pixel_centre_settings(compositing, samples);
    s.mist_pass = true;
    return s;
}

TEST(RenderDataPasses, SortedCompositingFollowsTheClosedForm) {
    for (float falloff : {2.0f, 1.0f, 0.5f}) {
        DataPassScene s(falloff);
        const Film film = render(s.scene, s.camera, mist_settings(Compositing::Sorted, 2));
        const Checked n = check_passes(film, falloff, 2e-4);
        EXPECT_GT(n.gaussian, 20);
        EXPECT_GT(n.floor, 20);
        EXPECT_GT(n.world, 20);
    }
}

TEST(RenderDataPasses, StochasticCompositingConvergesToIt) {
    // One Gaussian accepted with probability alpha per sample: the mean mist converges (4096 samples: standard error
    // below 0.4 * 0.5 / 64).
    DataPassScene s(1.0f);
    const Film film = render(s.scene, s.camera, mist_settings(Compositing::Stochastic, 4096));
    for (std::size_t p = 0; p < film.pixel_count(); ++p) {
        EXPECT_GE(film[FilmChannel::Mist][p], 0.0f);
        EXPECT_LE(film[FilmChannel::Mist][p], 1.0f);
    }
    // Indices and positions of one sample are the accepted Gaussian's or what lies behind: only the mean is checked.
    for_each_pixel([&](const Pixel& px) {
        const double alpha = px.alpha;
        const double behind = px.on_floor ? 1.0 - mist_of(kCameraHeight, 1.0) : 0.0;
        const double mist = 1.0 - alpha * (1.0 - mist_of(kCameraHeight - kLayerZ, 1.0)) - (1.0 - alpha) * behind;
        EXPECT_NEAR(film[FilmChannel::Mist][px.index], mist, 0.02) << px.i << ", " << px.j;
    });
}

TEST(RenderDataPasses, WorldMistSettingsAreValidated) {
    Scene scene;
    World w;
    w.mist_depth = -1.0f;
    EXPECT_THROW(scene.set_world(w), InvalidArgument);
    w.mist_depth = 1.0f;
    w.mist_falloff = 0.0f;
    EXPECT_THROW(scene.set_world(w), InvalidArgument);
    EXPECT_THROW(scene.set_gaussian_pass_indices(0, 1, 2), InvalidArgument);  // no such cloud
}

TEST(RenderDataPasses, MistOffComputesNothingAndChangesNothingElse) {
    // Without the Mist pass the channel holds 1 (no surface's term was added) and every other channel is bit for bit
    // that of the render with it, in both compositing modes and with camera-ray splatting.
    EXPECT_FALSE(RenderSettings{}.mist_pass);
    for (int mode = 0; mode < 3; ++mode) {
        DataPassScene s(1.0f);
        if (mode == 2) s.camera.type = CameraType::Perspective;
        RenderSettings off = pixel_centre_settings(mode == 1 ? Compositing::Stochastic : Compositing::Sorted, 8);
        off.jitter = true;
        off.camera_ray_splatting = mode == 2;
        RenderSettings on = off;
        on.mist_pass = true;
        const Film without = render(s.scene, s.camera, off), with = render(s.scene, s.camera, on);
        EXPECT_EQ(without.stats.camera_ray_splatting, mode == 2);
        double mist_sum = 0.0;
        for (float v : with[FilmChannel::Mist]) mist_sum += v;
        EXPECT_LT(mist_sum, 0.99 * double(with.pixel_count())) << mode;  // the pass saw the floor and the Gaussians
        for (float v : without[FilmChannel::Mist]) ASSERT_EQ(v, 1.0f) << mode;
        expect_channels_bit_identical(without, with, "Mist off and on", {FilmChannel::Mist});
    }
}
