// SuperSplat's compressed PLY: the real file through every entry point, write -> read within the format's
// quantisation, read -> write -> read of an untouched file, the writer's chunk order, bad files, and agreement with
// PlayCanvas splat-transform when it is installed. (The independent decoder of the real file is numpy's:
// native/python/test_compressed_ply.py.)
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <numeric>
#include <random>

#include "core/morton_order.h"
#include "io/splat_formats.h"
#include "io_test_util.h"
#include "raysplats/errors.h"
#include "raysplats/memory_budget.h"
#include "raysplats/splat_io.h"

namespace raysplats {
namespace {

using namespace testutil;

const std::string kGuitar = "guitar_supersplat.compressed.ply";

std::size_t header_end(const std::vector<std::uint8_t>& b) {
    const std::string text(b.begin(), b.begin() + std::min<std::size_t>(b.size(), 4096));
    const std::size_t end = text.find("end_header\n");
    return end == std::string::npos ? 0 : end + 11;
}

TEST(CompressedPly, GuitarIsReadByEveryEntryPoint) {
    const std::string path = data_path(kGuitar);
    const SplatFileSummary s = probe_splat_file(path);
    EXPECT_EQ(s.format, SplatFormat::CompressedPly);
    EXPECT_EQ(s.count, 90854u);
    EXPECT_EQ(s.sh_degree, 0);
    // The memory check before an import has its numbers from the probe.
    EXPECT_EQ(import_memory_bytes(s.count, s.sh_degree, 8), import_memory_bytes(90854, 0, 8));
    LoadReport report;
    const GaussianCloud a = read_splat_file(path, {}, &report);
    EXPECT_EQ(a.size(), 90854u);
    EXPECT_TRUE(report.warnings.empty());
    const GaussianCloud b = read_ply(path), c = read_compressed_ply(path);
    EXPECT_EQ(a.positions, b.positions);
    EXPECT_EQ(a.positions, c.positions);
    EXPECT_EQ(a.rotations, c.rotations);
    EXPECT_EQ(a.sh, c.sh);
    // From memory, as a fuzz target calls it.
    const std::vector<std::uint8_t> bytes = read_bytes(path);
    const GaussianCloud d = read_compressed_ply_bytes(bytes.data(), bytes.size(), "memory");
    EXPECT_EQ(a.scales, d.scales);
    EXPECT_EQ(a.opacities, d.opacities);
    // Filters apply as to every reader.
    ReadOptions options;
    options.max_count = 1000;
    EXPECT_EQ(read_splat_file(path, options).size(), 1000u);
}

TEST(CompressedPly, ExtensionNamesTheFormat) {
    EXPECT_EQ(splat_format_from_extension("a/scene.compressed.ply"), SplatFormat::CompressedPly);
    EXPECT_EQ(splat_format_from_extension("SCENE.Compressed.PLY"), SplatFormat::CompressedPly);
    EXPECT_EQ(splat_format_from_extension("compressed.ply"), SplatFormat::Ply);
    EXPECT_EQ(splat_format_from_extension("scene.ply"), SplatFormat::Ply);
    EXPECT_STREQ(splat_format_name(SplatFormat::CompressedPly), "compressed_ply");
}

// Chunk membership of the file: the cloud's order is kept where it is already compact (here: Morton order).
GaussianCloud in_order(const GaussianCloud& c, const std::vector<std::uint32_t>& order) {
    GaussianCloud out;
    out.resize(c.size(), c.sh_degree);
    const std::size_t K = std::size_t(c.coeffs_per_channel());
    for (std::size_t j = 0; j < order.size(); ++j) {
        const std::size_t i = order[j];
        std::copy_n(&c.positions[3 * i], 3, &out.positions[3 * j]);
        std::copy_n(&c.rotations[4 * i], 4, &out.rotations[4 * j]);
        std::copy_n(&c.scales[3 * i], 3, &out.scales[3 * j]);
        out.opacities[j] = c.opacities[i];
        std::copy_n(&c.sh[3 * K * i], 3 * K, &out.sh[3 * K * j]);
    }
    return out;
}

// Write -> read keeps every value within the format's quantisation, stated per chunk (splat_io.h).
TEST(CompressedPly, WriteReadKeepsValuesWithinQuantisation) {
    const GaussianCloud trained = read_ply(data_path("small_sh3_inria.ply"));
    const GaussianCloud a = in_order(trained, morton_order(trained));
    const std::string path = tmp_path("small_sh3.compressed.ply");
    write_splat_file(path, a);
    const GaussianCloud b = read_splat_file(path);
    ASSERT_EQ(b.size(), a.size());
    ASSERT_EQ(b.sh_degree, 3);
    const std::size_t n = a.size();
    double worst[6] = {0, 0, 0, 0, 0, 0};
    for (std::size_t c0 = 0; c0 < n; c0 += 256) {
        const std::size_t c1 = std::min(n, c0 + 256);
        double lo[9], hi[9];
        std::fill_n(lo, 9, HUGE_VAL), std::fill_n(hi, 9, -HUGE_VAL);
        for (std::size_t i = c0; i < c1; ++i)
            for (int j = 0; j < 3; ++j) {
                const double v[3] = {a.positions[3 * i + j], std::log(double(a.scales[3 * i + j])),
                                     0.5 + 0.28209479177387814 * a.sh[48 * i + std::size_t(j)]};
                for (int k = 0; k < 3; ++k) lo[3 * k + j] = std::min(lo[3 * k + j], v[k]), hi[3 * k + j] = std::max(hi[3 * k + j], v[k]);
            }
        for (std::size_t i = c0; i < c1; ++i) {
            for (int j = 0; j < 3; ++j) {
                const double levels = j == 1 ? 1023 : 2047;  // 11-10-11 bits
                const double p = std::fabs(double(b.positions[3 * i + j]) - a.positions[3 * i + j]);
                ASSERT_LE(p, (hi[j] - lo[j]) / (2 * levels) + 1e-6) << i << " " << j;
                const double s = std::fabs(std::log(double(b.scales[3 * i + j])) - std::log(double(a.scales[3 * i + j])));
                ASSERT_LE(s, (hi[3 + j] - lo[3 + j]) / (2 * levels) + 1e-6) << i << " " << j;
                const double c = std::fabs(double(b.sh[48 * i + std::size_t(j)]) - a.sh[48 * i + std::size_t(j)]) * 0.28209479177387814;
                ASSERT_LE(c, (hi[6 + j] - lo[6 + j]) / 510 + 1e-6) << i << " " << j;
                worst[0] = std::max(worst[0], p / std::max(hi[j] - lo[j], 1e-30));
                worst[1] = std::max(worst[1], s), worst[2] = std::max(worst[2], c);
            }
            const double o = std::fabs(double(b.opacities[i]) - a.opacities[i]);
            ASSERT_LE(o, 1.0 / 510 + 1e-7) << i;
            double dot = 0;
            for (int j = 0; j < 4; ++j) dot += double(a.rotations[4 * i + j]) * b.rotations[4 * i + j];
            // Each of the three smaller components within e = sqrt(2)/2046; then 1 - |dot| <= 6 e^2.
            const double e = std::sqrt(2.0) / 2046;
            ASSERT_LE(1 - std::fabs(dot), 6 * e * e + 1e-7) << i;
            for (std::size_t k = 3; k < 48; ++k) {
                const double r = std::fabs(double(b.sh[48 * i + k]) - std::clamp(double(a.sh[48 * i + k]), -4.0, 4.0));
                ASSERT_LE(r, 1.0 / 64 + 1e-6) << i << " " << k;
                worst[4] = std::max(worst[4], r);
            }
            worst[3] = std::max(worst[3], o), worst[5] = std::max(worst[5], 1 - std::fabs(dot));
        }
    }
    std::printf("largest errors: position %.3g of the chunk's extent, log scale %.3g, colour %.3g, opacity %.3g, "
                "f_rest %.3g, rotation 1-|dot| %.3g\n",
                worst[0], worst[1], worst[2], worst[3], worst[4], worst[5]);
}

// A trained scene in training order has no spatial order: the writer sorts it (Morton) so that each chunk is small,
// and its positions are far finer than in file order.
TEST(CompressedPly, WriterSortsAnUnorderedSceneIntoCompactChunks) {
    const GaussianCloud a = read_ply(data_path("donut_sh0.ply"));
    std::vector<std::uint32_t> order(a.size());
    std::iota(order.begin(), order.end(), 0u);
    std::shuffle(order.begin(), order.end(), std::mt19937(7));
    const GaussianCloud shuffled = in_order(a, order);
    const std::string path = tmp_path("shuffled.compressed.ply");
    write_compressed_ply(path, shuffled);
    const std::vector<std::uint8_t> bytes = read_bytes(path);
    const std::size_t data = header_end(bytes);
    ASSERT_GT(data, 0u);
    // Chunk records: 18 floats. Each chunk's position extent (summed over x, y, z) in the file, against the same
    // chunks of 256 taken in the shuffled order; medians, since the floaters' few chunks are large either way.
    const std::size_t chunks = (a.size() + 255) / 256;
    std::vector<double> written, unsorted;
    for (std::size_t c = 0; c < chunks; ++c) {
        float f[18];
        std::memcpy(f, bytes.data() + data + c * 72, 72);
        written.push_back(double(f[3] - f[0]) + (f[4] - f[1]) + (f[5] - f[2]));
        float lo[3] = {HUGE_VALF, HUGE_VALF, HUGE_VALF}, hi[3] = {-HUGE_VALF, -HUGE_VALF, -HUGE_VALF};
        for (std::size_t i = 256 * c; i < std::min(a.size(), 256 * c + 256); ++i)
            for (int j = 0; j < 3; ++j)
                lo[j] = std::min(lo[j], shuffled.positions[3 * i + j]), hi[j] = std::max(hi[j], shuffled.positions[3 * i + j]);
        unsorted.push_back(double(hi[0] - lo[0]) + (hi[1] - lo[1]) + (hi[2] - lo[2]));
    }
    std::sort(written.begin(), written.end()), std::sort(unsorted.begin(), unsorted.end());
    std::printf("median chunk extent %.4g written, %.4g in the shuffled order\n", written[chunks / 2], unsorted[chunks / 2]);
    // Measured: 0.099 against 0.489 (donut); unsorted chunks would span the whole scene (a ratio near 1).
    EXPECT_LT(written[chunks / 2], 0.3 * unsorted[chunks / 2]);
}

// An untouched compressed file read, written and read again keeps every value; how many bytes of its data change is
// printed (the header's comment names the writer, so the headers differ).
TEST(CompressedPly, GuitarReadWriteReadKeepsEveryValue) {
    const std::string source = data_path(kGuitar);
    const GaussianCloud a = read_splat_file(source);
    const std::string path = tmp_path("guitar_again.compressed.ply");
    write_splat_file(path, a);
    const GaussianCloud b = read_splat_file(path);
    ASSERT_EQ(b.size(), a.size());
    EXPECT_EQ(b.positions, a.positions);
    EXPECT_EQ(b.scales, a.scales);
    EXPECT_EQ(b.opacities, a.opacities);
    EXPECT_EQ(b.sh, a.sh);
    EXPECT_EQ(b.rotations, a.rotations);
    const std::vector<std::uint8_t> x = read_bytes(source), y = read_bytes(path);
    const std::size_t dx = header_end(x), dy = header_end(y);
    ASSERT_EQ(x.size() - dx, y.size() - dy);
    std::size_t differing = 0, chunk_differing = 0;
    const std::size_t chunk_bytes = 72 * ((a.size() + 255) / 256);
    for (std::size_t k = 0; k < x.size() - dx; ++k)
        if (x[dx + k] != y[dy + k]) ++differing, chunk_differing += k < chunk_bytes;
    std::printf("data bytes differing: %zu of %zu (%zu in the chunk bounds)\n", differing, x.size() - dx, chunk_differing);
    // Our own file written again is the same file, byte for byte.
    const std::string again = tmp_path("guitar_again_again.compressed.ply");
    write_splat_file(again, b);
    EXPECT_EQ(read_bytes(again), y);
}

TEST(CompressedPly, ShDegreesOneAndTwoAndEmptyClouds) {
    const GaussianCloud full = read_ply(data_path("small_sh3_inria.ply"));
    for (int degree : {0, 1, 2}) {
        GaussianCloud c;
        c.resize(300, degree);
        const std::size_t K = std::size_t(c.coeffs_per_channel());
        for (std::size_t i = 0; i < 300; ++i) {
            std::copy_n(&full.positions[3 * i], 3, &c.positions[3 * i]);
            std::copy_n(&full.rotations[4 * i], 4, &c.rotations[4 * i]);
            std::copy_n(&full.scales[3 * i], 3, &c.scales[3 * i]);
            c.opacities[i] = full.opacities[i];
            for (std::size_t k = 0; k < K; ++k) std::copy_n(&full.sh[(16 * i + k) * 3], 3, &c.sh[(K * i + k) * 3]);
        }
        const std::string path = tmp_path("degree" + std::to_string(degree) + ".compressed.ply");
        write_splat_file(path, c);
        EXPECT_EQ(probe_splat_file(path).sh_degree, degree);
        const GaussianCloud b = read_splat_file(path);
        EXPECT_EQ(b.sh_degree, degree);
        ASSERT_EQ(b.size(), 300u);
    }
    GaussianCloud empty;
    empty.resize(0, 0);
    const std::string path = tmp_path("empty.compressed.ply");
    write_splat_file(path, empty);
    EXPECT_EQ(read_splat_file(path).size(), 0u);
}

// A compressed PLY of `n` splats in `chunks` chunks, with every bound 0..1 (max_y = bound_value) and the packed data
// zero, its last `cut` bytes cut off.
std::string synthetic(const std::string& name, std::uint64_t n, std::uint64_t chunks, const std::string& extra_chunk_property = "",
                      std::size_t cut = 0, float bound_value = 1.0f) {
    std::string h = "ply\nformat binary_little_endian 1.0\nelement chunk " + std::to_string(chunks) + "\n";
    for (const char* p : {"min_x", "min_y", "min_z", "max_x", "max_y", "max_z", "min_scale_x", "min_scale_y",
                          "min_scale_z", "max_scale_x", "max_scale_y", "max_scale_z"})
        h += std::string("property float ") + p + "\n";
    h += extra_chunk_property;
    h += "element vertex " + std::to_string(n) + "\n";
    for (const char* p : {"packed_position", "packed_rotation", "packed_scale", "packed_color"})
        h += std::string("property uint ") + p + "\n";
    h += "end_header\n";
    std::string data;
    for (std::uint64_t c = 0; c < std::min<std::uint64_t>(chunks, 1000); ++c)
        for (long k = 0; k < 12 + std::count(extra_chunk_property.begin(), extra_chunk_property.end(), '\n'); ++k) {
            const float v = k == 4 ? bound_value : float(k >= 3 && k < 6);
            data.append(reinterpret_cast<const char*>(&v), 4);
        }
    data += std::string(std::size_t(std::min<std::uint64_t>(n, 100000)) * 16, '\0');
    std::string all = h + data;
    if (cut) all.resize(all.size() - cut);
    const std::string path = tmp_path(name);
    write_text(path, all);
    return path;
}

TEST(CompressedPlyErrors, BadFilesAreRefusedWithWhatIsWrong) {
    // A sound synthetic file reads (so that each case below fails for its one defect).
    EXPECT_EQ(read_splat_file(synthetic("sound.compressed.ply", 300, 2)).size(), 300u);
    const std::string truncated = synthetic("truncated.compressed.ply", 300, 2, "", 5);
    expect_format_error([&] { read_splat_file(truncated); }, "truncated.compressed.ply",
                        {"file is truncated", "element 'vertex' declares 300 records of 16 bytes"});
    expect_format_error([&] { probe_splat_file(truncated); }, "truncated.compressed.ply", {"file is truncated"});
    const std::string chunks = synthetic("chunks.compressed.ply", 300, 1);
    expect_format_error([&] { read_splat_file(chunks); }, "chunks.compressed.ply",
                        {"element 'chunk' has 1 records; 300 splats in chunks of 256 need 2", "at byte"});
    const std::string nan = synthetic("nan.compressed.ply", 300, 2, "", 0, std::nanf(""));
    expect_format_error([&] { read_splat_file(nan); }, "nan.compressed.ply",
                        {"chunk 0 has a non-finite bound max_y", "at byte"});
    const std::string partial = synthetic("partial_colour.compressed.ply", 300, 2, "property float min_r\n");
    expect_format_error([&] { read_splat_file(partial); }, "partial_colour.compressed.ply",
                        {"1 of the 6 colour bounds", "all or none"});
    std::string text = "ply\nformat binary_little_endian 1.0\nelement chunk 1\nproperty double min_x\nelement vertex 1\n"
                       "property uint packed_position\nproperty uint packed_rotation\nproperty uint packed_scale\n"
                       "property uint packed_color\nend_header\n" + std::string(24, '\0');
    write_text(tmp_path("double_bound.compressed.ply"), text);
    expect_format_error([&] { read_splat_file(tmp_path("double_bound.compressed.ply")); }, "double_bound.compressed.ply",
                        {"property 'min_x' of element 'chunk' is double; the format stores chunk bounds as float"});
    text = "ply\nformat ascii 1.0\nelement chunk 1\nproperty float min_x\nelement vertex 1\nproperty uint packed_position\n"
           "end_header\n0\n0\n";
    write_text(tmp_path("ascii.compressed.ply"), text);
    expect_format_error([&] { read_splat_file(tmp_path("ascii.compressed.ply")); }, "ascii.compressed.ply",
                        {"compressed PLY must be binary_little_endian, not ascii"});
    expect_format_error([&] { read_compressed_ply(data_path("donut_sh0.ply")); }, "donut_sh0.ply",
                        {"not a compressed PLY"});
    const std::uint8_t junk[3] = {'p', 'l', 'y'};
    expect_format_error([&] { read_compressed_ply_bytes(junk, 3, "three bytes"); }, "three bytes", {"PLY header"});
}

// PlayCanvas splat-transform (the reference converter) reads our compressed .ply as the scene we wrote, and writes a
// compressed .ply that we read as the scene it converted. Found like in spz_format_test.cpp; skipped when absent.
std::string splat_transform() {
    std::vector<std::string> candidates;
    if (const char* e = std::getenv("RAYSPLATS_SPLAT_TRANSFORM")) candidates.push_back(e);
    const char* npm = std::getenv("RAYSPLATS_NPM_DIR");
    const char* home = std::getenv("HOME");
    const std::string dir = npm ? npm : home ? std::string(home) + "/.cache/raysplats/npm" : "";
    if (!dir.empty()) candidates.push_back(dir + "/node_modules/.bin/splat-transform");
    for (const std::string& c : candidates)
        if (std::ifstream(c).good()) return c;
    return "";
}

TEST(CompressedPly, SplatTransformAgrees) {
    const std::string tool = splat_transform();
    if (tool.empty())
        GTEST_SKIP() << "splat-transform not installed (set RAYSPLATS_SPLAT_TRANSFORM or run scripts/setup_test_tools.sh)";
    auto run = [&](const std::string& in, const std::string& out) {
        const std::string command = "timeout 120 '" + tool + "' -w '" + in + "' '" + out + "' > /dev/null 2>&1";
        ASSERT_EQ(std::system(command.c_str()), 0) << command;
    };
    // Theirs decoding ours: the guitar written by us, converted by splat-transform to an INRIA .ply.
    const GaussianCloud guitar = read_splat_file(data_path(kGuitar));
    const std::string ours = tmp_path("ours_for_splat_transform.compressed.ply"), theirs = tmp_path("splat_transform_of_ours.ply");
    write_compressed_ply(ours, guitar);
    run(ours, theirs);
    // Theirs encoding: an INRIA .ply converted by splat-transform to a compressed .ply, which we read.
    const std::string theirs_compressed = tmp_path("splat_transform_of_small.compressed.ply");
    run(data_path("small_sh3_inria.ply"), theirs_compressed);
    const GaussianCloud a = read_splat_file(theirs);
    ASSERT_EQ(a.size(), guitar.size());
    for (std::size_t i = 0; i < a.size(); ++i) {
        for (int j = 0; j < 3; ++j) {
            ASSERT_NEAR(a.positions[3 * i + j], guitar.positions[3 * i + j], 1e-5) << i;
            ASSERT_NEAR(a.scales[3 * i + j], guitar.scales[3 * i + j], 1e-5 * guitar.scales[3 * i + j] + 1e-9) << i;
            ASSERT_NEAR(a.sh[3 * i + j], guitar.sh[3 * i + j], 1e-4) << i;
        }
        ASSERT_NEAR(a.opacities[i], guitar.opacities[i], 1e-5) << i;
        double dot = 0;
        for (int j = 0; j < 4; ++j) dot += double(a.rotations[4 * i + j]) * guitar.rotations[4 * i + j];
        ASSERT_GT(std::fabs(dot), 1 - 1e-5) << i;
    }
    // Their compressed file (SH degree 3: an 'sh' element) read by us and by them (decoded to an INRIA .ply): the
    // same splats in the same order, within float rounding (their SH bytes decode by the same formula).
    const std::string theirs_decoded = tmp_path("splat_transform_decoded.ply");
    run(theirs_compressed, theirs_decoded);
    const GaussianCloud b = read_splat_file(theirs_compressed), c = read_ply(theirs_decoded);
    ASSERT_EQ(b.size(), 9080u);
    ASSERT_EQ(c.size(), b.size());
    ASSERT_EQ(b.sh_degree, 3);
    ASSERT_EQ(c.sh_degree, 3);
    for (std::size_t i = 0; i < b.size(); ++i) {
        for (int j = 0; j < 3; ++j) {
            ASSERT_NEAR(b.positions[3 * i + j], c.positions[3 * i + j], 1e-6 * (1 + std::fabs(c.positions[3 * i + j]))) << i;
            ASSERT_NEAR(b.scales[3 * i + j], c.scales[3 * i + j], 1e-5 * c.scales[3 * i + j]) << i;
        }
        ASSERT_NEAR(b.opacities[i], c.opacities[i], 1e-6) << i;
        for (std::size_t k = 0; k < 48; ++k) ASSERT_NEAR(b.sh[48 * i + k], c.sh[48 * i + k], 1e-5) << i << " " << k;
        double dot = 0;
        for (int j = 0; j < 4; ++j) dot += double(b.rotations[4 * i + j]) * c.rotations[4 * i + j];
        ASSERT_GT(std::fabs(dot), 1 - 1e-6) << i;
    }
}

}  // namespace
}  // namespace raysplats
