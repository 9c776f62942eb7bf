// The denoiser's guides (film.h, SampleRecord::denoising_albedo and denoising_normal; RenderSettings::denoising_data):
// flat Gaussians of one colour over a mesh floor and over the world, against the closed form
//     albedo = a C + (1 - a) B,  normal = a n_G + (1 - a) n_floor
// (a: the Gaussians' coverage, C their linear colour, B the floor's base colour or the world's colour), whatever the
// compositing mode; camera-ray splatting fills them with the same weights; and with the setting off the guides are 0
// and every other channel is bit for bit the same.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>

#include "raysplats/render/renderer.h"
#include "half_floor_scene.h"
#include "render_test_util.h"

using namespace raysplats;
using namespace raysplats::testing;
using namespace raysplats::testing::half_floor;

namespace {

constexpr float kDisplayColor[3] = {0.8f, 0.3f, 0.2f};  // the Gaussians' display colour (as trained)
constexpr float kFloorColor[3] = {0.1f, 0.6f, 0.35f};   // the floor's base colour (linear)
constexpr float kWorldColor[3] = {0.2f, 0.25f, 1.7f};   // the world's (its blue clamped to 1 in the albedo)

// A floor z = 0 over x < 0 and two flat Gaussians 8 units below the camera at x = -1.5 (over the floor) and x = 1.5
// (over the world); a camera looking down from z = 10, orthographic or perspective.
struct GuideScene {
    Scene scene;
    TestMesh floor = make_quad_z(-8.0f, 0.0f, -8.0f, 8.0f, 0.0f, 0);
    GaussianCloud cloud;
    Camera camera;

    explicit GuideScene(CameraType type = CameraType::Orthographic) {
        Material m;
        m.base_color = {kFloorColor[0], kFloorColor[1], kFloorColor[2]};
        scene.add_material(m);
        scene.add_mesh(floor.desc());
        const float q[4] = {1, 0, 0, 0}, s[3] = {kSigma, kSigma, 1e-4f};
        for (float x : {kCentreX, -kCentreX}) {
            const float pos[3] = {x, 0.0f, kLayerZ};
            add_gaussian(cloud, pos, q, s, kOpacity, kDisplayColor);
        }
        scene.add_gaussians(cloud);
        World w;
        w.color = {kWorldColor[0], kWorldColor[1], kWorldColor[2]};
        scene.set_world(w);
        camera.type = type;
        camera.ortho_scale = kOrthoScale;
        camera.camera_to_world = Matrix4::translation(0.0f, 0.0f, kCameraHeight);
    }
};

RenderSettings guide_settings(Compositing compositing, int samples, bool denoising_data = true) {
    RenderSettings s = pixel_centre_settings(compositing, samples);
    s.denoising_data = denoising_data;
    return s;
}

// Checks every pixel of an orthographic render's guides against the closed form; returns the pixels where both the
// Gaussians and what lies behind them count (0.05 < a < 0.95).
int check_guides(const Film& film, double tolerance) {
    int mixed = 0;
    for_each_pixel([&](const Pixel& px) {
        const std::size_t p = px.index;
        const int i = px.i, j = px.j;
        const double a = px.alpha;
        const bool on_floor = px.on_floor;
        mixed += a > 0.05 && a < 0.95;
        const float* albedo = &film[FilmChannel::DenoisingAlbedo][3 * p];
        const float* normal = &film[FilmChannel::DenoisingNormal][3 * p];
        for (int c = 0; c < 3; ++c) {
            const double behind = on_floor ? kFloorColor[c] : std::min(1.0, double(kWorldColor[c]));
            EXPECT_NEAR(albedo[c], a * srgb_to_linear_ref(kDisplayColor[c]) + (1.0 - a) * behind, tolerance)
                << i << ", " << j << " channel " << c;
        }
        // Both the Gaussians' planes and the floor face the camera (+z); the world has no normal.
        EXPECT_NEAR(normal[0], 0.0, tolerance) << i << ", " << j;
        EXPECT_NEAR(normal[1], 0.0, tolerance) << i << ", " << j;
        EXPECT_NEAR(normal[2], a + (on_floor ? 1.0 - a : 0.0), tolerance) << i << ", " << j;
    });
    return mixed;
}

}  // namespace

TEST(DenoisingGuides, SortedCompositingFollowsTheClosedForm) {
    GuideScene s;
    const Film film = render(s.scene, s.camera, guide_settings(Compositing::Sorted, 2));
    EXPECT_GT(check_guides(film, 2e-4), 20);
}

TEST(DenoisingGuides, StochasticCompositingConvergesToIt) {
    // One Gaussian accepted with probability a per sample: the mean albedo's standard error is at most
    // 0.5 / sqrt(4096) = 0.008 per channel; 0.04 is five of them.
    GuideScene s;
    const Film film = render(s.scene, s.camera, guide_settings(Compositing::Stochastic, 4096));
    EXPECT_GT(check_guides(film, 0.04), 20);
}

TEST(DenoisingGuides, CameraRaySplattingWeighsAsItComposites) {
    // The splats' footprints differ from the traced model's, so the closed form's a is not known per pixel; but the
    // guides must still be a C + (1 - a) B with one a in [0, 1] for all three channels and for the normal.
    GuideScene s(CameraType::Perspective);
    RenderSettings st = guide_settings(Compositing::Sorted, 1);
    st.camera_ray_splatting = true;
    const Film film = render(s.scene, s.camera, st);
    ASSERT_TRUE(film.stats.camera_ray_splatting) << film.stats.camera_rays_traced_reason;
    // The floor's normal and the Gaussians' are both +z, so the normal's z is 1 over the floor whatever a, and a over
    // the world (where a <= the opacity 0.9): it tells the two apart and gives a over the world; over the floor a is
    // taken from the albedo's green channel.
    int mixed = 0, floor = 0, world = 0;
    for (std::size_t p = 0; p < film.pixel_count(); ++p) {
        const float* albedo = &film[FilmChannel::DenoisingAlbedo][3 * p];
        const float* normal = &film[FilmChannel::DenoisingNormal][3 * p];
        const bool on_floor = normal[2] > 0.95f;
        double behind[3], color[3];
        for (int c = 0; c < 3; ++c) {
            behind[c] = on_floor ? kFloorColor[c] : std::min(1.0, double(kWorldColor[c]));
            color[c] = srgb_to_linear_ref(kDisplayColor[c]);
        }
        const double a = on_floor ? (albedo[1] - behind[1]) / (color[1] - behind[1]) : normal[2];
        EXPECT_GE(a, -1e-4) << p;
        EXPECT_LE(a, 1.0 + 1e-4) << p;
        for (int c = 0; c < 3; ++c)
            EXPECT_NEAR(albedo[c], a * color[c] + (1.0 - a) * behind[c], 2e-4) << p << " channel " << c;
        EXPECT_NEAR(normal[0], 0.0, 1e-4) << p;
        EXPECT_NEAR(normal[1], 0.0, 1e-4) << p;
        if (on_floor) {
            EXPECT_NEAR(normal[2], 1.0, 1e-4) << p;
        }
        mixed += a > 0.05 && a < 0.95;
        floor += on_floor;
        world += !on_floor;
    }
    EXPECT_GT(floor, 20);
    EXPECT_GT(world, 20);
    EXPECT_GT(mixed, 10);
}

TEST(DenoisingGuides, OffByDefaultAndChangesNothingElse) {
    EXPECT_FALSE(RenderSettings{}.denoising_data);
    for (Compositing compositing : {Compositing::Sorted, Compositing::Stochastic}) {
        GuideScene s;
        const Film off = render(s.scene, s.camera, guide_settings(compositing, 8, false));
        const Film on = render(s.scene, s.camera, guide_settings(compositing, 8, true));
        // Without the flag the film does not hold the guides at all (computed_film_channels).
        EXPECT_TRUE(off[FilmChannel::DenoisingAlbedo].empty());
        EXPECT_TRUE(off[FilmChannel::DenoisingNormal].empty());
        ASSERT_EQ(on[FilmChannel::DenoisingAlbedo].size(), 3 * on.pixel_count());
        double albedo_sum = 0.0;
        for (float v : on[FilmChannel::DenoisingAlbedo]) albedo_sum += v;
        EXPECT_GT(albedo_sum, 1.0);
        for (std::size_t k = 0; k < kFilmChannelCount; ++k) {
            const auto channel = FilmChannel(k);
            if (channel == FilmChannel::DenoisingAlbedo || channel == FilmChannel::DenoisingNormal) continue;
            const FloatBuffer &a = off[channel], &b = on[channel];
            ASSERT_EQ(a.size(), b.size());
            for (std::size_t i = 0; i < a.size(); ++i)
                ASSERT_EQ(std::memcmp(&a[i], &b[i], sizeof(float)), 0) << film_channels()[k].key << " " << i;
        }
    }
}
