// The byte readers (native/src/io/io_common.h: read_splat_bytes, probe_splat_bytes, detect_splat_format): the same
// code as the path readers, so the same clouds and the same errors, byte for byte. The fuzz targets (native/fuzz)
// test the readers through them, so this is what makes their findings hold for files.
#include <gtest/gtest.h>

#include <functional>
#include <string>
#include <vector>

#include "io/io_common.h"
#include "io_test_util.h"
#include "raysplats/errors.h"
#include "raysplats/splat_io.h"

namespace raysplats {
namespace {

using namespace testutil;

std::string error_of(const std::function<void()>& fn) {
    try {
        fn();
    } catch (const FileFormatError& e) {
        return e.what();
    }
    return "(no error)";
}

void expect_same_cloud(const GaussianCloud& a, const GaussianCloud& b) {
    EXPECT_EQ(a.sh_degree, b.sh_degree);
    EXPECT_EQ(a.positions, b.positions);
    EXPECT_EQ(a.rotations, b.rotations);
    EXPECT_EQ(a.scales, b.scales);
    EXPECT_EQ(a.opacities, b.opacities);
    EXPECT_EQ(a.sh, b.sh);
}

TEST(SplatBytes, RealFilesReadAsFromTheirPath) {
    for (const char* name : {"small_sh3_inria.ply", "small.splat", "biker_v4.spz", "unicorn_sh3.sog",
                             "guitar_supersplat.compressed.ply"}) {
        SCOPED_TRACE(name);
        const std::string path = data_path(name);
        const std::vector<std::uint8_t> bytes = read_bytes(path);
        LoadReport from_file, from_memory;
        const GaussianCloud a = read_splat_file(path, {}, &from_file);
        const GaussianCloud b = io::read_splat_bytes(bytes.data(), bytes.size(), path, {}, &from_memory);
        expect_same_cloud(a, b);
        EXPECT_EQ(from_file.warnings, from_memory.warnings);
        const SplatFileSummary p = probe_splat_file(path), q = io::probe_splat_bytes(bytes.data(), bytes.size(), path);
        EXPECT_EQ(p.format, q.format);
        EXPECT_EQ(p.count, q.count);
        EXPECT_EQ(p.sh_degree, q.sh_degree);
    }
}

TEST(SplatBytes, ErrorsAreTheFileReadersErrors) {
    auto ply = read_bytes(data_path("small_sh3_inria.ply"));
    ply.resize(ply.size() - 100);
    std::vector<std::uint8_t> garbage = {1, 2, 3, 'x', 'y', 'z', 4, 5};
    auto splat = read_bytes(data_path("small.splat"));
    splat.resize(32 * 2 + 7);
    auto sog = read_bytes(data_path("unicorn_sh3.sog"));
    sog.resize(sog.size() / 2);
    const std::vector<std::pair<std::string, std::vector<std::uint8_t>>> cases = {
        {"bytes_truncated.ply", ply},   {"bytes_garbage.spz", garbage},   {"bytes_garbage.xyz", garbage},
        {"bytes_short.splat", splat},   {"bytes_truncated.sog", sog},     {"bytes_empty.ply", {}}};
    for (const auto& [name, bytes] : cases) {
        SCOPED_TRACE(name);
        const std::string path = tmp_path(name);
        write_bytes(path, bytes);
        const std::string from_file = error_of([&] { read_splat_file(path); });
        const std::string from_memory = error_of([&] { io::read_splat_bytes(bytes.data(), bytes.size(), path); });
        EXPECT_NE(from_file, "(no error)");
        EXPECT_EQ(from_file, from_memory);
        EXPECT_EQ(error_of([&] { probe_splat_file(path); }),
                  error_of([&] { io::probe_splat_bytes(bytes.data(), bytes.size(), path); }));
    }
}

// Bytes in memory have no folder: an unbundled SOG (meta.json, images beside it) is refused, never looked up on disk.
TEST(SplatBytes, MemoryNeverOpensFilesBesideIt) {
    const std::string meta = "{\"version\": 2, \"count\": 1}";
    const std::vector<std::uint8_t> bytes(meta.begin(), meta.end());
    expect_format_error([&] { io::read_splat_bytes(bytes.data(), bytes.size(), "scene/meta.json"); }, "scene/meta.json",
                        {"not a SOG bundle"});
}

TEST(SplatBytes, FormatFromContentThenName) {
    const std::uint8_t ply[] = {'p', 'l', 'y', '\n', 0, 0, 0, 0};
    const std::uint8_t ngsp[] = {'N', 'G', 'S', 'P', 0, 0, 0, 0};
    const std::uint8_t zip[] = {'P', 'K', 3, 4, 0, 0, 0, 0};
    const std::uint8_t other[] = {9, 9, 9, 9, 9, 9, 9, 9};
    EXPECT_EQ(io::detect_splat_format(ply, 8, "a.spz"), SplatFormat::Ply);
    EXPECT_EQ(io::detect_splat_format(ngsp, 8, "a.ply"), SplatFormat::Spz);
    EXPECT_EQ(io::detect_splat_format(zip, 8, "a.gltf"), SplatFormat::Sog);
    EXPECT_EQ(io::detect_splat_format(other, 8, "a.splat"), SplatFormat::Splat);
    EXPECT_EQ(io::detect_splat_format(other, 8, "a.gltf"), SplatFormat::Gltf);
    EXPECT_EQ(io::detect_splat_format(other, 8, "x/meta.json"), SplatFormat::Sog);
    // A .splat's first float spells 'ply' without the line end, or 'glTF' without glTF binary's version 2.
    const std::uint8_t ply_float[] = {'p', 'l', 'y', 0x3f, 0, 0, 0, 0};
    const std::uint8_t gltf_float[] = {'g', 'l', 'T', 'F', 7, 0, 0, 0};
    EXPECT_EQ(io::detect_splat_format(ply_float, 8, "a.splat"), SplatFormat::Splat);
    EXPECT_EQ(io::detect_splat_format(gltf_float, 8, "a.splat"), SplatFormat::Splat);
    expect_format_error([&] { io::detect_splat_format(other, 8, "a.xyz"); }, "a.xyz", {"unknown splat format"});
    expect_format_error([&] { io::detect_splat_format(other, 0, "a.splat"); }, "a.splat", {"file is empty"});
}

}  // namespace
}  // namespace raysplats
