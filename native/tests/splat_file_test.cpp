// Format dispatch, atomic writes and write errors.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/resource.h>

#include <filesystem>

#include "io/splat_formats.h"
#include "io_test_util.h"
#include "raysplats/errors.h"
#include "raysplats/memory_budget.h"
#include "raysplats/splat_io.h"

namespace raysplats {
namespace {

using namespace testutil;
namespace fs = std::filesystem;

TEST(SplatFile, FormatFromExtension) {
    EXPECT_EQ(splat_format_from_extension("a/b.PLY"), SplatFormat::Ply);
    EXPECT_EQ(splat_format_from_extension("x.Splat"), SplatFormat::Splat);
    EXPECT_EQ(splat_format_from_extension("x.spz"), SplatFormat::Spz);
    EXPECT_STREQ(splat_format_name(SplatFormat::Spz), "spz");
    expect_format_error([] { splat_format_from_extension("dir.ply/scene.obj"); }, "scene.obj", {"'.obj'"});
    expect_format_error([] { splat_format_from_extension("noext"); }, "noext", {"unknown splat format"});
}

TEST(SplatFile, LongestEndingWins) {
    // The one rule for file names (the add-on asks it through the bindings): longest ending, any case.
    SplatFormatMatch m = match_splat_format("/scans/Scene.Compressed.PLY");
    ASSERT_NE(m.format, nullptr);
    EXPECT_STREQ(m.format->name, "compressed_ply");
    EXPECT_EQ(m.ending_length, std::string(".compressed.ply").size());
    m = match_splat_format("/scans/compressed.ply");  // no dot before "compressed": an INRIA PLY
    ASSERT_NE(m.format, nullptr);
    EXPECT_STREQ(m.format->name, "ply");
    EXPECT_EQ(m.ending_length, 4u);
    m = match_splat_format("/scans/unicorn/META.JSON");
    ASSERT_NE(m.format, nullptr);
    EXPECT_STREQ(m.format->name, "sog");
    EXPECT_EQ(m.ending_length, 9u);
    EXPECT_EQ(match_splat_format("/scans/unicorn/meta.json", true).format, nullptr);  // read only
    EXPECT_EQ(match_splat_format("/scans/a.glb", true).format, nullptr);
    EXPECT_STREQ(match_splat_format("/scans/a.spz", true).format->name, "spz");
    EXPECT_EQ(match_splat_format("/scans/a.obj").format, nullptr);
    EXPECT_EQ(match_splat_format("").format, nullptr);
    EXPECT_EQ(splat_endings_text(true), ".ply, .splat, .spz, .compressed.ply");
    EXPECT_EQ(splat_endings_text(false, "/"), ".ply/.splat/.spz/.glb/.gltf/.compressed.ply/.sog/meta.json");
}

TEST(SplatFile, DispatchByContentNotName) {
    // A PLY saved under a .splat name is still read as PLY (content first); .spz content under .dat too.
    const std::string p1 = tmp_path("really_ply.splat");
    write_bytes(p1, read_bytes(data_path("small_sh3_inria.ply")));
    const GaussianCloud a = read_splat_file(p1);
    EXPECT_EQ(a.size(), 9080u);
    EXPECT_EQ(a.sh_degree, 3);
    const std::string p2 = tmp_path("really_spz.dat");
    write_bytes(p2, read_bytes(data_path("biker_v4.spz")));
    EXPECT_EQ(read_splat_file(p2).size(), 152746u);
}

// The header probe gives what the reader then reads (no splat of these files is dropped), without decoding.
TEST(SplatFile, ProbeReadsTheHeaderOnly) {
    const struct {
        const char* name;
        SplatFormat format;
        std::uint64_t count;
        int degree;
    } files[] = {{"small_sh3_inria.ply", SplatFormat::Ply, 9080, 3}, {"donut_sh0.ply", SplatFormat::Ply, 45624, 0},
                 {"small.splat", SplatFormat::Splat, 22764, 0}, {"biker_v4.spz", SplatFormat::Spz, 152746, 0}};
    for (const auto& f : files) {
        SCOPED_TRACE(f.name);
        const SplatFileSummary s = probe_splat_file(data_path(f.name));
        EXPECT_EQ(s.format, f.format);
        EXPECT_EQ(s.count, f.count);
        EXPECT_EQ(s.sh_degree, f.degree);
        EXPECT_EQ(read_splat_file(data_path(f.name)).size(), f.count);
    }
    // An SPZ of SH degree 1 written here.
    GaussianCloud c;
    c.resize(5, 1);
    const std::string spz = tmp_path("probe.spz");
    write_spz(spz, c);
    EXPECT_EQ(probe_splat_file(spz).sh_degree, 1);
    const std::string mesh = tmp_path("probe_mesh.ply");
    write_text(mesh, "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n"
                     "end_header\n0 0 0\n");
    expect_format_error([&] { probe_splat_file(mesh); }, "probe_mesh.ply", {"point cloud PLY"});
}

// The import estimate grows with what is imported, and the machine reports some available memory.
TEST(SplatFile, ImportMemoryEstimate) {
    EXPECT_EQ(import_memory_bytes(0, 3, 8), 0u);
    EXPECT_EQ(import_memory_bytes(2000, 0, 8), 2 * import_memory_bytes(1000, 0, 8));
    EXPECT_GT(import_memory_bytes(1000, 3, 8), import_memory_bytes(1000, 0, 8));
    EXPECT_GT(import_memory_bytes(1000, 0, 16), import_memory_bytes(1000, 0, 8));
    // 1.5 M octagons of degree 0: gigabytes (cloud 56 B, polygons ~430 B, mesh ~480 B twice, per Gaussian).
    EXPECT_GT(import_memory_bytes(1500000, 0, 8), 1500000000u);
    EXPECT_LT(import_memory_bytes(1500000, 0, 8), 4000000000u);
    EXPECT_GT(available_memory_bytes(), 0u);
    // The compact form (one point per Gaussian): 13.6 M Gaussians of degree 0 in a few GB, several times less than
    // polygons; SH adds 12 B per coefficient to each copy.
    EXPECT_EQ(compact_import_memory_bytes(2000, 0), 2 * compact_import_memory_bytes(1000, 0));
    EXPECT_LT(compact_import_memory_bytes(13600000, 0), 4000000000u);
    EXPECT_LT(5 * compact_import_memory_bytes(1000, 0), import_memory_bytes(1000, 0, 8));
    EXPECT_GT(compact_import_memory_bytes(1000, 3), compact_import_memory_bytes(1000, 0) + 1000 * 15 * 12 * 2);
}

TEST(SplatFileErrors, UnknownFormat) {
    const std::string path = tmp_path("mystery.xyz");
    write_text(path, "\x01\x02\x03 definitely not a splat file");
    expect_format_error([&] { read_splat_file(path); }, "mystery.xyz", {"unknown splat format", "'.xyz'"});
    const std::string path2 = tmp_path("mystery.spz");
    write_text(path2, "\x01\x02\x03 definitely not a splat file");
    expect_format_error([&] { read_splat_file(path2); }, "mystery.spz", {"not a spz file"});
}

TEST(SplatFileErrors, EmptyAndMissingFiles) {
    const std::string path = tmp_path("empty_any.ply");
    write_bytes(path, {});
    expect_format_error([&] { read_splat_file(path); }, "empty_any.ply", {"empty"});
    expect_format_error([&] { read_splat_file(tmp_path("does_not_exist.ply")); }, "does_not_exist.ply", {"cannot open"});
    expect_format_error([&] { read_splat_file(RAYSPLATS_TEST_TMP); }, RAYSPLATS_TEST_TMP, {"directory"});
}

GaussianCloud small_cloud() {
    GaussianCloud c;
    c.resize(4, 1);
    for (std::size_t i = 0; i < c.positions.size(); ++i) c.positions[i] = float(i) * 0.5f;
    for (std::size_t i = 0; i < c.scales.size(); ++i) c.scales[i] = 0.01f * float(i + 1);
    for (std::size_t i = 0; i < c.size(); ++i) c.opacities[i] = 0.2f * float(i + 1);
    for (std::size_t i = 0; i < c.sh.size(); ++i) c.sh[i] = 0.01f * float(i % 7);
    return c;
}

std::vector<std::string> leftover_temp_files(const std::string& dir, const std::string& stem) {
    std::vector<std::string> out;
    for (const auto& e : fs::directory_iterator(dir)) {
        const std::string name = e.path().filename().string();
        if (name.rfind(stem + ".tmp", 0) == 0) out.push_back(name);
    }
    return out;
}

TEST(SplatFile, WriteEachFormatByExtension) {
    const GaussianCloud c = small_cloud();
    for (const char* name : {"by_ext.ply", "by_ext.splat", "by_ext.spz"}) {
        const std::string path = tmp_path(name);
        fs::remove(path);
        write_splat_file(path, c);
        const GaussianCloud b = read_splat_file(path);
        ASSERT_EQ(b.size(), 4u) << name;
        EXPECT_NEAR(b.positions[5], 2.5f, 1e-3) << name;
        EXPECT_TRUE(leftover_temp_files(RAYSPLATS_TEST_TMP, name).empty()) << name;
    }
    expect_format_error([&] { write_splat_file(tmp_path("x.obj"), c); }, "x.obj", {"unknown splat format"});
}

TEST(SplatFormatRegistry, EveryRowCarriesItsFunctions) {
    const GaussianCloud c = small_cloud();
    ASSERT_EQ(io::splat_format_table().size(), splat_formats().size());
    for (std::size_t i = 0; i < splat_formats().size(); ++i) {
        const io::SplatFormatRow& row = io::splat_format_table()[i];
        const SplatFormatInfo& info = splat_formats()[i];
        SCOPED_TRACE(info.name);
        EXPECT_EQ(row.info.format, info.format);
        EXPECT_EQ(&io::splat_format_row(info.format), &row);
        // Only compressed PLY has no detector of its own (the PLY row finds it); every row reads and probes.
        EXPECT_EQ(row.detect == nullptr, info.format == SplatFormat::CompressedPly);
        EXPECT_NE(row.read, nullptr);
        EXPECT_NE(row.probe, nullptr);
        EXPECT_EQ(info.writable, row.write != nullptr);
        const std::string path = tmp_path(std::string("registry_") + info.name + info.extensions[0]);
        fs::remove(path);
        if (!row.write) {
            // A read-only format is refused by name, with its own reason, and nothing is written.
            ASSERT_NE(row.read_only_reason, nullptr);
            expect_format_error([&] { write_splat_file(path, c); }, path, {row.read_only_reason});
            EXPECT_FALSE(fs::exists(path));
            continue;
        }
        // A written file reads back, and the probe and the dispatch name the format of the row that wrote it.
        write_splat_file(path, c);
        EXPECT_EQ(read_splat_file(path).size(), c.size());
        EXPECT_EQ(probe_splat_file(path).format, info.format);
        EXPECT_EQ(probe_splat_file(path).count, c.size());
    }
}

TEST(SplatFileErrors, UnwritablePathNamesThePath) {
    const GaussianCloud c = small_cloud();
    const std::string bad = tmp_path("no_such_folder/sub/out.ply");
    expect_format_error([&] { write_ply(bad, c); }, bad, {"cannot write"});
    expect_format_error([&] { write_spz(tmp_path("no_such_folder/out.spz"), c); }, "out.spz", {"cannot write"});
    // A directory in the way of the target.
    expect_format_error([&] { write_dot_splat(RAYSPLATS_TEST_TMP, c); }, RAYSPLATS_TEST_TMP, {"directory"});
}

TEST(SplatFileErrors, InconsistentCloudIsRejectedBeforeTouchingTheFile) {
    const std::string path = tmp_path("keep_me.ply");
    write_ply(path, small_cloud());
    const auto before = read_bytes(path);
    GaussianCloud bad = small_cloud();
    bad.sh.pop_back();
    EXPECT_THROW(write_ply(path, bad), InvalidArgument);
    EXPECT_EQ(read_bytes(path), before);
}

// A write that fails midway (the file size limit is hit, so write() returns EFBIG) must leave the existing
// target as it was and remove its temporary file.
TEST(SplatFileErrors, FailedWriteLeavesExistingFileIntact) {
    const std::string path = tmp_path("intact.ply");
    write_ply(path, small_cloud());
    const auto before = read_bytes(path);
    ASSERT_GT(before.size(), 0u);
    GaussianCloud big;
    big.resize(200000, 3);  // ~50 MB of PLY, far over the limit set below
    rlimit old{};
    ASSERT_EQ(getrlimit(RLIMIT_FSIZE, &old), 0);
    auto old_handler = signal(SIGXFSZ, SIG_IGN);
    rlimit lim = old;
    lim.rlim_cur = 1 << 20;
    ASSERT_EQ(setrlimit(RLIMIT_FSIZE, &lim), 0);
    for (auto writer : {&write_ply, &write_dot_splat}) {
        try {
            writer(path, big);
            ADD_FAILURE() << "write should fail over the file size limit";
        } catch (const FileFormatError& e) {
            EXPECT_NE(std::string(e.what()).find("intact.ply"), std::string::npos) << e.what();
            EXPECT_NE(std::string(e.what()).find("cannot write"), std::string::npos) << e.what();
        }
    }
    setrlimit(RLIMIT_FSIZE, &old);
    signal(SIGXFSZ, old_handler);
    EXPECT_EQ(read_bytes(path), before);
    EXPECT_TRUE(leftover_temp_files(RAYSPLATS_TEST_TMP, "intact.ply").empty());
    const GaussianCloud back = read_ply(path);
    EXPECT_EQ(back.size(), 4u);
}

}  // namespace
}  // namespace raysplats
