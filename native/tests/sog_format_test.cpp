// PlayCanvas SOG reader (native/src/io/sog_format.cpp): the real unicorn_sh3.sog against PlayCanvas's own decoding of
// it (unicorn_sh3_reordered.ply), bundled, unbundled and in memory; small scenes of both versions built here from the
// specification's formulas; and malformed scenes, each refused with a message naming the file and the problem.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include "io/splat_formats.h"
#include "io_test_util.h"
#include "raysplats/errors.h"
#include "raysplats/splat_io.h"
#include "sog_test_util.h"

namespace raysplats {
namespace {

using namespace testutil;

GaussianCloud read_unicorn() { return read_sog(data_path("unicorn_sh3.sog")); }

// unicorn_sh3_reordered.ply is splat-transform's decoding of unicorn_sh3.sog (shared/data/README.md), in the same
// splat order. Our values must agree far inside the format's quantisation steps; the bounds, per attribute:
//   position   1e-6: under 1/10 of the smallest 16-bit step (the x range 0.927 / 65535 = 1.4e-5 in the log domain,
//              where d position / d n = exp|n| >= 1), i.e. only float rounding;
//   scale      log scale 1e-5: the codebook holds the log scale, and the file's float32 logs round within that;
//   opacity    1.5e-6 of one 8-bit step of 1/255: the reference stores logit(A / 255) clamped to [1e-6, 1 - 1e-6];
//   rotation   1e-6 per component after normalising the reference, up to the sign of the whole quaternion (8-bit
//              components step by sqrt(2) / 255 = 5.5e-3);
//   SH         1e-6: DC and every rest coefficient are codebook entries reached through the palette, copied as is.
TEST(SogFormat, RealBundleMatchesPlayCanvasDecoding) {
    const GaussianCloud c = read_unicorn();
    const RawPly ref(data_path("unicorn_sh3_reordered.ply"));
    ASSERT_EQ(c.size(), 49602u);
    ASSERT_EQ(ref.count, c.size());
    ASSERT_EQ(c.sh_degree, 3);
    ASSERT_EQ(ref.rest_count(), 45u);
    double worst[6] = {0, 0, 0, 0, 0, 0};
    for (std::size_t i = 0; i < c.size(); ++i) {
        const char* axes[3] = {"x", "y", "z"};
        for (int a = 0; a < 3; ++a) {
            worst[0] = std::max(worst[0], double(std::fabs(c.positions[3 * i + a] - ref.get(i, axes[a]))));
            const float ref_log_scale = ref.get(i, "scale_" + std::to_string(a));
            worst[1] = std::max(worst[1], std::fabs(std::log(double(c.scales[3 * i + a])) - ref_log_scale));
        }
        worst[2] = std::max(worst[2], std::fabs(double(c.opacities[i]) - sigmoid(ref.get(i, "opacity"))));
        double q[4], n2 = 0, same = 0, flipped = 0;
        for (int k = 0; k < 4; ++k) q[k] = ref.get(i, "rot_" + std::to_string(k)), n2 += q[k] * q[k];
        for (int k = 0; k < 4; ++k) {
            const double r = q[k] / std::sqrt(n2);
            same = std::max(same, std::fabs(c.rotations[4 * i + k] - r));
            flipped = std::max(flipped, std::fabs(c.rotations[4 * i + k] + r));
        }
        worst[3] = std::max(worst[3], std::min(same, flipped));
        const float* sh = &c.sh[i * 16 * 3];
        for (int ch = 0; ch < 3; ++ch) {
            worst[4] = std::max(worst[4], double(std::fabs(sh[ch] - ref.get(i, "f_dc_" + std::to_string(ch)))));
            for (int k = 0; k < 15; ++k)  // f_rest is channel-major: f_rest_{ch * 15 + k}
                worst[5] = std::max(worst[5], double(std::fabs(sh[3 * (1 + k) + ch] -
                                                               ref.get(i, "f_rest_" + std::to_string(ch * 15 + k)))));
        }
    }
    std::printf("  largest differences: position %.3g, log scale %.3g, opacity %.3g, rotation %.3g, DC %.3g, rest %.3g\n",
                worst[0], worst[1], worst[2], worst[3], worst[4], worst[5]);
    EXPECT_LE(worst[0], 1e-6);
    EXPECT_LE(worst[1], 1e-5);
    EXPECT_LE(worst[2], 1.5e-6);
    EXPECT_LE(worst[3], 1e-6);
    EXPECT_LE(worst[4], 1e-6);
    EXPECT_LE(worst[5], 1e-6);
}

void expect_same_cloud(const GaussianCloud& a, const GaussianCloud& b) {
    ASSERT_EQ(a.size(), b.size());
    EXPECT_EQ(a.sh_degree, b.sh_degree);
    EXPECT_EQ(a.positions, b.positions);
    EXPECT_EQ(a.rotations, b.rotations);
    EXPECT_EQ(a.scales, b.scales);
    EXPECT_EQ(a.opacities, b.opacities);
    EXPECT_EQ(a.sh, b.sh);
}

std::string unzip_unicorn() {
    const std::string dir = tmp_path("unicorn_unbundled");
    std::filesystem::remove_all(dir);
    // Python's zipfile: an extractor independent of the reader's minizip.
    const std::string command = "/usr/bin/python3 -m zipfile -e '" + data_path("unicorn_sh3.sog") + "' '" + dir + "'";
    EXPECT_EQ(std::system(command.c_str()), 0) << command;
    return dir;
}

TEST(SogFormat, UnbundledFolderReadsAsTheBundle) {
    const std::string dir = unzip_unicorn();
    const GaussianCloud bundled = read_unicorn();
    expect_same_cloud(read_sog(dir + "/meta.json"), bundled);
    expect_same_cloud(read_splat_file(dir + "/meta.json"), bundled);
    const SplatFileSummary s = probe_splat_file(dir + "/meta.json");
    EXPECT_EQ(s.format, SplatFormat::Sog);
    EXPECT_EQ(s.count, 49602u);
    EXPECT_EQ(s.sh_degree, 3);
    // A missing image is named by its path.
    std::filesystem::remove(dir + "/quats.webp");
    expect_format_error([&] { read_sog(dir + "/meta.json"); }, dir + "/quats.webp", {"the quats image", "cannot be opened"});
}

TEST(SogFormat, BundleFromFileAndMemoryAndDispatch) {
    const std::string path = data_path("unicorn_sh3.sog");
    const GaussianCloud c = read_unicorn();
    const std::vector<std::uint8_t> bytes = read_bytes(path);
    expect_same_cloud(read_sog_bundle(bytes.data(), bytes.size(), "in memory"), c);
    expect_same_cloud(read_splat_file(path), c);
    const SplatFileSummary s = probe_splat_file(path);
    EXPECT_EQ(s.format, SplatFormat::Sog);
    EXPECT_EQ(s.count, 49602u);
    EXPECT_EQ(s.sh_degree, 3);
    // ReadOptions apply as for every reader.
    ReadOptions options;
    options.max_count = 1000;
    EXPECT_EQ(read_splat_file(path, options).size(), 1000u);
}

TEST(SogFormat, TableSaysReadOnly) {
    EXPECT_EQ(splat_format_from_extension("/scans/Scene.SOG"), SplatFormat::Sog);
    EXPECT_EQ(splat_format_from_extension("/scans/unicorn/meta.json"), SplatFormat::Sog);
    EXPECT_EQ(splat_format_from_extension("/scans/unicorn.meta.json"), SplatFormat::Sog);
    expect_format_error([] { splat_format_from_extension("/scans/scene.json"); }, "scene.json", {"'.json'"});
    bool found = false;
    for (const SplatFormatInfo& f : splat_formats())
        if (f.format == SplatFormat::Sog) {
            found = true;
            EXPECT_FALSE(f.writable);
            EXPECT_STREQ(f.name, "sog");
        } else {
            // (glTF splats are read here too and written by the mesh export.)
            EXPECT_EQ(f.writable, f.format != SplatFormat::Gltf) << f.name;
        }
    EXPECT_TRUE(found);
    GaussianCloud cloud;
    cloud.resize(1, 0);
    cloud.rotations = {1, 0, 0, 0};
    const std::string out = tmp_path("read_only.sog");
    std::filesystem::remove(out);
    expect_format_error([&] { write_splat_file(out, cloud); }, "read_only.sog", {"SOG is read only"});
    EXPECT_FALSE(std::filesystem::exists(out));
}

// ---------------------------------------------------------------------------------------------------------------
// Scenes built here, checked against the specification's formulas evaluated in this test.

constexpr double kSqrt2 = 1.4142135623730951;

std::string good_meta_for_folder_test() {
    return sog_meta_v2(5, json_ramp(256, -10, 0.05), json_ramp(256, -2, 0.015625),
                       "{\"count\": 3, \"bands\": 1, \"codebook\": " + json_ramp(256, -0.5, 1.0 / 256) +
                           ", \"files\": [\"shN_centroids.webp\", \"shN_labels.webp\"]}");
}

double unlog(double n) { return (n < 0 ? -1.0 : 1.0) * (std::exp(std::fabs(n)) - 1.0); }

struct Built {
    std::vector<ZipMember> members;
    std::vector<unsigned> q[3];
};

// Five splats on 4 x 2 images; quats in all four modes; a 3-entry palette of 1 band.
Built build_scene(const std::string& meta, int shn_width = 192) {
    Built b;
    const int w = 4, h = 2, n = 5;
    RgbaImage lo(w, h), hi(w, h), quats(w, h), scales(w, h), sh0(w, h), labels(w, h), centroids(shn_width, 1);
    const unsigned qx[n] = {0, 65535, 32768, 1234, 60000};
    for (int i = 0; i < n; ++i) {
        const unsigned q[3] = {qx[i], 65535 - qx[i], qx[i] / 2};
        for (int a = 0; a < 3; ++a) b.q[a].push_back(q[a]);
        lo.set(std::size_t(i), std::uint8_t(q[0] & 255), std::uint8_t(q[1] & 255), std::uint8_t(q[2] & 255), 255);
        hi.set(std::size_t(i), std::uint8_t(q[0] >> 8), std::uint8_t(q[1] >> 8), std::uint8_t(q[2] >> 8), 255);
        quats.set(std::size_t(i), std::uint8_t(100 + 10 * i), std::uint8_t(140 - 10 * i), 128, std::uint8_t(252 + i % 4));
        scales.set(std::size_t(i), std::uint8_t(50 * i), std::uint8_t(20 * i + 3), std::uint8_t(255 - i), 255);
        sh0.set(std::size_t(i), std::uint8_t(i == 0 ? 0 : 30 * i), std::uint8_t(1 + i), 255, std::uint8_t(60 * i));
        labels.set(std::size_t(i), std::uint8_t(i % 3), 0, 0, 255);
    }
    for (int e = 0; e < 3; ++e)
        for (int k = 0; k < 3; ++k)
            centroids.set(std::size_t(e * 3 + k), std::uint8_t(e * 50 + k), std::uint8_t(100 + 7 * k), std::uint8_t(200 - 10 * e - k), 255);
    b.members = {{"meta.json", bytes_of(meta)},          {"means_l.webp", lo.webp()},     {"means_u.webp", hi.webp()},
                 {"quats.webp", quats.webp(), true},     {"scales.webp", scales.webp()}, {"sh0.webp", sh0.webp()},
                 {"shN_centroids.webp", centroids.webp()}, {"shN_labels.webp", labels.webp(), true}};
    return b;
}

GaussianCloud read_built(const std::vector<ZipMember>& members, const std::string& name) {
    const std::string path = tmp_path(name);
    write_bytes(path, make_zip(members));
    return read_sog(path);
}

// Byte values of build_scene, as the specification's formulas see them.
void expect_quats_and_palette(const GaussianCloud& c, const std::function<double(int)>& shn_value) {
    for (int i = 0; i < 5; ++i) {
        // [spec 3.2]: a = (byte / 255 - 0.5) sqrt 2; mode = A - 252 is the left-out (largest) of (w, x, y, z).
        const double kept[3] = {((100 + 10 * i) / 255.0 - 0.5) * kSqrt2, ((140 - 10 * i) / 255.0 - 0.5) * kSqrt2,
                                (128 / 255.0 - 0.5) * kSqrt2};
        const int mode = i % 4;
        double q[4];
        for (int k = 0, j = 0; k < 4; ++k)
            if (k != mode) q[k] = kept[j++];
        q[mode] = std::sqrt(1.0 - kept[0] * kept[0] - kept[1] * kept[1] - kept[2] * kept[2]);
        for (int k = 0; k < 4; ++k) EXPECT_NEAR(c.rotations[4 * std::size_t(i) + k], q[k], 1e-6) << "splat " << i << " component " << k;
        const int entry = i % 3;
        for (int k = 0; k < 3; ++k) {
            const int bytes[3] = {entry * 50 + k, 100 + 7 * k, 200 - 10 * entry - k};
            for (int ch = 0; ch < 3; ++ch)
                EXPECT_NEAR(c.sh[(std::size_t(i) * 4 + 1 + std::size_t(k)) * 3 + std::size_t(ch)], shn_value(bytes[ch]), 1e-6);
        }
    }
}

TEST(SogFormat, Version2DecodesAsTheSpecificationSays) {
    // sh0's codebook starts with null, which the engine replaces by cb[1] + (cb[1] - cb[255]) / 255.
    const std::string sh0_book = "[null, " + json_ramp(255, -2.0 + 0.015625, 0.015625).substr(1);
    const std::string meta = sog_meta_v2(5, json_ramp(256, -10, 0.05), sh0_book,
                                         "{\"count\": 3, \"bands\": 1, \"codebook\": " + json_ramp(256, -0.5, 1.0 / 256) +
                                             ", \"files\": [\"shN_centroids.webp\", \"shN_labels.webp\"]}");
    const Built b = build_scene(meta);
    const GaussianCloud c = read_built(b.members, "v2_by_spec.sog");
    ASSERT_EQ(c.size(), 5u);
    ASSERT_EQ(c.sh_degree, 1);
    const double mins[3] = {-1, -2, -3}, maxs[3] = {1, 2, 3};
    const auto sh0_value = [](int byte) {
        const double cb1 = -2.0 + 0.015625, cb255 = -2.0 + 255 * 0.015625;
        return byte == 0 ? cb1 + (cb1 - cb255) / 255.0 : -2.0 + byte * 0.015625;
    };
    for (int i = 0; i < 5; ++i) {
        for (int a = 0; a < 3; ++a) {
            // [spec 3.1]: n = lerp(min, max, q / 65535); x = sign(n) (exp|n| - 1).
            const double n = mins[a] + (maxs[a] - mins[a]) * (b.q[a][std::size_t(i)] / 65535.0);
            EXPECT_NEAR(c.positions[3 * std::size_t(i) + a], unlog(n), 1e-6 * std::max(1.0, std::fabs(unlog(n))));
        }
        const int scale_bytes[3] = {50 * i, 20 * i + 3, 255 - i};
        for (int a = 0; a < 3; ++a)
            EXPECT_NEAR(std::log(c.scales[3 * std::size_t(i) + a]), -10 + 0.05 * scale_bytes[a], 1e-5);
        const int dc_bytes[3] = {i == 0 ? 0 : 30 * i, 1 + i, 255};
        for (int ch = 0; ch < 3; ++ch) EXPECT_NEAR(c.sh[std::size_t(i) * 12 + std::size_t(ch)], sh0_value(dc_bytes[ch]), 1e-6);
        EXPECT_NEAR(c.opacities[std::size_t(i)], 60 * i / 255.0, 1e-7);  // [spec 3.4]: A / 255
    }
    expect_quats_and_palette(c, [](int byte) { return -0.5 + byte / 256.0; });
}

TEST(SogFormat, Version1DecodesAsSplatTransformAndTheEngineDo) {
    // Version 1: no "version", count = means.shape[0], per-channel mins / maxs instead of codebooks, opacity as a
    // lerped logit, shN scalar mins / maxs with the bands from the centroids' width (192: 1 band).
    const std::string meta =
        "{\"means\": {\"shape\": [5, 3], \"mins\": [-1, -2, -3], \"maxs\": [1, 2, 3], \"files\": [\"means_l.webp\", "
        "\"means_u.webp\"]}, \"scales\": {\"mins\": [-9, -8, -7], \"maxs\": [-1, 0, 1], \"files\": [\"scales.webp\"]}, "
        "\"quats\": {\"encoding\": \"quaternion_packed\", \"files\": [\"quats.webp\"]}, \"sh0\": {\"mins\": [-2, -3, -4, -6], "
        "\"maxs\": [2, 3, 4, 6], \"files\": [\"sh0.webp\"]}, \"shN\": {\"mins\": -0.75, \"maxs\": 0.5, \"files\": "
        "[\"shN_centroids.webp\", \"shN_labels.webp\"]}}";
    const Built b = build_scene(meta);
    LoadReport report;
    const std::string path = tmp_path("v1_by_spec.sog");
    write_bytes(path, make_zip(b.members));
    const GaussianCloud c = read_sog(path, {}, &report);
    ASSERT_EQ(c.size(), 5u);
    ASSERT_EQ(c.sh_degree, 1);
    EXPECT_EQ(probe_splat_file(path).sh_degree, 1);  // from the centroids' width, as there is no shN.shape
    const auto lerp = [](double lo, double hi, int byte) { return lo + (hi - lo) * (byte / 255.0); };
    const double smin[3] = {-9, -8, -7}, smax[3] = {-1, 0, 1}, cmin[4] = {-2, -3, -4, -6}, cmax[4] = {2, 3, 4, 6};
    for (int i = 0; i < 5; ++i) {
        const int scale_bytes[3] = {50 * i, 20 * i + 3, 255 - i};
        for (int a = 0; a < 3; ++a)
            EXPECT_NEAR(std::log(c.scales[3 * std::size_t(i) + a]), lerp(smin[a], smax[a], scale_bytes[a]), 1e-5);
        const int dc_bytes[3] = {i == 0 ? 0 : 30 * i, 1 + i, 255};
        for (int ch = 0; ch < 3; ++ch)
            EXPECT_NEAR(c.sh[std::size_t(i) * 12 + std::size_t(ch)], lerp(cmin[ch], cmax[ch], dc_bytes[ch]), 1e-6);
        EXPECT_NEAR(c.opacities[std::size_t(i)], sigmoid(lerp(cmin[3], cmax[3], 60 * i)), 1e-6);
    }
    expect_quats_and_palette(c, [&](int byte) { return lerp(-0.75, 0.5, byte); });
    ASSERT_FALSE(report.warnings.empty());
    EXPECT_NE(report.warnings.back().find("version 1"), std::string::npos);
}

TEST(SogFormat, BundleWithItsFilesInOneFolder) {
    // Some tools zip the scene's folder rather than its files: meta.json and the images under "unicorn/".
    std::vector<ZipMember> members = build_scene(good_meta_for_folder_test()).members;
    const GaussianCloud at_root = read_built(members, "files_at_root.sog");
    for (ZipMember& m : members) m.name = "unicorn/" + m.name;
    expect_same_cloud(read_built(members, "files_in_folder.sog"), at_root);
    members.push_back({"other/meta.json", bytes_of("{}")});
    const std::string path = tmp_path("two_folders.sog");
    write_bytes(path, make_zip(members));
    expect_format_error([&] { read_sog(path); }, path, {"no meta.json at its root, and several in folders"});
}

// ---------------------------------------------------------------------------------------------------------------
// Malformed scenes (the hostile files whose memory matters are in hostile_input_format_test.cpp).

std::string good_meta(const std::string& shn_codebook = json_ramp(256, -0.5, 1.0 / 256), const std::string& count = "3") {
    return sog_meta_v2(5, json_ramp(256, -10, 0.05), json_ramp(256, -2, 0.015625),
                       "{\"count\": " + count + ", \"bands\": 1, \"codebook\": " + shn_codebook +
                           ", \"files\": [\"shN_centroids.webp\", \"shN_labels.webp\"]}");
}

void expect_bundle_refused(const std::vector<ZipMember>& members, const std::string& name, const std::vector<std::string>& problems) {
    const std::string path = tmp_path(name);
    write_bytes(path, make_zip(members));
    expect_format_error([&] { read_splat_file(path); }, path, problems);
}

std::vector<ZipMember> with_meta(std::vector<ZipMember> members, const std::string& meta) {
    members[0].data = bytes_of(meta);
    return members;
}

TEST(SogFormat, MalformedMetaIsNamed) {
    const std::vector<ZipMember> good = build_scene(good_meta()).members;
    expect_bundle_refused(with_meta(good, "{\"version\": 2, \"count\": 5,"), "bad_json.sog", {"member 'meta.json'", "malformed JSON"});
    std::string nan_meta = good_meta();
    nan_meta.replace(nan_meta.find("[-1, -2, -3]"), 12, "[-1, NaN, -3]");
    expect_bundle_refused(with_meta(good, nan_meta), "nan_mins.sog", {"malformed JSON", "JSON has no NaN"});
    std::string null_meta = good_meta();
    null_meta.replace(null_meta.find("[1, 2, 3]"), 9, "[1, null, 3]");
    expect_bundle_refused(with_meta(good, null_meta), "null_maxs.sog", {"'means.maxs[1]' is null"});
    std::string huge_meta = good_meta();
    huge_meta.replace(huge_meta.find("[1, 2, 3]"), 9, "[1, 1e999, 3]");
    expect_bundle_refused(with_meta(good, huge_meta), "inf_maxs.sog", {"malformed JSON", "1e999"});
    std::string no_mins = good_meta();
    no_mins.replace(no_mins.find("\"mins\""), 6, "\"minz\"");
    expect_bundle_refused(with_meta(good, no_mins), "no_mins.sog", {"'means.mins' is missing"});
    std::string version3 = good_meta();
    version3.replace(version3.find("\"version\": 2"), 12, "\"version\": 3");
    expect_bundle_refused(with_meta(good, version3), "version3.sog", {"version 3 is not supported"});
    std::string escape = good_meta();
    escape.replace(escape.find("\"quats.webp\""), 12, "\"../quats.webp\"");
    expect_bundle_refused(with_meta(good, escape), "escape.sog", {"'quats.files[0]' is '../quats.webp'", "no '..'"});
    expect_bundle_refused(with_meta(good, std::string(100, '[') + std::string(100, ']')), "deep.sog", {"nested more than 64"});
    expect_bundle_refused(with_meta(good, good_meta(json_ramp(300, 0, 1))), "long_codebook.sog",
                          {"'shN.codebook' is not a list of 1 to 256 numbers"});
}

TEST(SogFormat, MissingFilesAndWrongImagesAreNamed) {
    const std::vector<ZipMember> good = build_scene(good_meta()).members;
    std::vector<ZipMember> no_quats = good;
    no_quats.erase(no_quats.begin() + 3);
    expect_bundle_refused(no_quats, "no_quats.sog", {"meta.json names 'quats.webp' (the quats image), which the bundle does not contain"});
    std::vector<ZipMember> no_meta(good.begin() + 1, good.end());
    expect_bundle_refused(no_meta, "no_meta.sog", {"no meta.json"});
    // An image too small for the count: 4 x 2 = 8 pixels for 9 splats.
    std::string nine = good_meta();
    nine.replace(nine.find("\"count\": 5"), 10, "\"count\": 9");
    expect_bundle_refused(with_meta(good, nine), "too_small.sog",
                          {"member 'means_l.webp'", "4 x 2 = 8 pixels, fewer than the 9 splats of meta.json's count"});
    std::vector<ZipMember> not_webp = good;
    not_webp[4].data = bytes_of("not an image at all");
    expect_bundle_refused(not_webp, "not_webp.sog", {"member 'scales.webp'", "not a WebP image"});
    // The centroids image must be 64 entries of 3 pixels wide for 1 band.
    expect_bundle_refused(build_scene(good_meta(), 96).members, "narrow_palette.sog",
                          {"member 'shN_centroids.webp'", "is 96 x 1", "needs 192 x 1"});
    const std::string path = tmp_path("not_a_zip.sog");
    write_text(path, "{\"version\": 2}");
    expect_format_error([&] { read_splat_file(path); }, path, {"not a SOG bundle", "zip"});
}

TEST(SogFormat, IndicesOutsideTheirTablesAreNamed) {
    // Labels 0, 1, 2, 0, 1 against a palette of 2 entries: splat 2 (pixel (2, 0)) is the first outside.
    expect_bundle_refused(build_scene(good_meta(json_ramp(256, -0.5, 1.0 / 256), "2")).members, "label.sog",
                          {"member 'shN_labels.webp'", "palette index 2 at pixel (2, 0) (splat 2)", "palette's 2 entries"});
    // A 100-entry shN codebook: the centroids hold bytes up to 200.
    expect_bundle_refused(build_scene(good_meta(json_ramp(100, 0, 0.01))).members, "shn_codebook.sog",
                          {"member 'shN_centroids.webp'", "outside the 100-entry shN codebook"});
    // A 16-entry scales codebook: splat 0's B is 255.
    std::string small_book = good_meta();
    small_book.replace(small_book.find(json_ramp(256, -10, 0.05)), json_ramp(256, -10, 0.05).size(), json_ramp(16, -10, 0.05));
    expect_bundle_refused(with_meta(build_scene(good_meta()).members, small_book), "scale_codebook.sog",
                          {"member 'scales.webp'", "index 255 at pixel (0, 0) (splat 0)", "16-entry scales codebook"});
    // A quats alpha below 252.
    std::vector<ZipMember> members = build_scene(good_meta()).members;
    RgbaImage quats(4, 2, 0xfc808080u);
    quats.set(3, 128, 128, 128, 17);
    members[3].data = quats.webp();
    expect_bundle_refused(members, "quats_alpha.sog", {"member 'quats.webp'", "alpha at pixel (3, 0) (splat 3) is 17", "252 to 255"});
}

}  // namespace
}  // namespace raysplats
