// KHR_gaussian_splatting in glTF: the reader (gltf_splat_format.cpp) against the writer (gltf_writer.cpp) and against
// hand-edited documents. Expected values are computed here from the definitions (glTF -> RDF is F = diag(1, -1, -1);
// a node maps the covariance as L Σ L^T; SH colours are compared as functions of the viewing direction), not with the
// reader's own conversion code.
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <array>
#include <cmath>
#include <random>

#include "core/linear_algebra.h"
#include "io/splat_formats.h"
#include "io_test_util.h"
#include "raysplats/errors.h"
#include "raysplats/gltf_contents.h"
#include "raysplats/mesh_export.h"
#include "raysplats/spherical_harmonics.h"
#include "raysplats/splat_io.h"

namespace raysplats {
namespace {

using namespace testutil;
using namespace la;

// Row-major 3x3 covariance R diag(s)^2 R^T of Gaussian i.
std::array<double, 9> covariance(const GaussianCloud& c, std::size_t i) {
    const float* q = &c.rotations[4 * i];
    const std::array<double, 9> r = quaternion_to_rotation<double>(q[0], q[1], q[2], q[3]);
    std::array<double, 9> m{};
    for (int a = 0; a < 3; ++a)
        for (int b = 0; b < 3; ++b)
            for (int k = 0; k < 3; ++k) {
                const double s = c.scales[3 * i + std::size_t(k)];
                m[std::size_t(3 * a + b)] += r[std::size_t(3 * a + k)] * s * s * r[std::size_t(3 * b + k)];
            }
    return m;
}

// Every Gaussian of `read` is Gaussian i of `source` mapped by the linear map `a` (row-major, applied to positions
// as a p + t, to covariances as a Σ a^T, to view directions for SH as d -> a d / |a d| when a is a rotation).
void expect_mapped(const GaussianCloud& source, const GaussianCloud& read, const double a[9], const double t[3],
                   bool check_sh, double tolerance) {
    ASSERT_EQ(read.size(), source.size());
    ASSERT_EQ(read.sh_degree, source.sh_degree);
    std::mt19937 rng(7);
    std::normal_distribution<double> normal;
    for (std::size_t i = 0; i < source.size(); ++i) {
        const float* p = &source.positions[3 * i];
        for (int r = 0; r < 3; ++r) {
            const double expected = a[3 * r] * p[0] + a[3 * r + 1] * p[1] + a[3 * r + 2] * p[2] + t[r];
            ASSERT_NEAR(read.positions[3 * i + std::size_t(r)], expected, tolerance * (1 + std::fabs(expected))) << i;
        }
        const std::array<double, 9> cs = covariance(source, i), cr = covariance(read, i);
        double scale2 = 0;
        for (double v : cs) scale2 = std::max(scale2, std::fabs(v));
        for (int r = 0; r < 3; ++r)
            for (int c = 0; c < 3; ++c) {
                double expected = 0;
                for (int k = 0; k < 3; ++k)
                    for (int l = 0; l < 3; ++l) expected += a[3 * r + k] * cs[std::size_t(3 * k + l)] * a[3 * c + l];
                ASSERT_NEAR(cr[std::size_t(3 * r + c)], expected, tolerance * 10 * scale2 + 1e-30) << i;
            }
        ASSERT_FLOAT_EQ(read.opacities[i], source.opacities[i]);
        if (!check_sh) continue;
        // colour_read(d) = colour_source(a^T d) for unit d (a is a rotation here).
        for (int k = 0; k < 3; ++k) {
            double d[3] = {normal(rng), normal(rng), normal(rng)};
            const double n = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
            for (double& v : d) v /= n;
            const double e[3] = {a[0] * d[0] + a[3] * d[1] + a[6] * d[2], a[1] * d[0] + a[4] * d[1] + a[7] * d[2],
                                 a[2] * d[0] + a[5] * d[1] + a[8] * d[2]};
            const std::size_t coeffs = std::size_t(source.coeffs_per_channel());
            const auto got = evaluate_sh(read.sh_degree, &read.sh[3 * coeffs * i], d[0], d[1], d[2]);
            const auto want = evaluate_sh(source.sh_degree, &source.sh[3 * coeffs * i], e[0], e[1], e[2]);
            for (int c = 0; c < 3; ++c) ASSERT_NEAR(got[std::size_t(c)], want[std::size_t(c)], 1e-4) << i;
        }
    }
}

const double kF[9] = {1, 0, 0, 0, -1, 0, 0, 0, -1};
const double kZero[3] = {0, 0, 0};

std::string write_splats_gltf(const std::string& name, const GaussianCloud& cloud, const double node_matrix[16] = nullptr) {
    ExportScene scene;
    ExportGaussians gaussians;
    gaussians.name = "splats";
    gaussians.cloud = cloud;
    if (node_matrix) std::copy(node_matrix, node_matrix + 16, gaussians.node_matrix);
    scene.gaussians.push_back(std::move(gaussians));
    MeshWriteOptions options;
    options.gaussian_splatting_extension = true;
    const std::string path = tmp_path(name);
    write_mesh_file(path, scene, options);
    return path;
}

GaussianCloud real_scene(const char* file, std::size_t max_count) {
    ReadOptions options;
    options.max_count = max_count;
    return read_splat_file(data_path(file), options);
}

// The writer takes glTF coordinates; reading gives the core's RDF: F applied, every value within float precision.
TEST(GltfSplatReader, ExportedSplatsReadBackAsTheSameGaussiansInRdf) {
    const GaussianCloud source = real_scene("small_sh3_inria.ply", 0);  // SH degree 3, all 9080
    for (const char* name : {"roundtrip.glb", "roundtrip.gltf"}) {
        LoadReport report;
        const GaussianCloud read = read_splat_file(write_splats_gltf(name, source), {}, &report);
        expect_mapped(source, read, kF, kZero, true, 1e-6);
        EXPECT_TRUE(report.warnings.empty()) << report.warnings.front();
        // Scales and positions within float precision of the source (F only flips signs: exact).
        for (std::size_t k = 0; k < source.positions.size(); k += 3) {
            ASSERT_EQ(read.positions[k], source.positions[k]);
            ASSERT_EQ(read.positions[k + 1], -source.positions[k + 1]);
            ASSERT_EQ(read.positions[k + 2], -source.positions[k + 2]);
        }
    }
    const SplatFileSummary probe = probe_splat_file(tmp_path("roundtrip.glb"));
    EXPECT_EQ(probe.format, SplatFormat::Gltf);
    EXPECT_EQ(probe.count, source.size());
    EXPECT_EQ(probe.sh_degree, 3);
}

TEST(GltfSplatReader, FromMemoryEqualsFromFile) {
    const GaussianCloud source = real_scene("donut_sh0.ply", 5000);
    const std::string path = write_splats_gltf("memory.glb", source);
    const std::vector<std::uint8_t> bytes = read_bytes(path);
    const GaussianCloud a = read_gltf_splats(path), b = read_gltf_splats_from_memory(bytes.data(), bytes.size(), "memory.glb");
    EXPECT_EQ(a.positions, b.positions);
    EXPECT_EQ(a.rotations, b.rotations);
    EXPECT_EQ(a.sh, b.sh);
    // A .gltf whose buffer is a separate file cannot be read from memory: a clear error, not a file access.
    const std::string gltf = write_splats_gltf("memory.gltf", source);
    const std::vector<std::uint8_t> text = read_bytes(gltf);
    try {
        read_gltf_splats_from_memory(text.data(), text.size(), "memory.gltf");
        FAIL() << "read an external buffer from memory";
    } catch (const FileFormatError& e) {
        EXPECT_NE(std::string(e.what()).find("cannot be read from memory"), std::string::npos) << e.what();
    }
}

// Node transforms place the splats: a similarity keeps each Gaussian's shape (rotated, scaled) and rotates its SH; a
// non-uniform scale shears covariances (checked as L Σ L^T).
TEST(GltfSplatReader, NodeTransformsPlaceTheSplats) {
    const GaussianCloud source = real_scene("unicorn_sh3_reordered.ply", 3000);
    // 90° about y, times 2, then translated: row-major (x' = 2 z + 1, y' = 2 y - 2, z' = -2 x + 3).
    const double similarity[16] = {0, 0, 2, 1, 0, 2, 0, -2, -2, 0, 0, 3, 0, 0, 0, 1};
    GaussianCloud read = read_gltf_splats(write_splats_gltf("node_similarity.glb", source, similarity));
    // Expected: F (L p + t); SH checked with the rotation part only (scale does not change directions).
    double a[9], t[3], rot[9];
    for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c) a[3 * r + c] = kF[4 * r] * similarity[4 * r + c], rot[3 * r + c] = a[3 * r + c] / 2;
        t[r] = kF[4 * r] * similarity[4 * r + 3];
    }
    expect_mapped(source, read, a, t, false, 1e-6);
    GaussianCloud unscaled = read;
    for (std::size_t k = 0; k < unscaled.positions.size(); ++k) unscaled.positions[k] = 0.0f;
    for (float& s : unscaled.scales) s /= 2.0f;
    GaussianCloud src0 = source;
    for (float& p : src0.positions) p = 0.0f;
    expect_mapped(src0, unscaled, rot, kZero, true, 1e-5);

    const double stretch[16] = {3, 0, 0, 0, 0, 1, 0, 0, 0, 0, 0.5, 0, 0, 0, 0, 1};
    read = read_gltf_splats(write_splats_gltf("node_stretch.glb", source, stretch));
    const double a2[9] = {3, 0, 0, 0, -1, 0, 0, 0, -0.5};
    expect_mapped(source, read, a2, kZero, false, 1e-5);
}

// --- Documents edited by hand: each refused with a message that names the file and the problem.
nlohmann::json load_json(const std::string& path) { return nlohmann::json::parse(read_bytes(path)); }
std::string save_json(const std::string& name, const nlohmann::json& doc) {
    const std::string path = tmp_path(name);
    write_text(path, doc.dump());
    return path;
}

void expect_refused(const std::string& path, const std::vector<std::string>& problems) {
    try {
        read_splat_file(path);
        FAIL() << path << " was read";
    } catch (const FileFormatError& e) {
        const std::string what = e.what();
        EXPECT_NE(what.find(path), std::string::npos) << what;
        for (const std::string& p : problems) EXPECT_NE(what.find(p), std::string::npos) << "lacks '" << p << "': " << what;
    }
}

class GltfSplatErrors : public ::testing::Test {
protected:
    void SetUp() override {
        GaussianCloud c;
        c.resize(4, 1);
        for (std::size_t i = 0; i < 4; ++i) {
            c.positions[3 * i] = float(i);
            c.scales[3 * i] = c.scales[3 * i + 1] = c.scales[3 * i + 2] = 0.1f;
            c.opacities[i] = 0.5f;
        }
        // The buffer (.bin) is named after the document, so every edited copy reads the same one. One document per
        // test: ctest runs these tests in parallel processes.
        edit = std::string("edit_") + ::testing::UnitTest::GetInstance()->current_test_info()->name() + ".gltf";
        write_splats_gltf(edit, c);
        doc = load_json(tmp_path(edit));
    }
    std::string edit;
    nlohmann::json& primitive() { return doc["meshes"][0]["primitives"][0]; }
    int accessor(const std::string& semantic) { return primitive()["attributes"][semantic].get<int>(); }
    nlohmann::json doc;
};

TEST_F(GltfSplatErrors, AccessorCountBeyondItsBuffer) {
    doc["accessors"][accessor("KHR_gaussian_splatting:SCALE")]["count"] = 1u << 30;
    expect_refused(save_json(edit, doc), {"SCALE", "do not fit"});
}

TEST_F(GltfSplatErrors, AttributesOfDifferentCounts) {
    doc["accessors"][accessor("KHR_gaussian_splatting:OPACITY")]["count"] = 3;
    expect_refused(save_json(edit, doc), {"different counts"});
}

TEST_F(GltfSplatErrors, MissingRequiredAttribute) {
    primitive()["attributes"].erase("KHR_gaussian_splatting:OPACITY");
    expect_refused(save_json(edit, doc), {"KHR_gaussian_splatting:OPACITY is missing"});
}

TEST_F(GltfSplatErrors, PartialShDegree) {
    primitive()["attributes"].erase("KHR_gaussian_splatting:SH_DEGREE_1_COEF_2");
    expect_refused(save_json(edit, doc), {"degree 1 is partially defined"});
}

TEST_F(GltfSplatErrors, WrongModeAndComponentType) {
    primitive()["mode"] = 4;
    expect_refused(save_json(edit, doc), {"mode POINTS"});
    primitive()["mode"] = 0;
    doc["accessors"][accessor("KHR_gaussian_splatting:ROTATION")]["componentType"] = 5121;  // UNSIGNED_BYTE
    expect_refused(save_json(edit, doc), {"ROTATION", "not allowed"});
}

TEST_F(GltfSplatErrors, NodeCycleAndHeavyInstancing) {
    doc["nodes"][0]["children"] = {0};
    expect_refused(save_json(edit, doc), {"cycle"});
    doc["nodes"][0].erase("children");
    for (int k = 0; k < 40; ++k) doc["scenes"][0]["nodes"].push_back(0);
    expect_refused(save_json(edit, doc), {"more than 16 times"});
}

TEST_F(GltfSplatErrors, BufferThatIsNotARegularFile) {
    // A buffer file beside the document that is a link to /dev/zero: reading it would never end.
    const std::string link = tmp_path("zero.bin");
    std::filesystem::remove(link);
    std::filesystem::create_symlink("/dev/zero", link);
    doc["buffers"][0]["uri"] = "zero.bin";
    expect_refused(save_json(edit, doc), {"zero.bin", "not a regular file"});
}

TEST_F(GltfSplatErrors, GltfWithoutSplatsPointsToBlendersImporter) {
    ExportScene scene;
    const float positions[] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
    const std::uint32_t tri[] = {0, 1, 2};
    TriangleMeshView view;
    view.positions = positions, view.vertex_count = 3, view.triangles = tri, view.triangle_count = 1;
    const double identity[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
    scene.meshes.push_back(triangle_mesh(view, identity, {-1}, scene.materials, "Triangle"));
    const std::string path = tmp_path("no_splats.glb");
    write_mesh_file(path, scene);
    expect_refused(path, {"no KHR_gaussian_splatting primitives", "File > Import > glTF 2.0"});
    const GltfContents contents = gltf_contents(path);
    EXPECT_EQ(contents.splat_primitives, 0u);
    EXPECT_EQ(contents.other_primitives, 1u);
}

TEST(GltfSplatErrors2, NotGltfAtAll) {
    const std::string path = tmp_path("garbage.glb");
    write_text(path, "glTF\x02\x00\x00\x00garbage");
    expect_refused(path, {"not a valid glTF file"});
    const std::string text = tmp_path("garbage.gltf");
    write_text(text, "{\"asset\": ");
    expect_refused(text, {"not a valid glTF file"});
}

}  // namespace
}  // namespace raysplats
