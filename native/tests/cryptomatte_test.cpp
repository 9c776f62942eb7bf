// The Cryptomatte passes (raysplats/render/cryptomatte.h): names' ids (MurmurHash3_32 and the specification's
// uint32_to_float32), and the ranks of flat Gaussians of opacity a over a mesh floor and over the world against the
// closed form: the Gaussians' object with coverage a, the floor's with 1 - a (nothing for the world), sorted by
// coverage, in every compositing mode; camera-ray splatting's weights are those it composites with; and without the
// passes nothing is kept and every other channel is bit for bit the same.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>

#include "raysplats/errors.h"
#include "raysplats/render/cryptomatte.h"
#include "raysplats/render/renderer.h"
#include "half_floor_scene.h"
#include "render_test_util.h"

using namespace raysplats;
using namespace raysplats::testing;
using namespace raysplats::testing::half_floor;

namespace {

// The half-floor scene (half_floor_scene.h) with names: the Gaussians are object "Splats" (material "Haze", asset
// "Rig"), the floor object "Floor" (material "Ground", its own asset).
struct NamedScene {
    Scene scene;
    TestMesh floor = make_quad_z(-8.0f, 0.0f, -8.0f, 8.0f, 0.0f, 0);
    GaussianCloud cloud;
    Camera camera;

    explicit NamedScene(CameraType type = CameraType::Orthographic) {
        scene.add_material(Material{});
        scene.set_material_cryptomatte_name(0, "Ground");
        scene.add_mesh(floor.desc());
        scene.set_mesh_cryptomatte_names(0, "Floor", "Floor");
        const float q[4] = {1, 0, 0, 0}, s[3] = {kSigma, kSigma, 1e-4f}, rgb[3] = {0.8f, 0.3f, 0.2f};
        for (float x : {kCentreX, -kCentreX}) {
            const float pos[3] = {x, 0.0f, kLayerZ};
            add_gaussian(cloud, pos, q, s, kOpacity, rgb);
        }
        scene.add_gaussians(cloud);
        scene.set_gaussian_cryptomatte_names(0, "Splats", "Haze", "Rig");
        camera.type = type;
        camera.ortho_scale = kOrthoScale;
        camera.camera_to_world = Matrix4::translation(0.0f, 0.0f, kCameraHeight);
    }
};

RenderSettings crypto_settings(Compositing compositing, int samples, int levels = 6) {
    RenderSettings s = pixel_centre_settings(compositing, samples);
    s.cryptomatte_object = s.cryptomatte_material = s.cryptomatte_asset = true;
    s.cryptomatte_levels = levels;
    return s;
}

// The coverage pixel `p` of a Cryptomatte buffer gives `id` (0 when it holds none), checking that the ranks are
// sorted by coverage and that absent ranks are (0, 0).
double coverage_of(const Film& film, CryptomatteType type, std::size_t p, float id) {
    const int ranks = film.cryptomatte_ranks;
    const float* slots = film.cryptomatte[std::size_t(type)].data() + 2 * std::size_t(ranks) * p;
    double found = 0.0;
    for (int r = 0; r < ranks; ++r) {
        if (r > 0) EXPECT_LE(slots[2 * r + 1], slots[2 * r - 1]) << "ranks not sorted at pixel " << p;
        if (slots[2 * r] == 0.0f) EXPECT_EQ(slots[2 * r + 1], 0.0f) << p;
        if (slots[2 * r] == id) found += slots[2 * r + 1];
    }
    return found;
}

// Every pixel of an orthographic render against a and 1 - a; returns the pixels where both count (0.05 < a < 0.95).
int check_ranks(const Film& film, double tolerance) {
    const struct {
        CryptomatteType type;
        const char *gaussians, *floor;
    } kinds[] = {{CryptomatteType::Object, "Splats", "Floor"},
                 {CryptomatteType::Material, "Haze", "Ground"},
                 {CryptomatteType::Asset, "Rig", "Floor"}};
    int mixed = 0;
    for_each_pixel([&](const Pixel& px) {
        mixed += px.alpha > 0.05 && px.alpha < 0.95;
        for (const auto& kind : kinds) {
            EXPECT_NEAR(coverage_of(film, kind.type, px.index, cryptomatte_id_of(kind.gaussians)), px.alpha, tolerance)
                << px.i << ", " << px.j << " " << cryptomatte_pass_prefix(kind.type);
            EXPECT_NEAR(coverage_of(film, kind.type, px.index, cryptomatte_id_of(kind.floor)),
                        px.on_floor ? 1.0 - px.alpha : 0.0, tolerance)
                << px.i << ", " << px.j << " " << cryptomatte_pass_prefix(kind.type);
        }
    });
    return mixed;
}

}  // namespace

TEST(Cryptomatte, IdsAreMurmurHash3AsTheSpecificationConvertsThem) {
    // MurmurHash3_x86_32, seed 0 (the reference implementation's values).
    EXPECT_EQ(cryptomatte_hash(""), 0u);
    EXPECT_EQ(cryptomatte_hash("hello"), 0x248bfa47u);
    EXPECT_EQ(cryptomatte_hash("Hello, world!"), 0xc0363e43u);
    EXPECT_EQ(cryptomatte_hash("Cube"), 0xa8fce865u);
    // uint32_to_float32: the bits, the exponent clamped to [1, 254] (never 0, denormal, infinite or NaN).
    auto bits = [](float f) {
        std::uint32_t b;
        std::memcpy(&b, &f, sizeof b);
        return b;
    };
    EXPECT_EQ(bits(cryptomatte_id(0x248bfa47u)), 0x248bfa47u);
    EXPECT_EQ(bits(cryptomatte_id(0u)), 1u << 23);
    EXPECT_EQ(bits(cryptomatte_id(0x807fffffu)), 0x80ffffffu);
    EXPECT_EQ(bits(cryptomatte_id(0xffffffffu)), 0xff7fffffu);
    EXPECT_TRUE(std::isfinite(cryptomatte_id(0x7f800000u)));
}

TEST(Cryptomatte, LayoutFollowsBlendersLevels) {
    RenderSettings s;
    EXPECT_FALSE(cryptomatte_layout_of(s).on());
    s.cryptomatte_material = true;
    for (int levels : {1, 2, 3, 6, 16}) {
        s.cryptomatte_levels = levels;
        EXPECT_EQ(cryptomatte_layout_of(s).layers(), (levels + 1) / 2) << levels;
    }
    s.cryptomatte_levels = 17;
    EXPECT_THROW(s.validate(), InvalidArgument);
    s.cryptomatte_levels = 0;
    EXPECT_THROW(s.validate(), InvalidArgument);
    Scene scene;
    EXPECT_THROW(scene.set_gaussian_cryptomatte_names(0, "a", "b", "c"), InvalidArgument);
    EXPECT_THROW(scene.set_mesh_cryptomatte_names(0, "a", "b"), InvalidArgument);
    EXPECT_THROW(scene.set_material_cryptomatte_name(0, "a"), InvalidArgument);
}

TEST(Cryptomatte, SortedCompositingFollowsTheClosedForm) {
    for (int levels : {2, 6}) {
        NamedScene s;
        const Film film = render(s.scene, s.camera, crypto_settings(Compositing::Sorted, 2, levels));
        ASSERT_EQ(film.cryptomatte_ranks, levels);
        for (const FloatBuffer& buffer : film.cryptomatte)
            ASSERT_EQ(buffer.size(), 2 * std::size_t(levels) * film.pixel_count());
        EXPECT_GT(check_ranks(film, 2e-4), 20);
    }
}

TEST(Cryptomatte, StochasticCompositingConvergesToIt) {
    // One Gaussian accepted with probability a per sample: coverage's standard error is at most 0.5 / sqrt(4096) =
    // 0.008; 0.04 is five of them.
    NamedScene s;
    const Film film = render(s.scene, s.camera, crypto_settings(Compositing::Stochastic, 4096));
    EXPECT_GT(check_ranks(film, 0.04), 20);
}

TEST(Cryptomatte, CameraRaySplattingWeighsAsItComposites) {
    // The splats' footprints are not the traced model's, so a is not known in closed form; but over the world the
    // Gaussians' coverage is the pixel's alpha, and over the floor the two objects' coverages sum to 1.
    NamedScene s(CameraType::Perspective);
    RenderSettings st = crypto_settings(Compositing::Sorted, 1);
    st.camera_ray_splatting = true;
    const Film film = render(s.scene, s.camera, st);
    ASSERT_TRUE(film.stats.camera_ray_splatting) << film.stats.camera_rays_traced_reason;
    const float splats = cryptomatte_id_of("Splats"), floor = cryptomatte_id_of("Floor");
    int mixed = 0;
    for (std::size_t p = 0; p < film.pixel_count(); ++p) {
        const double a = coverage_of(film, CryptomatteType::Object, p, splats);
        const double b = coverage_of(film, CryptomatteType::Object, p, floor);
        if (b > 0.0) {
            EXPECT_NEAR(a + b, 1.0, 1e-4) << p;
        } else {
            EXPECT_NEAR(a, film.alpha()[p], 1e-4) << p;
        }
        mixed += a > 0.05 && a < 0.95;
    }
    EXPECT_GT(mixed, 10);
}

TEST(Cryptomatte, OffByDefaultAndChangesNothingElse) {
    EXPECT_FALSE(cryptomatte_layout_of(RenderSettings{}).on());
    for (Compositing compositing : {Compositing::Sorted, Compositing::Stochastic}) {
        NamedScene s;
        RenderSettings off_settings = pixel_centre_settings(compositing, 8);
        off_settings.jitter = true;
        RenderSettings on_settings = crypto_settings(compositing, 8);
        on_settings.jitter = true;
        const Film off = render(s.scene, s.camera, off_settings);
        const Film on = render(s.scene, s.camera, on_settings);
        EXPECT_EQ(off.cryptomatte_ranks, 0);
        for (const FloatBuffer& buffer : off.cryptomatte) EXPECT_TRUE(buffer.empty());
        EXPECT_FALSE(on.cryptomatte[0].empty());
        expect_channels_bit_identical(off, on, "Cryptomatte off and on");
    }
}

TEST(Cryptomatte, ARenderRegionLeavesTheRestWithoutIds) {
    NamedScene s;
    RenderSettings st = crypto_settings(Compositing::Sorted, 1);
    st.region_x = 4, st.region_y = 4, st.region_width = 8, st.region_height = 8;
    const Film film = render(s.scene, s.camera, st);
    for (std::size_t p = 0; p < film.pixel_count(); ++p) {
        const int x = int(p % kWidth), y = int(p / kWidth);
        const bool inside = x >= 4 && x < 12 && y >= 4 && y < 12;
        const float* slots = film.cryptomatte[0].data() + 2 * std::size_t(film.cryptomatte_ranks) * p;
        if (!inside) {
            EXPECT_EQ(slots[0], 0.0f) << x << ", " << y;
            EXPECT_EQ(slots[1], 0.0f) << x << ", " << y;
        }
    }
}
