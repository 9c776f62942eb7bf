// Hostile splat files: each is refused with an error that says what is wrong, and refusing it costs
// little memory. Each file is read in a fresh process (this test binary re-run on one hidden test), because peak
// memory (VmHWM) is per process and a forked copy of a multi-threaded (TBB) process is not safe to use. The child
// also runs under an address-space limit, so that a regression (a reader allocating what the header claims)
// fails fast with std::bad_alloc instead of exhausting the machine.
#include <gtest/gtest.h>
#include <sys/resource.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <sstream>
#include <string>

#include "io/splat_formats.h"
#include "io_test_util.h"
#include "raysplats/errors.h"
#include "raysplats/splat_io.h"
#include "sog_test_util.h"

namespace raysplats {
namespace {

using namespace testutil;

constexpr const char* kFileVariable = "RAYSPLATS_HOSTILE_FILE";

// Under AddressSanitizer (scripts/test_sanitized.sh) the child cannot run under an address-space limit: ASan reserves
// terabytes of address space for its shadow memory at start. ASan's own cap on a single allocation stands in for it
// (read_in_child's ASAN_OPTIONS): a runaway allocation is then an ASan report, which fails the test as fast.
#if defined(__SANITIZE_ADDRESS__)
constexpr bool kAddressSanitizer = true;
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
constexpr bool kAddressSanitizer = true;
#else
constexpr bool kAddressSanitizer = false;
#endif
#else
constexpr bool kAddressSanitizer = false;
#endif
constexpr long kMaxPeakGrowthKb = 200 * 1024;  // 200 MB

long status_kb(const char* field) {
    std::ifstream in("/proc/self/status");
    std::string line;
    while (std::getline(in, line))
        if (line.rfind(field, 0) == 0) return std::atol(line.c_str() + std::strlen(field));
    return -1;
}

// The child: reads the file named by the environment and prints what happened and how much the peak resident
// memory grew while reading it.
TEST(HostileInputChild, DISABLED_ReadOneFile) {
    const char* path = std::getenv(kFileVariable);
    if (!path) GTEST_SKIP() << "expected: run by HostileInput tests only";
    if (!kAddressSanitizer) {
        rlimit limit{};
        limit.rlim_cur = limit.rlim_max = rlim_t(4) << 30;  // 4 GB of address space: a runaway allocation throws
        setrlimit(RLIMIT_AS, &limit);
    }
    std::ofstream("/proc/self/clear_refs") << "5";  // resets VmHWM to the current resident size
    const long before = status_kb("VmRSS:");
    std::string outcome;
    try {
        const GaussianCloud c = read_splat_file(path);
        outcome = "read " + std::to_string(c.size()) + " Gaussians";
    } catch (const FileFormatError& e) {
        outcome = std::string("FileFormatError: ") + e.what();
    } catch (const std::exception& e) {
        outcome = std::string("other exception: ") + e.what();
    }
    const long peak = status_kb("VmHWM:");
    std::printf("\nOUTCOME %s\nPEAK_GROWTH_KB %ld\n", outcome.c_str(), peak - before);
}

struct ChildResult {
    std::string outcome;
    long peak_growth_kb = -1;
};

ChildResult read_in_child(const std::string& path) {
    const char* asan_options = std::getenv("ASAN_OPTIONS");
    const std::string asan = kAddressSanitizer ? std::string("ASAN_OPTIONS='max_allocation_size_mb=4096:allocator_may_return_null=1:") +
                                                     (asan_options ? asan_options : "") + "' "
                                               : std::string();
    const std::string command = asan + std::string(kFileVariable) + "='" + path + "' /proc/" + std::to_string(getpid()) +
                                "/exe --gtest_also_run_disabled_tests --gtest_filter=HostileInputChild.DISABLED_ReadOneFile";
    FILE* pipe = popen(command.c_str(), "r");
    EXPECT_NE(pipe, nullptr);
    std::string output;
    char buffer[4096];
    while (pipe && std::fgets(buffer, sizeof buffer, pipe)) output += buffer;
    if (pipe) pclose(pipe);
    ChildResult r;
    std::istringstream lines(output);
    std::string line;
    while (std::getline(lines, line)) {
        if (line.rfind("OUTCOME ", 0) == 0) r.outcome = line.substr(8);
        if (line.rfind("PEAK_GROWTH_KB ", 0) == 0) r.peak_growth_kb = std::atol(line.c_str() + 15);
    }
    EXPECT_FALSE(r.outcome.empty()) << "child output:\n" << output;
    return r;
}

void expect_refused_cheaply(const std::string& path, const std::vector<std::string>& problems) {
    const ChildResult r = read_in_child(path);
    EXPECT_EQ(r.outcome.rfind("FileFormatError: ", 0), 0u) << r.outcome;
    EXPECT_NE(r.outcome.find(path), std::string::npos) << "message does not name the file: " << r.outcome;
    for (const std::string& p : problems) EXPECT_NE(r.outcome.find(p), std::string::npos) << "lacks '" << p << "': " << r.outcome;
    EXPECT_GE(r.peak_growth_kb, 0);
    EXPECT_LT(r.peak_growth_kb, kMaxPeakGrowthKb) << r.outcome;
    std::printf("  %s: %s (peak memory growth %ld kB)\n", path.substr(path.find_last_of('/') + 1).c_str(), r.outcome.c_str(),
                r.peak_growth_kb);
}

void put_u32(std::vector<std::uint8_t>& b, std::uint32_t v) {
    for (int i = 0; i < 4; ++i) b.push_back(std::uint8_t(v >> (8 * i)));
}
void put_u64(std::vector<std::uint8_t>& b, std::uint64_t v) {
    put_u32(b, std::uint32_t(v)), put_u32(b, std::uint32_t(v >> 32));
}

// 134 bytes: a v4 header claiming 100 M points of SH degree 1, a table of contents whose uncompressed sizes agree
// with that count, and six one-byte "streams". Before: the reader allocated and zeroed 6.5 GB first.
TEST(HostileInput, SpzV4TableOfContentsClaims100MPoints) {
    const std::uint64_t n = 100000000;
    const std::uint64_t sizes[6] = {n * 9, n, n * 3, n * 3, n * 4, n * 9};
    std::vector<std::uint8_t> b;
    put_u32(b, 0x5053474e), put_u32(b, 4), put_u32(b, std::uint32_t(n));
    b.push_back(1), b.push_back(12), b.push_back(0), b.push_back(6);
    put_u32(b, 32);
    b.resize(32, 0);
    for (std::uint64_t s : sizes) put_u64(b, 1), put_u64(b, s);
    for (int k = 0; k < 6; ++k) b.push_back(0x28);
    ASSERT_EQ(b.size(), 134u);
    const std::string path = tmp_path("hostile_100M_points.spz");
    write_bytes(path, b);
    expect_refused_cheaply(path, {"'positions'", "cannot hold the 100000000 points", "32768:1", "at byte 32"});
}

std::string gaussian_properties() {
    std::string h;
    for (const char* p : {"x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1", "scale_2", "rot_0",
                          "rot_1", "rot_2", "rot_3"})
        h += std::string("property float ") + p + "\n";
    return h;
}

// Before: `rest` was resized to 2^31 entries (8.4 GB) before the index was checked.
TEST(HostileInput, PlyRestIndexFarBeyondDegree3) {
    std::string text = "ply\nformat binary_little_endian 1.0\nelement vertex 1\n" + gaussian_properties() +
                       "property float f_rest_2147483646\nend_header\n";
    text += std::string(15 * 4, '\0');
    const std::string path = tmp_path("hostile_f_rest_index.ply");
    write_text(path, text);
    expect_refused_cheaply(path, {"'f_rest_2147483646'", "beyond SH degree 3", "f_rest_0..f_rest_44", "at byte 346"});
}

// Before: the count was read as a float and converted to an integer (undefined behaviour for 1e30), and the
// malformed file was accepted.
TEST(HostileInput, PlyListCountOfFloatType) {
    std::string text = "ply\nformat binary_little_endian 1.0\nelement face 1\nproperty list float int vertex_indices\n"
                       "element vertex 1\n" + gaussian_properties() + "end_header\n";
    const float huge = 1e30f;
    text.append(reinterpret_cast<const char*>(&huge), 4);
    text += std::string(14 * 4, '\0');
    const std::string path = tmp_path("hostile_float_list_count.ply");
    write_text(path, text);
    expect_refused_cheaply(path, {"list property 'vertex_indices' of element 'face'", "float count", "integer type",
                                  "at byte"});
    // The ASCII form of a fractional count is refused as well.
    const std::string ascii = tmp_path("hostile_fractional_list_count.ply");
    write_text(ascii, "ply\nformat ascii 1.0\nelement face 1\nproperty list uchar int vertex_indices\nelement vertex 1\n" +
                          gaussian_properties() + "end_header\n2.5 0 1\n" + std::string("0 0 0 0 0 0 0 0 0 0 1 0 0 0\n"));
    expect_format_error([&] { read_ply(ascii); }, "hostile_fractional_list_count.ply",
                        {"bad list count '2.5", "whole number", "'vertex_indices'"});
}

// Before: 2^64 - 1 records of nothing were skipped one by one (minutes at -O1/-O2).
TEST(HostileInput, PlyElementWithoutPropertiesAndHugeCount) {
    const std::string text = "ply\nformat ascii 1.0\nelement nothing 18446744073709551615\nelement vertex 1\n" +
                             gaussian_properties() + "end_header\n0 0 0 0 0 0 0 0 0 0 1 0 0 0\n";
    const std::string path = tmp_path("hostile_empty_element.ply");
    write_text(path, text);
    expect_refused_cheaply(path, {"element 'nothing' declares 18446744073709551615 records but no properties", "at byte 21"});
}

// A 300-byte .glb whose splat accessors claim a billion splats in a 16-byte buffer (so do its attributes sharing one
// accessor, which the extension allows), and one whose buffer claims 4 GiB in a 16-byte BIN chunk: refused before
// any splat is allocated.
std::string minimal_splat_glb(std::uint64_t count, std::uint64_t buffer_length) {
    const std::string json =
        "{\"asset\":{\"version\":\"2.0\"},\"extensionsUsed\":[\"KHR_gaussian_splatting\"],"
        "\"buffers\":[{\"byteLength\":" + std::to_string(buffer_length) + "}],"
        "\"bufferViews\":[{\"buffer\":0,\"byteLength\":16}],"
        "\"accessors\":[{\"bufferView\":0,\"componentType\":5126,\"count\":" + std::to_string(count) + ",\"type\":\"VEC3\"},"
        "{\"bufferView\":0,\"componentType\":5126,\"count\":" + std::to_string(count) + ",\"type\":\"VEC4\"},"
        "{\"bufferView\":0,\"componentType\":5126,\"count\":" + std::to_string(count) + ",\"type\":\"SCALAR\"}],"
        "\"meshes\":[{\"primitives\":[{\"mode\":0,\"attributes\":{\"POSITION\":0,"
        "\"KHR_gaussian_splatting:ROTATION\":1,\"KHR_gaussian_splatting:SCALE\":0,\"KHR_gaussian_splatting:OPACITY\":2,"
        "\"KHR_gaussian_splatting:SH_DEGREE_0_COEF_0\":0},"
        "\"extensions\":{\"KHR_gaussian_splatting\":{\"kernel\":\"ellipse\",\"colorSpace\":\"srgb_rec709_display\"}}}]}],"
        "\"nodes\":[{\"mesh\":0}],\"scenes\":[{\"nodes\":[0]}],\"scene\":0}";
    std::string padded = json;
    while (padded.size() % 4) padded += ' ';
    std::vector<std::uint8_t> b;
    b.insert(b.end(), {'g', 'l', 'T', 'F'});
    put_u32(b, 2), put_u32(b, std::uint32_t(12 + 8 + padded.size() + 8 + 16));
    put_u32(b, std::uint32_t(padded.size())), put_u32(b, 0x4E4F534Au);
    b.insert(b.end(), padded.begin(), padded.end());
    put_u32(b, 16), put_u32(b, 0x004E4942u);
    b.resize(b.size() + 16, 0);
    return std::string(b.begin(), b.end());
}

TEST(HostileInput, GltfAccessorsClaimABillionSplatsInSixteenBytes) {
    const std::string path = tmp_path("hostile_billion_splats.glb");
    write_text(path, minimal_splat_glb(1000000000, 16));
    expect_refused_cheaply(path, {"POSITION", "1000000000 elements do not fit in its bufferView of 16 bytes"});
    // The same file with one splat is read: the refusal above is the count's, not the layout's.
    write_text(path, minimal_splat_glb(1, 16));
    EXPECT_EQ(read_splat_file(path).size(), 1u);
}

TEST(HostileInput, GltfBufferClaimsMoreThanItsBinChunk) {
    const std::string path = tmp_path("hostile_gltf_buffer.glb");
    write_text(path, minimal_splat_glb(1, std::uint64_t(1) << 32));
    expect_refused_cheaply(path, {"not a valid glTF file"});
}

// A SuperSplat compressed PLY of 600 bytes whose header claims 100 M splats: refused at the chunk table, before any allocation.
TEST(HostileInput, CompressedPlyClaims100MSplats) {
    std::string text = "ply\nformat binary_little_endian 1.0\nelement chunk 390625\n";
    for (const char* p : {"min_x", "min_y", "min_z", "max_x", "max_y", "max_z", "min_scale_x", "min_scale_y", "min_scale_z",
                          "max_scale_x", "max_scale_y", "max_scale_z"})
        text += std::string("property float ") + p + "\n";
    text += "element vertex 100000000\nproperty uint packed_position\nproperty uint packed_rotation\n"
            "property uint packed_scale\nproperty uint packed_color\nend_header\n";
    text += std::string(64, '\0');
    const std::string path = tmp_path("hostile_100M_splats.compressed.ply");
    write_text(path, text);
    expect_refused_cheaply(path, {"file is truncated", "element 'chunk' declares 390625 records of 48 bytes",
                                  "only 64 bytes follow"});
}

// --- PlayCanvas SOG (native/src/io/sog_format.cpp): a zip of meta.json and WebP images.

std::vector<ZipMember> sog_members(std::size_t count) {
    return small_sog_members(count, 4, 2, sog_meta_v2(count, json_ramp(256, -10, 0.05), json_ramp(256, -2, 0.015625)));
}

std::string write_sog(const std::string& name, const std::vector<ZipMember>& members) {
    const std::string path = tmp_path(name);
    write_bytes(path, make_zip(members));
    return path;
}

// 1.3 kB: meta.json deflated, claiming 4 GB uncompressed. Refused from the zip's directory, before any allocation.
TEST(HostileInput, SogMemberClaims4GB) {
    std::vector<ZipMember> members = sog_members(5);
    members[0].deflate = true;
    members[0].claimed_size = 4000000000LL;
    const std::string path = write_sog("hostile_claims_4GB.sog", members);
    expect_refused_cheaply(path, {"member 'meta.json'", "claims 4000000000 bytes, more than meta.json can need (1048576)"});
}

// A means image claiming 1.5 MB (as much as 1000 splats may need) from its ~100 deflated bytes: more than deflate
// can expand.
TEST(HostileInput, SogMemberClaimsMoreThanDeflateExpands) {
    std::vector<ZipMember> members =
        small_sog_members(1000, 32, 32, sog_meta_v2(1000, json_ramp(256, -10, 0.05), json_ramp(256, -2, 0.015625)));
    members[1].deflate = true;
    members[1].claimed_size = 1500000;
    const std::string path = write_sog("hostile_deflate_ratio.sog", members);
    expect_refused_cheaply(path, {"member 'means_l.webp'", "claims 1500000 bytes from", "1032:1", "zip bomb"});
}

// A true zip bomb: 16 MB of spaces as meta.json, deflated to 16 kB, sizes honest. Refused at its claimed size.
TEST(HostileInput, SogDeflateBombAsMeta) {
    std::vector<ZipMember> members = sog_members(5);
    members[0].data.assign(std::size_t(16) << 20, ' ');
    members[0].deflate = true;
    const std::string path = write_sog("hostile_deflate_bomb.sog", members);
    EXPECT_LT(read_bytes(path).size(), 40000u);
    expect_refused_cheaply(path, {"member 'meta.json'", "claims 16777216 bytes, more than meta.json can need"});
}

// 42-byte WebPs whose VP8L headers claim 16383 x 16383 pixels (1 GB of RGBA), for a meta.json count of 150 M splats
// (35 GB of cloud at SH degree 3): refused from the headers, since no lossless WebP of 42 bytes holds that.
TEST(HostileInput, SogWebpHeaderClaims16383Squared) {
    ByteVector webp = bytes_of("RIFF");
    put32(webp, 34);
    const std::string tag = "WEBPVP8L";
    webp.insert(webp.end(), tag.begin(), tag.end());
    put32(webp, 21);
    webp.push_back(0x2f);
    put32(webp, 16382u | (16382u << 14));  // width - 1, height - 1 (14 bits each), no alpha, version 0
    webp.resize(42, 0);
    std::vector<ZipMember> members = sog_members(5);
    members[0].data = bytes_of(sog_meta_v2(150000000, json_ramp(256, -10, 0.05), json_ramp(256, -2, 0.015625)));
    members[1].data = members[2].data = webp;
    const std::string path = write_sog("hostile_webp_dimensions.sog", members);
    expect_refused_cheaply(path, {"member 'means_l.webp'", "16383 x 16383", "more than a lossless WebP of 42 bytes can hold"});
}

// meta.json claims 100 M splats for 4 x 2 images: refused before the cloud (23.6 GB) is allocated.
TEST(HostileInput, SogCountBeyondItsImages) {
    std::vector<ZipMember> members = sog_members(5);
    members[0].data = bytes_of(sog_meta_v2(100000000, json_ramp(256, -10, 0.05), json_ramp(256, -2, 0.015625)));
    const std::string path = write_sog("hostile_sog_count.sog", members);
    expect_refused_cheaply(path, {"member 'means_l.webp'", "4 x 2 = 8 pixels, fewer than the 100000000 splats"});
}

}  // namespace
}  // namespace raysplats
