// antimatter15 .splat reading and writing, checked against the raw 32-byte records.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>

#include "io/splat_formats.h"
#include "io_test_util.h"
#include "raysplats/errors.h"
#include "raysplats/splat_io.h"

namespace raysplats {
namespace {

using namespace testutil;

constexpr double kC0 = 0.28209479177387814;

float rec_float(const std::vector<std::uint8_t>& b, std::size_t i, int k) {
    float v;
    std::memcpy(&v, b.data() + 32 * i + 4 * std::size_t(k), 4);
    return v;
}

TEST(DotSplatFormat, RealFileMatchesRecordBytes) {
    const std::string path = data_path("small.splat");
    const auto b = read_bytes(path);
    ASSERT_EQ(b.size(), 22764u * 32u);
    const GaussianCloud c = read_dot_splat(path);
    ASSERT_EQ(c.size(), 22764u);
    EXPECT_EQ(c.sh_degree, 0);
    for (std::size_t i : sample_indices(c.size())) {
        SCOPED_TRACE(i);
        for (int j = 0; j < 3; ++j) EXPECT_EQ(c.positions[3 * i + j], rec_float(b, i, j));
        for (int j = 0; j < 3; ++j) EXPECT_EQ(c.scales[3 * i + j], rec_float(b, i, 3 + j));
        const std::uint8_t* p = b.data() + 32 * i;
        for (int j = 0; j < 3; ++j) EXPECT_NEAR(c.sh[3 * i + j], (p[24 + j] / 255.0 - 0.5) / kC0, 1e-6);
        EXPECT_NEAR(c.opacities[i], p[27] / 255.0, 1e-7);
        double q[4], n2 = 0;
        for (int j = 0; j < 4; ++j) q[j] = (p[28 + j] - 128.0) / 128.0, n2 += q[j] * q[j];
        for (int j = 0; j < 4; ++j) EXPECT_NEAR(c.rotations[4 * i + j], q[j] / std::sqrt(n2), 1e-6);
    }
    EXPECT_EQ(read_splat_file(path).positions, c.positions);  // dispatch by extension
}

TEST(DotSplatFormat, RoundTripKeepsBytes) {
    const std::string path = data_path("small.splat");
    const GaussianCloud a = read_dot_splat(path);
    const std::string out = tmp_path("roundtrip.splat");
    write_dot_splat(out, a);
    const auto src = read_bytes(path), dst = read_bytes(out);
    ASSERT_EQ(src.size(), dst.size());
    // An untouched round trip is byte-exact, rotation bytes included: the stored bytes are not a unit quaternion
    // (the reader normalises them), and re-quantising the normalised one changed a byte in 44 % of the records
    // before the writer looked for the bytes that read back as the same quaternion.
    std::size_t records_changed = 0;
    for (std::size_t i = 0; i < a.size(); ++i) {
        EXPECT_EQ(std::memcmp(&src[32 * i], &dst[32 * i], 28), 0) << "record " << i;
        records_changed += std::memcmp(&src[32 * i + 28], &dst[32 * i + 28], 4) != 0;
    }
    EXPECT_EQ(records_changed, 0u) << "of " << a.size();
    EXPECT_TRUE(src == dst);
    const GaussianCloud b = read_dot_splat(out);
    EXPECT_EQ(b.positions, a.positions);
    EXPECT_EQ(b.sh, a.sh);
    EXPECT_EQ(b.opacities, a.opacities);
}

TEST(DotSplatFormat, EditedRotationIsStillQuantisedToTheNearestBytes) {
    // The exact-bytes search must not change what an edited (arbitrary) quaternion becomes: the nearest bytes.
    GaussianCloud c;
    c.resize(3, 0);
    const float q[12] = {0.8f, 0.36f, -0.48f, 0.0f, 0.5f, 0.5f, 0.5f, 0.5f, 0.1234f, -0.9f, 0.3f, 0.2771f};
    for (int i = 0; i < 3; ++i) {
        double n = 0;
        for (int j = 0; j < 4; ++j) n += double(q[4 * i + j]) * q[4 * i + j];
        for (int j = 0; j < 4; ++j) c.rotations[4 * i + j] = float(q[4 * i + j] / std::sqrt(n));
    }
    const std::string out = tmp_path("edited_rotation.splat");
    write_dot_splat(out, c);
    const GaussianCloud back = read_dot_splat(out);
    for (int i = 0; i < 3; ++i) {
        double dot = 0;
        for (int j = 0; j < 4; ++j) dot += double(back.rotations[4 * i + j]) * c.rotations[4 * i + j];
        EXPECT_GT(dot, 1.0 - 1e-4) << i;  // 8-bit components: within 1/128 per component
    }
}

TEST(DotSplatFormat, PlyToSplatWithinQuantisation) {
    const GaussianCloud a = read_ply(data_path("small_sh3_inria.ply"));
    const std::string out = tmp_path("from_ply.splat");
    write_dot_splat(out, a);
    const GaussianCloud b = read_dot_splat(out);
    ASSERT_EQ(b.size(), a.size());
    EXPECT_EQ(b.sh_degree, 0);  // higher bands are lost
    EXPECT_EQ(b.positions, a.positions);
    EXPECT_EQ(b.scales, a.scales);
    const int K = a.coeffs_per_channel();
    // Steps: colour 1/255 of (0.5 + C0 dc), i.e. dc step 1/(255 C0) = 0.0139, so error <= 0.007 inside the
    // representable range; opacity step 1/255 (error <= 0.002); rotation components step 1/128.
    for (std::size_t i = 0; i < a.size(); ++i) {
        for (int ch = 0; ch < 3; ++ch) {
            const double dc = a.sh[i * K * 3 + ch];
            const double clamped = std::min(std::max(dc, -0.5 / kC0), 0.5 / kC0);
            ASSERT_NEAR(b.sh[3 * i + ch], clamped, 0.5 / (255 * kC0) + 1e-6) << i;
        }
        ASSERT_NEAR(b.opacities[i], a.opacities[i], 0.5 / 255 + 1e-6) << i;
        double dot = 0;
        for (int j = 0; j < 4; ++j) dot += double(a.rotations[4 * i + j]) * b.rotations[4 * i + j];
        ASSERT_GT(std::fabs(dot), 1.0 - 2e-4) << i;
    }
}

TEST(DotSplatFormat, NonFinitePositionDropped) {
    auto b = read_bytes(data_path("small.splat"));
    b.resize(32 * 10);
    const float nan = std::nanf("");
    std::memcpy(&b[32 * 3 + 4], &nan, 4);  // y of splat 3
    std::memset(&b[32 * 5 + 28], 128, 4);  // zero quaternion of splat 5
    const std::string path = tmp_path("nan.splat");
    write_bytes(path, b);
    LoadReport report;
    const GaussianCloud c = read_dot_splat(path, {}, &report);
    EXPECT_EQ(c.size(), 9u);
    EXPECT_EQ(report.non_finite_dropped, 1u);
    EXPECT_EQ(report.zero_rotation_repaired, 1u);
    EXPECT_EQ(c.rotations[4 * 4], 1.0f);  // splat 5 is now index 4
    EXPECT_EQ(report.warnings.size(), 2u);
}

// Found by fuzzing (native/fuzz/fuzz_dot_splat.cpp): a .splat stores linear scales, so a record may hold a negative
// one; it was returned as stored and then refused by the core's own check (GaussianCloud::check_values).
TEST(DotSplatFormat, NegativeScaleReadAsItsMagnitude) {
    auto b = read_bytes(data_path("small.splat"));
    b.resize(32 * 4);
    float s;
    std::memcpy(&s, &b[32 * 1 + 12 + 4], 4);  // scale y of splat 1
    const float negative = -std::fabs(s);
    std::memcpy(&b[32 * 1 + 12 + 4], &negative, 4);
    const float negative_zero = -0.0f;  // the sign of a zero is no negative scale
    std::memcpy(&b[32 * 2 + 12], &negative_zero, 4);
    const std::string path = tmp_path("negative_scale.splat");
    write_bytes(path, b);
    LoadReport report;
    const GaussianCloud c = read_dot_splat(path, {}, &report);
    ASSERT_EQ(c.size(), 4u);
    EXPECT_EQ(c.scales[3 * 1 + 1], std::fabs(s));
    EXPECT_EQ(report.negative_scale_repaired, 1u);
    ASSERT_EQ(report.warnings.size(), 1u);
    EXPECT_NE(report.warnings[0].find("negative scale"), std::string::npos);
    EXPECT_NO_THROW(c.check_values("negative_scale.splat"));
}

// A .splat whose first float begins with gzip's two bytes 1f 8b (about 1 in 65,536 files: the low bytes of the first
// position's x) was refused as corrupt SPZ gzip; a .splat name takes SPZ only for a full SPZ signature.
TEST(DotSplatFormat, GzipMagicByChanceIsStillASplat) {
    auto b = read_bytes(data_path("small.splat"));
    b.resize(32 * 3);
    b[0] = 0x1f, b[1] = 0x8b;  // x of splat 0 changes in its low mantissa bits only
    const std::string path = tmp_path("gzip_by_chance.splat");
    write_bytes(path, b);
    EXPECT_EQ(read_splat_file(path).size(), 3u);
    const SplatFileSummary s = probe_splat_file(path);
    EXPECT_EQ(s.format, SplatFormat::Splat);
    EXPECT_EQ(s.count, 3u);
    // The same bytes under another name are SPZ by content, and refused as such.
    const std::string spz = tmp_path("gzip_by_chance.spz");
    write_bytes(spz, b);
    expect_format_error([&] { read_splat_file(spz); }, "gzip_by_chance.spz", {"gzip"});
}

TEST(DotSplatFormatErrors, SizeNotMultipleOf32) {
    auto b = read_bytes(data_path("small.splat"));
    b.resize(b.size() - 5);
    const std::string path = tmp_path("truncated.splat");
    write_bytes(path, b);
    expect_format_error([&] { read_dot_splat(path); }, "truncated.splat", {"not a multiple of the 32-byte", "27 trailing bytes"});
    expect_format_error([&] { read_splat_file(path); }, "truncated.splat", {"multiple of the 32-byte"});
}

TEST(DotSplatFormatErrors, EmptyFile) {
    const std::string path = tmp_path("empty.splat");
    write_bytes(path, {});
    expect_format_error([&] { read_dot_splat(path); }, "empty.splat", {"empty"});
}

}  // namespace
}  // namespace raysplats
