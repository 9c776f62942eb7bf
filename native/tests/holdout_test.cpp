// Blender's Holdout (MeshDesc::holdout, Scene::set_gaussian_holdout), Shadow Catcher (MeshDesc::shadow_catcher) and
// the Environment pass (film.h, SampleRecord) of a mesh floor and flat Gaussians over it, against closed forms of the
// scene: held-out Gaussians lose their coverage T_i a_i from Combined's alpha and add no colour, a held-out mesh takes
// all the transmittance left and no colour, a shadow catcher shows the Gaussians' shadow as alpha and as the Shadow
// Catcher pass, and the Environment pass is the world's colour times the transmittance where the camera ray escapes.
#include <gtest/gtest.h>

#include <cmath>

#include "raysplats/errors.h"
#include "raysplats/render/renderer.h"
#include "half_floor_scene.h"
#include "render_test_util.h"

using namespace raysplats;
using namespace raysplats::testing;
using namespace raysplats::testing::half_floor;

namespace {

constexpr float kEmission[3] = {0.5f, 0.4f, 0.3f};
constexpr float kWorld[3] = {0.1f, 0.2f, 0.3f};
constexpr float kGaussianColor[3] = {0.8f, 0.3f, 0.2f};

// An emissive floor z = 0 over x < 0 and the two flat Gaussians of half_floor_scene.h in the plane z = 2 (one over
// the floor, one over the world); an orthographic camera looking down from z = 10.
struct HoldoutScene {
    Scene scene;
    TestMesh floor = make_quad_z(-8.0f, 0.0f, -8.0f, 8.0f, 0.0f, 0);
    GaussianCloud cloud;
    Camera camera;

    HoldoutScene(bool floor_held_out, bool gaussians_held_out) {
        scene.add_material(emissive(kEmission[0], kEmission[1], kEmission[2]));
        MeshDesc d = floor.desc();
        d.holdout = floor_held_out;
        scene.add_mesh(d);
        const float q[4] = {1, 0, 0, 0}, s[3] = {kSigma, kSigma, 1e-4f};
        for (float x : {kCentreX, -kCentreX}) {
            const float pos[3] = {x, 0.0f, kLayerZ};
            add_gaussian(cloud, pos, q, s, kOpacity, kGaussianColor);
        }
        scene.add_gaussians(cloud);
        if (gaussians_held_out) scene.set_gaussian_holdout(0, true);
        World w;
        w.color = {kWorld[0], kWorld[1], kWorld[2]};
        scene.set_world(w);
        camera.type = CameraType::Orthographic;
        camera.ortho_scale = kOrthoScale;
        camera.camera_to_world = Matrix4::translation(0.0f, 0.0f, kCameraHeight);
    }
};

RenderSettings linear_settings(Compositing compositing, int samples, bool transparent) {
    RenderSettings s = pixel_centre_settings(compositing, samples);
    s.blend_space = BlendSpace::Linear;  // closed forms in linear light
    s.transparent_background = transparent;
    return s;
}

}  // namespace

TEST(Holdout, HeldOutGaussiansLoseTheirCoverageAndColour) {
    for (bool transparent : {false, true}) {
        HoldoutScene s(false, true);
        const Film film = render(s.scene, s.camera, linear_settings(Compositing::Sorted, 2, transparent));
        int gaussian = 0;
        for_each_pixel([&](const Pixel& px) {
            const double a = px.alpha, t = 1.0 - a;
            const float* rgba = &film.rgba()[4 * px.index];
            const float* env = &film[FilmChannel::Environment][3 * px.index];
            gaussian += a > 0.3;
            // Behind the held-out Gaussians: the floor's emission or the world, times what they let through.
            const double alpha = px.on_floor ? t : (transparent ? 0.0 : t);
            EXPECT_NEAR(rgba[3], alpha, 2e-4) << px.i << ", " << px.j;
            for (int c = 0; c < 3; ++c) {
                const double behind = px.on_floor ? kEmission[c] : (transparent ? 0.0 : kWorld[c]);
                EXPECT_NEAR(rgba[c], t * behind, 2e-4) << px.i << ", " << px.j << " " << c;
                EXPECT_NEAR(env[c], px.on_floor ? 0.0 : t * kWorld[c], 2e-4) << px.i << ", " << px.j << " " << c;
            }
            // The Alpha pass stays the coverage.
            EXPECT_NEAR(film.alpha()[px.index], px.on_floor ? 1.0 : a, 2e-4);
        });
        EXPECT_GT(gaussian, 40);
    }
}

TEST(Holdout, AHeldOutMeshLeavesOnlyWhatIsInFrontOfIt) {
    // The Gaussians are mirror images about x = 0: over the held-out floor they show what they show over the world
    // with a transparent background (their own colour and coverage, nothing behind).
    for (bool transparent : {false, true}) {
        HoldoutScene s(true, false);
        const Film film = render(s.scene, s.camera, linear_settings(Compositing::Sorted, 2, transparent));
        HoldoutScene reference(false, false);
        World black = black_world();
        reference.scene.set_world(black);
        const Film over_nothing = render(reference.scene, reference.camera,
                                         linear_settings(Compositing::Sorted, 2, true));
        int floor = 0;
        for_each_pixel([&](const Pixel& px) {
            const float* rgba = &film.rgba()[4 * px.index];
            if (px.on_floor) {
                ++floor;
                const std::size_t mirror = std::size_t(px.j) * kWidth + std::size_t(kWidth - 1 - px.i);
                EXPECT_NEAR(rgba[3], px.alpha, 2e-4) << px.i << ", " << px.j;
                for (int c = 0; c < 3; ++c)
                    EXPECT_NEAR(rgba[c], over_nothing.rgba()[4 * mirror + c], 1e-5) << px.i << ", " << px.j;
                EXPECT_EQ(film.alpha()[px.index], 1.0f);  // the coverage: the floor covers the pixel
            } else {
                EXPECT_NEAR(rgba[3], transparent ? px.alpha : 1.0, 2e-4) << px.i << ", " << px.j;
            }
        });
        EXPECT_GT(floor, 100);
    }
}

TEST(Holdout, StochasticCompositingConvergesToTheHeldOutFraction) {
    // One Gaussian accepted with probability alpha per sample, held out: alpha 1 - a on the mean (1024 samples:
    // standard error below 0.5 / 32).
    HoldoutScene s(false, true);
    const Film film = render(s.scene, s.camera, linear_settings(Compositing::Stochastic, 1024, false));
    for_each_pixel([&](const Pixel& px) {
        EXPECT_NEAR(film.rgba()[4 * px.index + 3], 1.0 - px.alpha, 0.06) << px.i << ", " << px.j;
    });
}

TEST(Holdout, CameraRaySplattingStepsAsideForHeldOutGaussians) {
    HoldoutScene s(false, true);
    s.camera.type = CameraType::Perspective;
    RenderSettings settings = linear_settings(Compositing::Sorted, 1, false);
    settings.camera_ray_splatting = true;
    const Film film = render(s.scene, s.camera, settings);
    EXPECT_FALSE(film.stats.camera_ray_splatting);
    EXPECT_EQ(film.stats.camera_rays_traced_reason, "needs no Gaussian object held out");
}

// A shadow catcher floor (x < 0) under the Gaussians of HoldoutScene and a sun tilted 45 degrees about X, so that each Gaussian's
// shadow falls 2 units (its height) along +Y from it: the floor point (x, y) sees the sun through the Gaussian layer at
// (x, y - 2), r = 1 - a(x, y - 2), and the camera sees the point through T = 1 - a(x, y).
struct CatcherScene : HoldoutScene {
    CatcherScene() : HoldoutScene(false, false) {
        MeshDesc d = floor.desc();
        d.material = scene.add_material(Material{});  // grey and diffuse: the sun's light reaches it
        d.shadow_catcher = true;
        scene.update_mesh(0, d);
        Light sun;
        sun.type = LightType::Sun;
        sun.power = 3.0f;
        sun.light_to_world = Matrix4::rotation(0.78539816f, 1.0f, 0.0f, 0.0f);
        scene.add_light(sun);
    }
};

// Whether (x, y) of the Gaussians' plane is away from the rims of their disks (Mahalanobis radius 3), where shadow rays
// and camera rays may keep or cut a Gaussian's last 1 % of alpha differently.
bool away_from_rims(double x, double y) {
    for (double cx : {double(kCentreX), -double(kCentreX)})
        if (std::abs(((x - cx) * (x - cx) + y * y) / (kSigma * kSigma) - 9.0) < 0.5) return false;
    return true;
}

// The shadow ray leaves the floor 1e-4 (relative to the coordinates) above it, which moves where it crosses the
// Gaussians' plane by as much along the sun: r differs from the closed form at the point by up to the alpha's slope
// times that (measured 2e-4).
constexpr double kShadowTolerance = 5e-4;

TEST(ShadowCatcher, TheGaussiansShadowIsItsAlphaAndItsPass) {
    CatcherScene s;
    const Film film = render(s.scene, s.camera, linear_settings(Compositing::Sorted, 2, true));
    int shadowed = 0, lit = 0;
    for_each_pixel([&](const Pixel& px) {
        if (!px.on_floor || !away_from_rims(px.x, px.y - kLayerZ)) return;
        const double t = 1.0 - px.alpha, r = 1.0 - layer_alpha(px.x, px.y - kLayerZ);
        const float* rgba = &film.rgba()[4 * px.index];
        const float* pass = &film[FilmChannel::ShadowCatcher][3 * px.index];
        EXPECT_NEAR(rgba[3], 1.0 - t * r, kShadowTolerance) << px.i << ", " << px.j;
        for (int c = 0; c < 3; ++c)
            EXPECT_NEAR(pass[c], 1.0 - t * (1.0 - r), kShadowTolerance) << px.i << ", " << px.j;
        if (r < 0.5) ++shadowed;
        if (r == 1.0) {
            ++lit;
            EXPECT_EQ(pass[0], 1.0f);
        }
    });
    EXPECT_GT(shadowed, 10);
    EXPECT_GT(lit, 50);
    // With the Shadow Catcher pass written, Combined leaves the catcher transparent: the Gaussians' coverage alone.
    RenderSettings with_pass = linear_settings(Compositing::Sorted, 2, true);
    with_pass.shadow_catcher_pass = true;
    const Film passed = render(s.scene, s.camera, with_pass);
    for_each_pixel([&](const Pixel& px) {
        if (!px.on_floor) return;
        EXPECT_NEAR(passed.rgba()[4 * px.index + 3], px.alpha, 2e-4) << px.i << ", " << px.j;
        EXPECT_EQ(passed[FilmChannel::ShadowCatcher][3 * px.index], film[FilmChannel::ShadowCatcher][3 * px.index]);
    });
}

TEST(ShadowCatcher, AnOpaqueBackgroundShowsTheShadowedWorld) {
    // Without a transparent background the catcher shows the world times T r, behind the Gaussians' own colour (the
    // same scene without world or catcher gives that colour).
    CatcherScene s;
    const Film film = render(s.scene, s.camera, linear_settings(Compositing::Sorted, 2, false));
    HoldoutScene reference(true, false);
    reference.scene.set_world(black_world());
    const Film gaussians = render(reference.scene, reference.camera, linear_settings(Compositing::Sorted, 2, true));
    for_each_pixel([&](const Pixel& px) {
        EXPECT_EQ(film.rgba()[4 * px.index + 3], 1.0f);
        if (!away_from_rims(px.x, px.y - kLayerZ)) return;
        // (Right of the floor, the world itself.)
        const double t = 1.0 - px.alpha, r = px.on_floor ? 1.0 - layer_alpha(px.x, px.y - kLayerZ) : 1.0;
        for (int c = 0; c < 3; ++c)
            EXPECT_NEAR(film.rgba()[4 * px.index + c] - gaussians.rgba()[4 * px.index + c], t * r * kWorld[c],
                        kShadowTolerance)
                << px.i << ", " << px.j;
    });
}

TEST(Holdout, AnUnknownCloudIsAnError) {
    Scene scene;
    EXPECT_THROW(scene.set_gaussian_holdout(0, true), InvalidArgument);
}
