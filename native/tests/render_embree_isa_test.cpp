// The renderer does not depend on the instruction set Embree runs. Embree picks its kernels by the CPU: with
// AVX-512 a 16-ray packet reaches the Gaussians' callbacks as it was sent; with AVX2 or SSE its ray stream filter
// splits it into packets of 8 or 4 rays and renumbers the lanes, and counts a ray as active by its segment, not by
// the valid mask. These tests force the instruction sets users' CPUs have (the Scene's Embree configuration) and
// require Gaussian-only films to be the same bit for bit under each: every Gaussian test is the project's own code,
// so only a callback that mistakes one ray for another, or traces a ray it should not, can change them. (Films with
// meshes differ in the last bits of Embree's triangle distances between instruction sets: render_golden_test.cpp
// compares those with a tolerance.)
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cstdio>
#include <string>
#include <vector>

#include "raysplats/errors.h"
#include "raysplats/render/renderer.h"
#include "raysplats/splat_io.h"
#include "render_test_util.h"

using namespace raysplats;
using namespace raysplats::testing;

namespace {

// Whether this CPU (and Debian's Embree build) can run Embree with `config`.
bool embree_config_available(const std::string& config) {
    try {
        Scene probe(config);
        return true;
    } catch (const Error&) {
        return false;
    }
}

// The configurations to compare: Embree's own choice (or RAYSPLATS_EMBREE_CONFIG), and the instruction sets of
// users' CPUs that this one can run.
std::vector<std::string> isa_configs() {
    std::vector<std::string> configs = {default_embree_config()};
    for (const char* c : {"isa=sse4.2", "isa=avx2"})
        if (embree_config_available(c)) configs.push_back(c);
    return configs;
}

struct RealScene {
    GaussianCloud cloud = read_splat_file(std::string(RAYSPLATS_DATA_DIR) + "/small_sh3_inria.ply");
    std::array<float, 3> center{};
    float radius = 1.0f;
    RealScene() {
        // Median and 10-90 % extent per axis: the camera frames the bulk of the scene, not its floaters.
        float extent = 0.0f;
        for (int a = 0; a < 3; ++a) {
            std::vector<float> v(cloud.size());
            for (std::size_t i = 0; i < cloud.size(); ++i) v[i] = cloud.positions[3 * i + a];
            std::sort(v.begin(), v.end());
            center[a] = v[v.size() / 2];
            extent = std::max(extent, v[v.size() * 9 / 10] - v[v.size() / 10]);
        }
        radius = extent;
    }
    Camera camera(CameraType type) const {
        Camera cam;
        cam.type = type;
        cam.clip_start = 0.01f * radius;
        cam.clip_end = 100.0f * radius;
        cam.focal_length_mm = 30.0f;
        cam.ortho_scale = 1.0f * radius;
        cam.camera_to_world = Matrix4::look_at({center[0] + 0.2f * radius, center[1] - 0.8f * radius, center[2] + 0.4f * radius},
                                               {center[0], center[1], center[2]}, {0, 0, 1});
        return cam;
    }
};

Film render_with(const std::string& config, const RealScene& rs, CameraType type, const RenderSettings& s,
                 bool depth_of_field = false) {
    Scene scene(config);
    scene.add_gaussians(rs.cloud);
    Camera camera = rs.camera(type);
    if (depth_of_field) {
        // Focused in front of the scene's centre, at a wide aperture: the lens samples change most rays.
        camera.use_dof = true;
        camera.focus_distance = 0.5f * rs.radius;
        camera.aperture_fstop = type == CameraType::Orthographic ? 20.0f / rs.radius : 30e-3f / (0.1f * rs.radius);
    }
    return render(scene, camera, s);
}

}  // namespace

// The configurations the other tests use are real: a forced AVX2 or SSE4.2 device has no native 16-wide packets, so
// the render tests run under them (ctest's core.render_tests_isa_*) go through Embree's splitting on every machine,
// AVX-512 ones included. An unusable configuration is a clear error naming it.
TEST(RenderEmbreeIsa, ForcedInstructionSetsSplitPackets) {
    for (const char* config : {"isa=sse4.2", "isa=avx2"}) {
        if (!embree_config_available(config)) {
            std::printf("(this CPU cannot run Embree with %s)\n", config);
            continue;
        }
        const EmbreeDeviceInfo info = Scene(config).embree_device();
        EXPECT_EQ(info.config, config);
        EXPECT_FALSE(info.native_ray16) << config;
        EXPECT_TRUE(info.native_ray4) << config;
    }
    EXPECT_FALSE(Scene("isa=sse4.2").embree_device().native_ray8);
    // A configuration Embree refuses, or an instruction set it does not know (which it would take silently, running
    // its SSE2 kernels), is an Error that names it.
    for (const char* bad : {"threads=not_a_number", "isa=avx3", "verbose=0,isa=sse42"}) {
        try {
            Scene scene(bad);
            ADD_FAILURE() << "Scene(\"" << bad << "\") was accepted";
        } catch (const Error& e) {
            EXPECT_NE(std::string(e.what()).find(bad), std::string::npos) << e.what();
        }
    }
    EXPECT_TRUE(embree_config_available(""));
}

// Gaussian-only films, bit for bit the same under every instruction set: sorted (flat and volumetric, a buffer
// that overflows so that packets re-trace some of their rays while others are finished), stochastic, and the
// camera models whose rays are traced as packets, with and without depth of field. The image is 61 x 45, so that the right and bottom packets have
// inactive lanes.
TEST(RenderEmbreeIsa, GaussianFilmsAreTheSameUnderEveryInstructionSet) {
    const RealScene rs;
    const std::vector<std::string> configs = isa_configs();
    ASSERT_GE(configs.size(), 2u) << "this CPU cannot run Embree with isa=sse4.2";
    struct Case {
        const char* name;
        CameraType camera;
        Compositing compositing;
        GaussianMode mode;
        int k;
        double min_coverage;  // of pixels with alpha > 0.5 (the fisheye sees the scene in a small part of its disc)
        bool depth_of_field = false;  // a thin lens: rays of a packet leave the lens at different points
    };
    const Case cases[] = {
        {"perspective sorted flat", CameraType::Perspective, Compositing::Sorted, GaussianMode::Flat, 96, 0.5},
        {"perspective sorted volumetric k=4", CameraType::Perspective, Compositing::Sorted, GaussianMode::Volumetric, 4, 0.5},
        {"perspective stochastic flat", CameraType::Perspective, Compositing::Stochastic, GaussianMode::Flat, 96, 0.5},
        {"orthographic sorted flat k=4", CameraType::Orthographic, Compositing::Sorted, GaussianMode::Flat, 4, 0.5},
        {"fisheye stochastic volumetric", CameraType::FisheyeEquisolid, Compositing::Stochastic,
         GaussianMode::Volumetric, 96, 0.05},
        {"perspective sorted flat depth of field", CameraType::Perspective, Compositing::Sorted, GaussianMode::Flat,
         96, 0.5, true},
        {"orthographic stochastic volumetric k=4 depth of field", CameraType::Orthographic, Compositing::Stochastic,
         GaussianMode::Volumetric, 4, 0.5, true},
    };
    for (const Case& c : cases) {
        RenderSettings s;
        s.width = 61;
        s.height = 45;
        s.samples = 2;
        s.seed = 11;
        s.tile_size = 16;
        s.max_bounces = 0;
        s.compositing = c.compositing;
        s.gaussian_mode = c.mode;
        s.gather_buffer_size = c.k;
        s.transparent_background = true;
        const Film reference = render_with(configs[1], rs, c.camera, s, c.depth_of_field);  // isa=sse4.2
        // The scene must show Gaussians in most pixels, or equal films would prove little.
        std::size_t covered = 0;
        for (std::size_t p = 0; p < reference.pixel_count(); ++p) covered += reference.alpha()[p] > 0.5f;
        EXPECT_GT(double(covered), c.min_coverage * double(reference.pixel_count())) << c.name;
        for (const std::string& config : configs) {
            if (config == configs[1]) continue;
            const Film film = render_with(config, rs, c.camera, s, c.depth_of_field);
            std::size_t differing = 0;
            for (std::size_t i = 0; i < film.rgba().size(); ++i) differing += film.rgba()[i] != reference.rgba()[i];
            EXPECT_EQ(differing, 0u) << c.name << ": rgba values differ between " << config << " and " << configs[1];
            EXPECT_TRUE(film.channels == reference.channels) << c.name << ": films differ between \"" << config
                                                              << "\" and " << configs[1];
            EXPECT_EQ(film.stats.gaussian_hits, reference.stats.gaussian_hits) << c.name << " " << config;
        }
    }
}
