// Golden films: a fixed set of scenes (a real splat scene with meshes, lights, glass and a mirror; every camera
// model, both compositing modes, both Gaussian modes, the interactive chunked scene) is rendered with fixed seeds
// and every film channel is hashed bit for bit; a refactoring that changes no behaviour must leave them unchanged.
// The cases named *_display use BlendSpace::Display (the default); the older cases set Linear.
//
// What the bits depend on, and so what the recorded hashes are keyed by:
// - Embree's instruction set: its triangle distance is T * rcp(den) with a Newton step, fused (FMA) under AVX2 and
//   not under SSE, so mesh distances differ in the last bits, and path-traced bounces carry that into the image.
//   The films are therefore recorded under one instruction set every x86-64 CPU in use has, SSE4.2 (the Scene's
//   Embree configuration "isa=sse4.2"), whatever the machine's best one. The films under the machine's own, AVX2 and
//   AVX-512 (where the CPU has them) are compared with that film within the bounds of
//   FilmsUnderOtherInstructionSetsAgree.
// - The CPU's approximate reciprocal (RCPPS, the start of that Newton step): its table is the vendor's, so the bits
//   differ between CPU families even under one instruction set. The key carries a hash of RCPPS over its whole
//   input range (rcp_family()). A family with no recorded films at all renders and checks everything else and skips
//   the comparison, saying which family and how to record it; a recorded family never skips (a hash it lacks is a
//   failure), and a golden file that is missing, unreadable or malformed is a failure naming it.
// - The group test's SIMD path (AVX2 + FMA or SSE; RAYSPLATS_SIMD=sse), the compiler and libm.
// To record (only when a change of the images is intended, and say so in the commit):
//   RAYSPLATS_UPDATE_GOLDEN=1 build/native/tests/raysplats_tests --gtest_filter=RenderGolden.*
//   RAYSPLATS_UPDATE_GOLDEN=1 RAYSPLATS_SIMD=sse build/native/tests/raysplats_tests --gtest_filter=RenderGolden.*
// RAYSPLATS_GOLDEN_PNG=DIR writes the films as PNGs to look at.
#include <gtest/gtest.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <xmmintrin.h>

#include "raysplats/errors.h"
#include "raysplats/render/renderer.h"
#include "raysplats/splat_io.h"
#include "render/gaussian_callbacks.h"
#include "render_test_util.h"

using namespace raysplats;
using namespace raysplats::testing;

namespace {

const std::string kGoldenFile = std::string(RAYSPLATS_SOURCE_DIR) + "/native/tests/golden/render_films.txt";

std::uint64_t fnv1a(const void* data, std::size_t bytes, std::uint64_t h = 1469598103934665603ull) {
    const auto* p = static_cast<const unsigned char*>(data);
    for (std::size_t i = 0; i < bytes; ++i) h = (h ^ p[i]) * 1099511628211ull;
    return h;
}

// One hash per film channel, in a fixed order.
std::map<std::string, std::uint64_t> film_hashes(const Film& f) {
    std::map<std::string, std::uint64_t> h;
    h["rgba"] = fnv1a(f.rgba().data(), f.rgba().size() * sizeof(float));
    h["depth"] = fnv1a(f.depth().data(), f.depth().size() * sizeof(float));
    h["normal"] = fnv1a(f.normal().data(), f.normal().size() * sizeof(float));
    h["alpha"] = fnv1a(f.alpha().data(), f.alpha().size() * sizeof(float));
    return h;
}

const char* const kChannels[] = {"alpha", "depth", "normal", "rgba"};

// The recorded hashes (key -> 16 hex digits), or why they cannot be had: a file that cannot be opened, holds no hash
// or has a line that is not "key hash" is an error naming it, never a reason to check nothing.
struct GoldenFile {
    std::map<std::string, std::string> hashes;
    std::string error;
};

GoldenFile read_golden(const std::string& file = kGoldenFile) {
    GoldenFile golden;
    std::ifstream in(file);
    if (!in) {
        golden.error = "cannot open the golden films file " + file + ": " + std::strerror(errno);
        return golden;
    }
    std::string line;
    for (int number = 1; std::getline(in, line); ++number) {
        if (line.empty()) continue;
        std::istringstream fields(line);
        std::string key, value, extra;
        if (!(fields >> key >> value) || (fields >> extra) || value.size() != 16 ||
            value.find_first_not_of("0123456789abcdef") != std::string::npos) {
            golden.error = file + ":" + std::to_string(number) + ": not a golden film line (key, 16 hex digits): " + line;
            return golden;
        }
        golden.hashes[key] = value;
    }
    if (in.bad()) golden.error = "cannot read the golden films file " + file;
    else if (golden.hashes.empty()) golden.error = "the golden films file " + file + " holds no hashes";
    return golden;
}

// Whether a CPU family's films under one group test path can be compared: every case's every channel recorded
// (Recorded), none of the family recorded under any path (FamilyNotRecorded: the only reason to skip), or the family
// recorded but some of these hashes missing (Incomplete: a failure). `missing` receives the keys not recorded.
enum class GoldenCoverage { Recorded, FamilyNotRecorded, Incomplete };

void write_golden(const std::map<std::string, std::string>& golden) {
    std::ofstream out(kGoldenFile, std::ios::trunc);
    for (const auto& [key, value] : golden) out << key << ' ' << value << '\n';
}

std::string hex(std::uint64_t v) {
    char buf[17];
    std::snprintf(buf, sizeof buf, "%016llx", static_cast<unsigned long long>(v));
    return buf;
}

// The Embree configuration the golden films are recorded under (see the header).
const char* const kGoldenIsa = "isa=sse4.2";

// Which approximate reciprocal this CPU has: RCPPS of every 12-bit mantissa prefix in [1, 2) (the instruction's
// result depends on no more), hashed. The first 8 hex digits name the family in the golden keys.
std::string rcp_family() {
    std::uint64_t h = 1469598103934665603ull;
    for (int i = 0; i < 4096; i += 4) {
        alignas(16) float in[4], out[4];
        for (int k = 0; k < 4; ++k) in[k] = 1.0f + float(i + k) / 4096.0f;
        _mm_store_ps(out, _mm_rcp_ps(_mm_load_ps(in)));
        h = fnv1a(out, sizeof out, h);
    }
    return hex(h).substr(0, 8);
}

// The real scene and the meshes around it. Everything the scene points to lives here.
struct GoldenScene {
    GaussianCloud cloud;
    std::vector<TestMesh> meshes;
    std::array<float, 3> center{}, size{};

    GoldenScene() {
        cloud = read_splat_file(std::string(RAYSPLATS_DATA_DIR) + "/small_sh3_inria.ply");
        // Median and 10-90 % extent per axis: the camera frames the bulk of the scene, not its floaters.
        for (int a = 0; a < 3; ++a) {
            std::vector<float> v(cloud.size());
            for (std::size_t i = 0; i < cloud.size(); ++i) v[i] = cloud.positions[3 * i + a];
            std::sort(v.begin(), v.end());
            center[a] = v[v.size() / 2];
            size[a] = v[v.size() * 9 / 10] - v[v.size() / 10];
        }
        const float r = std::max(size[0], std::max(size[1], size[2]));
        const float c[3] = {center[0], center[1], center[2]};
        // Ground (diffuse, textured by nothing), a glass box and a mirror beside the cloud, a small emitter.
        meshes.push_back(make_quad_z(c[0] - 2 * r, c[0] + 2 * r, c[1] - 2 * r, c[1] + 2 * r, c[2] - 0.6f * r, 0));
        const float glo[3] = {c[0] + 0.2f * r, c[1] - 0.3f * r, c[2] - 0.6f * r};
        const float ghi[3] = {c[0] + 0.5f * r, c[1] + 0.0f * r, c[2] - 0.2f * r};
        meshes.push_back(make_box(glo, ghi, 1));
        TestMesh mirror = make_quad_z(-0.5f * r, 0.5f * r, -0.5f * r, 0.5f * r, 0.0f, 2);
        mirror.object_to_world = Matrix4::translation(c[0] - 0.8f * r, c[1], c[2]) *
                                 Matrix4::rotation(1.2f, 0.0f, 1.0f, 0.0f);
        meshes.push_back(mirror);
        const float elo[3] = {c[0] - 0.1f * r, c[1] + 0.6f * r, c[2] - 0.6f * r};
        const float ehi[3] = {c[0] + 0.1f * r, c[1] + 0.8f * r, c[2] - 0.4f * r};
        meshes.push_back(make_box(elo, ehi, 3));
    }

    float radius() const { return std::max(size[0], std::max(size[1], size[2])); }

    void fill(Scene& scene) const {
        Material ground;
        ground.base_color = {0.6f, 0.55f, 0.5f};
        ground.roughness = 0.7f;
        scene.add_material(ground);
        Material glass;
        glass.transmission = 1.0f;
        glass.roughness = 0.0f;
        glass.ior = 1.5f;
        scene.add_material(glass);
        Material mirror;
        mirror.metallic = 1.0f;
        mirror.roughness = 0.1f;
        mirror.base_color = {0.9f, 0.9f, 0.9f};
        scene.add_material(mirror);
        scene.add_material(emissive(4.0f, 3.0f, 2.0f));
        for (const TestMesh& m : meshes) {
            MeshDesc d = m.desc();
            scene.add_mesh(d);
        }
        scene.add_gaussians(cloud);
        const float r = radius();
        Light sun;
        sun.type = LightType::Sun;
        sun.power = 3.0f;
        sun.sun_angle = 0.05f;
        sun.light_to_world = Matrix4::rotation(0.5f, 1.0f, 0.3f, 0.0f);
        scene.add_light(sun);
        Light area;
        area.type = LightType::AreaRectangle;
        area.power = 200.0f * r * r;
        area.size_x = 0.5f * r;
        area.size_y = 0.3f * r;
        area.light_to_world = Matrix4::look_at({center[0] + r, center[1] + r, center[2] + 1.5f * r},
                                               {center[0], center[1], center[2]}, {0, 1, 0});
        scene.add_light(area);
        Light spot;
        spot.type = LightType::Spot;
        spot.power = 300.0f * r * r;
        spot.light_to_world = Matrix4::look_at({center[0] - r, center[1] - r, center[2] + r},
                                               {center[0], center[1], center[2]}, {0, 0, 1});
        scene.add_light(spot);
        World w;
        w.color = {0.1f, 0.12f, 0.15f};
        scene.set_world(w);
    }
};

struct GoldenCase {
    const char* name;
    CameraType camera;
    Compositing compositing;
    GaussianMode mode;
    bool meshes_shadow_gaussians = false;
    bool transparent_background = false;
    int gather_buffer_size = 96;
    bool speculative_ends = true;
    std::uint32_t interactive_chunk = 0;  // 0: a final-render scene
    GaussianShading shading = GaussianShading::Baked;
    // The films recorded before BlendSpace existed are linear; set explicitly, as the default is now Display.
    BlendSpace blend_space = BlendSpace::Linear;
};

const GoldenCase kCases[] = {
    {"perspective_sorted_flat", CameraType::Perspective, Compositing::Sorted, GaussianMode::Flat},
    {"perspective_stochastic_flat", CameraType::Perspective, Compositing::Stochastic, GaussianMode::Flat},
    {"perspective_sorted_volumetric_shadowed_transparent", CameraType::Perspective, Compositing::Sorted,
     GaussianMode::Volumetric, true, true},
    {"ortho_sorted_flat_k4_no_speculation", CameraType::Orthographic, Compositing::Sorted, GaussianMode::Flat, false,
     false, 4, false},
    {"equirect_stochastic_volumetric", CameraType::Equirectangular, Compositing::Stochastic, GaussianMode::Volumetric},
    {"fisheye_sorted_flat_interactive", CameraType::FisheyeEquisolid, Compositing::Sorted, GaussianMode::Flat, false,
     false, 96, true, 1024},
    // Relightable splats, recorded when they were added.
    {"perspective_sorted_flat_lit", CameraType::Perspective, Compositing::Sorted, GaussianMode::Flat, false, false, 96,
     true, 0, GaussianShading::Lit},
    {"perspective_stochastic_volumetric_baked_shadowed", CameraType::Perspective, Compositing::Stochastic,
     GaussianMode::Volumetric, false, false, 96, true, 0, GaussianShading::BakedShadowed},
    // Display blend space: camera runs combined by the film, mirror and glass reflections of splats
    // combined per path, shadowed Gaussians darkened in linear light, a transparent background, stochastic runs.
    {"perspective_sorted_flat_display", CameraType::Perspective, Compositing::Sorted, GaussianMode::Flat, false, false,
     96, true, 0, GaussianShading::Baked, BlendSpace::Display},
    {"perspective_stochastic_flat_display", CameraType::Perspective, Compositing::Stochastic, GaussianMode::Flat,
     false, false, 96, true, 0, GaussianShading::Baked, BlendSpace::Display},
    {"perspective_sorted_volumetric_shadowed_transparent_display", CameraType::Perspective, Compositing::Sorted,
     GaussianMode::Volumetric, true, true, 96, true, 0, GaussianShading::Baked, BlendSpace::Display},
    {"equirect_stochastic_volumetric_display", CameraType::Equirectangular, Compositing::Stochastic,
     GaussianMode::Volumetric, false, false, 96, true, 0, GaussianShading::Baked, BlendSpace::Display},
};

GoldenCoverage golden_coverage(const std::map<std::string, std::string>& hashes, const std::string& family,
                               const std::string& group_path, std::vector<std::string>* missing) {
    bool family_recorded = false;
    for (const auto& [key, value] : hashes) family_recorded |= key.rfind(family + "/", 0) == 0;
    if (!family_recorded) return GoldenCoverage::FamilyNotRecorded;
    missing->clear();
    for (const GoldenCase& gc : kCases)
        for (const char* channel : kChannels) {
            const std::string key = family + "/" + group_path + "/" + gc.name + "/" + channel;
            if (!hashes.count(key)) missing->push_back(key);
        }
    return missing->empty() ? GoldenCoverage::Recorded : GoldenCoverage::Incomplete;
}

Film render_case(const GoldenScene& gs, const GoldenCase& gc, const std::string& embree_config, int width = 64,
                 int height = 48) {
    Scene scene(embree_config);
    if (gc.interactive_chunk) scene.set_interactive(true, gc.interactive_chunk);
    gs.fill(scene);
    const float r = gs.radius();
    const auto& c = gs.center;
    Camera cam;
    cam.type = gc.camera;
    cam.clip_start = 0.01f * r;
    cam.clip_end = 100.0f * r;
    if (gc.camera == CameraType::Equirectangular) {
        cam.camera_to_world = Matrix4::look_at({c[0], c[1], c[2] + 0.1f * r}, {c[0] + r, c[1], c[2]}, {0, 0, 1});
    } else {
        cam.camera_to_world = Matrix4::look_at({c[0] + 0.3f * r, c[1] - 1.6f * r, c[2] + 0.9f * r},
                                               {c[0], c[1], c[2]}, {0, 0, 1});
    }
    cam.focal_length_mm = 30.0f;
    cam.ortho_scale = 2.5f * r;
    RenderSettings s;
    s.width = width;
    s.height = height;
    s.samples = 3;
    s.max_bounces = 3;
    s.seed = 7;
    s.tile_size = 16;
    s.compositing = gc.compositing;
    s.blend_space = gc.blend_space;
    s.gaussian_mode = gc.mode;
    s.meshes_shadow_gaussians = gc.meshes_shadow_gaussians;
    s.transparent_background = gc.transparent_background;
    s.gather_buffer_size = gc.gather_buffer_size;
    s.speculative_ends = gc.speculative_ends;
    s.gaussian_shading = gc.shading;
    return render(scene, cam, s);
}

}  // namespace

TEST(RenderGolden, FilmsAreBitIdenticalToTheRecordedOnes) {
    const bool update = std::getenv("RAYSPLATS_UPDATE_GOLDEN") != nullptr;
    GoldenFile recorded = read_golden();
    if (!update) ASSERT_EQ(recorded.error, "") << "the golden films cannot be checked";
    std::map<std::string, std::string>& golden = recorded.hashes;
    const std::string family = std::string("sse4.2-rcp") + rcp_family();
    const std::string path = family + "/" + gaussian_group_test_path();
    std::vector<std::string> missing;
    const GoldenCoverage coverage = golden_coverage(golden, family, gaussian_group_test_path(), &missing);
    if (!update)
        ASSERT_NE(coverage, GoldenCoverage::Incomplete)
            << kGoldenFile << " has films of this CPU's family " << family << " but not " << missing.size()
            << " of its " << gaussian_group_test_path() << " group test's hashes, e.g. " << missing.front()
            << "; record them (see the header of " << __FILE__ << ")";
    const bool compare = !update && coverage == GoldenCoverage::Recorded;
    const GoldenScene scene;
    for (const GoldenCase& gc : kCases) {
        const Film film = render_case(scene, gc, kGoldenIsa);
        if (const char* dir = std::getenv("RAYSPLATS_GOLDEN_PNG")) film.write_png(std::string(dir) + "/" + gc.name + ".png");
        // The scene must show something of every kind, or the hashes would guard little.
        double sum = 0.0, covered = 0.0;
        for (std::size_t p = 0; p < film.pixel_count(); ++p) {
            sum += film.rgba()[4 * p] + film.rgba()[4 * p + 1] + film.rgba()[4 * p + 2];
            covered += film.alpha()[p];
        }
        EXPECT_GT(sum, 0.0) << gc.name;
        EXPECT_GT(covered, 0.1 * film.pixel_count()) << gc.name;
        EXPECT_GT(film.stats.gaussian_hits, 1000u) << gc.name;
        for (const auto& [channel, h] : film_hashes(film)) {
            const std::string key = path + "/" + gc.name + "/" + channel;
            if (update) {
                golden[key] = hex(h);
            } else if (compare) {
                EXPECT_EQ(golden.at(key), hex(h)) << key << " changed";
            }
        }
    }
    if (update) write_golden(golden);
    if (!update && coverage == GoldenCoverage::FamilyNotRecorded) {
        std::set<std::string> families;
        for (const auto& [key, value] : golden) families.insert(key.substr(0, key.find('/')));
        std::string recorded_families;
        for (const std::string& f : families) recorded_families += (recorded_families.empty() ? "" : ", ") + f;
        GTEST_SKIP() << "expected: this CPU's approximate-reciprocal family " << family << " has no golden films in "
                     << kGoldenFile << " (recorded: " << recorded_families << "); the films were rendered and checked "
                     << "for content, not compared. To record this family: RAYSPLATS_UPDATE_GOLDEN=1 "
                     << "build/native/tests/raysplats_tests --gtest_filter=RenderGolden.FilmsAreBitIdenticalToTheRecordedOnes"
                     << ", then the same with RAYSPLATS_SIMD=sse, and commit the file";
    }
}

// The golden file's own failures are failures: a missing, unreadable or malformed file names itself.
TEST(RenderGolden, AMissingOrMalformedGoldenFileIsAnErrorNamingIt) {
    const std::string missing = std::string(RAYSPLATS_TEST_TMP) + "/no_such_golden_films.txt";
    std::remove(missing.c_str());
    EXPECT_NE(read_golden(missing).error.find(missing), std::string::npos);
    EXPECT_NE(read_golden(RAYSPLATS_TEST_TMP).error.find(RAYSPLATS_TEST_TMP), std::string::npos) << "a folder";
    const std::string malformed = std::string(RAYSPLATS_TEST_TMP) + "/malformed_golden_films.txt";
    std::ofstream(malformed) << "sse4.2-rcp00000000/sse/case/rgba 0123456789abcdef\nnot-a-hash\n";
    EXPECT_NE(read_golden(malformed).error.find(malformed + ":2:"), std::string::npos) << read_golden(malformed).error;
    std::ofstream(malformed, std::ios::trunc) << "";
    EXPECT_NE(read_golden(malformed).error.find("holds no hashes"), std::string::npos);
    EXPECT_EQ(read_golden().error, "");
}

// The comparison skips only for a CPU family with no films at all: every recorded family has every hash under both
// group tests, a family with one group test recorded fails on the other rather than skipping, and on a CPU whose
// family is recorded the comparison runs.
TEST(RenderGolden, ARecordedFamilyIsComparedNeverSkipped) {
    const GoldenFile golden = read_golden();
    ASSERT_EQ(golden.error, "");
    std::set<std::string> families;
    for (const auto& [key, value] : golden.hashes) families.insert(key.substr(0, key.find('/')));
    ASSERT_FALSE(families.empty());
    std::vector<std::string> missing;
    for (const std::string& family : families)
        for (const char* group_path : {"avx2", "sse"})
            EXPECT_EQ(golden_coverage(golden.hashes, family, group_path, &missing), GoldenCoverage::Recorded)
                << family << "/" << group_path << " lacks " << missing.size() << " hashes";
    const std::string first = *families.begin();
    std::map<std::string, std::string> one_path;
    for (const auto& [key, value] : golden.hashes)
        if (key.rfind(first + "/avx2/", 0) == 0) one_path[key] = value;
    EXPECT_EQ(golden_coverage(one_path, first, "sse", &missing), GoldenCoverage::Incomplete);
    EXPECT_EQ(missing.size(), std::size(kCases) * std::size(kChannels));
    EXPECT_EQ(golden_coverage(one_path, "sse4.2-rcpffffffff", "sse", &missing), GoldenCoverage::FamilyNotRecorded);
    const std::string family = std::string("sse4.2-rcp") + rcp_family();
    if (families.count(family))
        EXPECT_EQ(golden_coverage(golden.hashes, family, gaussian_group_test_path(), &missing),
                  GoldenCoverage::Recorded);
}

// How far a film is from the reference film of the same case: per pixel the difference is the largest of |d rgba| and
// |d alpha|.
struct FilmAgreement {
    float largest = 0.0f;          // the largest difference of any pixel (NaN when a pixel is NaN)
    double mean = 0.0;             // mean |d rgba| over all channels
    std::size_t off = 0;           // pixels differing by more than kOffBy
    std::size_t any_bits = 0;      // pixels differing at all
    std::size_t depth_off = 0;     // pixels whose depth differs by more than 1 % of the scene's size
    std::size_t pixels = 0;
};
constexpr float kOffBy = 0.1f;

FilmAgreement agreement(const Film& film, const Film& reference, float scene_radius) {
    FilmAgreement a;
    a.pixels = film.pixel_count();
    double abs_sum = 0.0;
    for (std::size_t p = 0; p < a.pixels; ++p) {
        float d = std::abs(film.alpha()[p] - reference.alpha()[p]);
        for (int c = 0; c < 4; ++c) {
            const float dc = std::abs(film.rgba()[4 * p + c] - reference.rgba()[4 * p + c]);
            abs_sum += dc;
            d = std::isnan(d) || std::isnan(dc) ? NAN : std::max(d, dc);
        }
        a.largest = std::isnan(a.largest) || std::isnan(d) ? NAN : std::max(a.largest, d);
        a.off += !(d <= kOffBy);
        a.any_bits += !(d == 0.0f);
        const float da = film.depth()[p], db = reference.depth()[p];
        const bool both_far = !std::isfinite(da) && !std::isfinite(db);
        a.depth_off += !both_far && !(std::abs(da - db) <= 0.01f * scene_radius);
    }
    a.mean = abs_sum / double(4 * a.pixels);
    return a;
}

// The same scenes under the machine's own instruction set (or RAYSPLATS_EMBREE_CONFIG) and under each other one this
// CPU runs (AVX2, AVX-512) agree with the recorded instruction set's films. They cannot be equal: Embree's triangle
// distances differ in their last bits (see the header), and a bounce or a stochastic decision that a last bit tips goes
// another way. The films are 61 x 45, so that the 4 x 4 packets along the right and bottom edges have inactive lanes
// (the tiles' last columns and rows); every case mixes meshes and Gaussians. Bounds, each about 2.5 times the largest
// value measured over all cases and instruction sets (docs/benchmarks.md, "Cross-ISA agreement"): the pixels off by
// more than kOffBy (fewer than the 16 of one packet), the mean difference, the largest difference (radiance is not
// bounded by 1: one path sees the emitter and the other does not; the bound catches NaN and runaway values). Depth,
// the camera rays' first hit, was never measured off by 1 % of the scene's size: 3 pixels, fewer than one edge
// packet's column, allow for a ray grazing an edge.
constexpr std::size_t kMaxPixelsOff = 12;
constexpr double kMaxMeanDifference = 0.02;
constexpr float kMaxDifference = 70.0f;
constexpr std::size_t kMaxPixelsOffInDepth = 3;

::testing::AssertionResult agrees(const FilmAgreement& a) {
    if (!(a.largest <= kMaxDifference) || a.off > kMaxPixelsOff || !(a.mean <= kMaxMeanDifference) ||
        a.depth_off > kMaxPixelsOffInDepth)
        return ::testing::AssertionFailure()
               << "largest |d| " << a.largest << " (bound " << kMaxDifference << "), pixels off by > " << kOffBy
               << ": " << a.off << " (bound " << kMaxPixelsOff << "), mean |d rgba| " << a.mean << " (bound "
               << kMaxMeanDifference << "), pixels off in depth " << a.depth_off << " (bound " << kMaxPixelsOffInDepth
               << ") of " << a.pixels;
    return ::testing::AssertionSuccess();
}

TEST(RenderGolden, FilmsUnderOtherInstructionSetsAgree) {
    const GoldenScene scene;
    constexpr int kWidth = 61, kHeight = 45;
    std::vector<std::string> configs;
    for (const std::string& c : {default_embree_config(), std::string("isa=avx2"), std::string("isa=avx512")}) {
        if (c == kGoldenIsa || std::find(configs.begin(), configs.end(), c) != configs.end()) continue;
        try {
            Scene probe(c);
            configs.push_back(c);
        } catch (const Error&) {
            std::printf("(this CPU cannot run Embree with %s)\n", c.c_str());
        }
    }
    if (configs.empty()) GTEST_SKIP() << "no instruction set besides " << kGoldenIsa << " on this CPU";
    FilmAgreement worst;
    for (const GoldenCase& gc : kCases) {
        const Film reference = render_case(scene, gc, kGoldenIsa, kWidth, kHeight);
        ASSERT_EQ(reference.pixel_count(), std::size_t(kWidth * kHeight));
        for (const std::string& config : configs) {
            const Film film = render_case(scene, gc, config, kWidth, kHeight);
            const FilmAgreement a = agreement(film, reference, scene.radius());
            std::printf("%-58s %-10s largest |d| %.3g, off by > %.2g: %zu, mean |d| %.2e, any bit: %zu, "
                        "depth: %zu (of %zu)\n", gc.name, config.empty() ? "(default)" : config.c_str(), a.largest,
                        kOffBy, a.off, a.mean, a.any_bits, a.depth_off, a.pixels);
            EXPECT_TRUE(agrees(a)) << gc.name << " under " << config;
            worst.largest = std::max(worst.largest, a.largest);
            worst.mean = std::max(worst.mean, a.mean);
            worst.off = std::max(worst.off, a.off);
            worst.depth_off = std::max(worst.depth_off, a.depth_off);
        }
        // The bounds catch a packet gone wrong: the reference with one 4 x 4 packet of its covered middle blanked
        // (as a lost packet of rays leaves it) does not agree with itself.
        if (gc.camera == CameraType::Perspective && !gc.transparent_background) {
            Film broken = reference;
            const int bx = 4 * (kWidth / 8), by = 4 * (kHeight / 8);
            for (int y = by; y < by + 4; ++y)
                for (int x = bx; x < bx + 4; ++x) {
                    const std::size_t p = std::size_t(y) * kWidth + x;
                    for (int c = 0; c < 4; ++c) broken.rgba()[4 * p + c] = 0.0f;
                    broken.alpha()[p] = 0.0f;
                }
            EXPECT_FALSE(agrees(agreement(broken, reference, scene.radius()))) << gc.name << ": a blanked packet";
        }
    }
    std::printf("worst over all films: largest |d| %.3g, off by > %.2g: %zu, mean |d| %.2e, depth: %zu\n",
                worst.largest, kOffBy, worst.off, worst.mean, worst.depth_off);
}
