// Niantic .spz: the real v4 file decoded independently here (zstd + the reference formulas), synthetic v2 and
// v3 gzip files encoded here, round trips and cross-format checks within the format's quantisation.
#include <gtest/gtest.h>
#include <zlib.h>
#include <zstd.h>

#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>

#include "io/splat_formats.h"
#include "io_test_util.h"
#include "raysplats/errors.h"
#include "raysplats/splat_io.h"

namespace raysplats {
namespace {

using namespace testutil;

std::uint32_t u32(const std::uint8_t* p) { std::uint32_t v; std::memcpy(&v, p, 4); return v; }
std::uint64_t u64(const std::uint8_t* p) { std::uint64_t v; std::memcpy(&v, p, 8); return v; }

// Reference decoding formulas (nianticlabs/spz unpackGaussians), written out independently of the library.
float ref_position(const std::uint8_t* p, int fbits) {
    std::int32_t v = p[0] | (p[1] << 8) | (p[2] << 16);
    if (v & 0x800000) v |= std::int32_t(0xff000000u);
    return float(v) / float(1 << fbits);
}
double ref_dc(std::uint8_t b) { return (b / 255.0 - 0.5) / 0.15; }
double ref_scale(std::uint8_t b) { return std::exp(b / 16.0 - 10.0); }
double ref_alpha(std::uint8_t b) { return b / 255.0; }  // sigmoid(invSigmoid(b / 255))
double ref_sh(std::uint8_t b) { return (b - 128.0) / 128.0; }
void ref_rotation_v3(const std::uint8_t* r, double wxyz[4]) {
    std::uint32_t comp = u32(r);
    const unsigned largest = comp >> 30;
    double xyzw[4], ss = 0;
    for (int i = 3; i >= 0; --i) {
        if (unsigned(i) == largest) continue;
        const double mag = comp & 511u;
        const bool neg = (comp >> 9) & 1u;
        comp >>= 10;
        xyzw[i] = (neg ? -1 : 1) * std::sqrt(0.5) * mag / 511.0;
        ss += xyzw[i] * xyzw[i];
    }
    xyzw[largest] = std::sqrt(std::max(0.0, 1.0 - ss));
    wxyz[0] = xyzw[3], wxyz[1] = xyzw[0], wxyz[2] = xyzw[1], wxyz[3] = xyzw[2];
}

// SPZ stores RUB, the core RDF: the reader and writer rotate 180° about x, F = diag(1, -1, -1). Written out
// here from the real SH basis of the reference 3DGS (sh_utils.py), not from the library's SH rotation: under
// (x, y, z) -> (x, -y, -z) a basis function changes sign when it is odd in y and z together:
//   l=1: y, z, x                                                  -> -, -, +
//   l=2: xy, yz, 3z^2-1, xz, x^2-y^2                              -> -, +, +, -, +
//   l=3: y(3x^2-y^2), xyz, y(5z^2-1), z(5z^2-3), x(5z^2-1), z(x^2-y^2), x(x^2-3y^2) -> -, +, -, -, +, -, +
constexpr float kAxisFlip[3] = {1, -1, -1};
constexpr float kShFlip[16] = {1, -1, -1, 1, -1, 1, 1, -1, 1, -1, 1, -1, -1, 1, -1, 1};
// RDF quaternion of a stored RUB one (w x y z): F R F, i.e. y and z negated (the reference's convertCoordinates).
void rub_to_rdf_quaternion(double q[4]) { q[2] = -q[2], q[3] = -q[3]; }

struct RawSpzV4 {
    std::uint32_t version = 0, n = 0;
    int degree = 0, fbits = 0, streams = 0;
    std::vector<std::vector<std::uint8_t>> s;  // decompressed streams in file order
};

RawSpzV4 decode_v4(const std::string& path) {
    const auto b = read_bytes(path);
    RawSpzV4 r;
    EXPECT_EQ(std::memcmp(b.data(), "NGSP", 4), 0);
    r.version = u32(&b[4]);
    r.n = u32(&b[8]);
    r.degree = b[12];
    r.fbits = b[13];
    r.streams = b[15];
    const std::uint32_t toc = u32(&b[16]);
    std::size_t off = toc + std::size_t(r.streams) * 16;
    for (int k = 0; k < r.streams; ++k) {
        const std::uint64_t cs = u64(&b[toc + 16 * k]), us = u64(&b[toc + 16 * k + 8]);
        std::vector<std::uint8_t> out(us);
        const std::size_t got = ZSTD_decompress(out.data(), out.size(), &b[off], cs);
        EXPECT_EQ(got, us);
        r.s.push_back(std::move(out));
        off += cs;
    }
    EXPECT_EQ(off, b.size());
    return r;
}

TEST(SpzFormat, BikerV4MatchesIndependentDecode) {
    const std::string path = data_path("biker_v4.spz");
    const RawSpzV4 raw = decode_v4(path);
    ASSERT_EQ(raw.version, 4u);
    ASSERT_EQ(raw.n, 152746u);
    ASSERT_EQ(raw.streams, 5);
    const GaussianCloud c = read_spz(path);
    ASSERT_EQ(c.size(), 152746u);
    EXPECT_EQ(c.sh_degree, 0);
    for (std::size_t i : sample_indices(c.size())) {
        SCOPED_TRACE(i);
        for (int j = 0; j < 3; ++j)
            EXPECT_EQ(c.positions[3 * i + j], kAxisFlip[j] * ref_position(&raw.s[0][(3 * i + j) * 3], raw.fbits));
        EXPECT_NEAR(c.opacities[i], ref_alpha(raw.s[1][i]), 1e-6);
        for (int j = 0; j < 3; ++j) EXPECT_NEAR(c.sh[3 * i + j], ref_dc(raw.s[2][3 * i + j]), 1e-5);
        for (int j = 0; j < 3; ++j) {
            const double want = ref_scale(raw.s[3][3 * i + j]);
            EXPECT_NEAR(c.scales[3 * i + j], want, 1e-6 * want);
        }
        double q[4];
        ref_rotation_v3(&raw.s[4][4 * i], q);
        rub_to_rdf_quaternion(q);
        for (int j = 0; j < 4; ++j) EXPECT_NEAR(c.rotations[4 * i + j], q[j], 1e-5);
    }
    // Plausible values: a real scene of bounded extent, small Gaussians, a spread of opacities.
    double lo[3] = {1e30, 1e30, 1e30}, hi[3] = {-1e30, -1e30, -1e30}, mean_scale = 0, mean_alpha = 0;
    for (std::size_t i = 0; i < c.size(); ++i) {
        for (int j = 0; j < 3; ++j) lo[j] = std::min(lo[j], double(c.positions[3 * i + j])), hi[j] = std::max(hi[j], double(c.positions[3 * i + j]));
        mean_scale += c.scales[3 * i] / double(c.size());
        mean_alpha += c.opacities[i] / double(c.size());
    }
    for (int j = 0; j < 3; ++j) {
        EXPECT_GT(hi[j] - lo[j], 0.1);
        EXPECT_LT(hi[j] - lo[j], 1000.0);
    }
    EXPECT_GT(mean_scale, 1e-4);
    EXPECT_LT(mean_scale, 1.0);
    EXPECT_GT(mean_alpha, 0.05);
    EXPECT_LT(mean_alpha, 1.0);
    EXPECT_EQ(read_splat_file(path).positions, c.positions);  // content dispatch: NGSP magic
}

// ---------------------------------------------------------------------------------------------------------
// Synthetic gzip files, versions 2 and 3, encoded here.

std::vector<std::uint8_t> gzip(const std::vector<std::uint8_t>& in) {
    z_stream z{};
    EXPECT_EQ(deflateInit2(&z, 6, Z_DEFLATED, 16 + MAX_WBITS, 8, Z_DEFAULT_STRATEGY), Z_OK);
    std::vector<std::uint8_t> out(deflateBound(&z, uLong(in.size())) + 64);
    z.next_in = const_cast<Bytef*>(in.data());
    z.avail_in = uInt(in.size());
    z.next_out = out.data();
    z.avail_out = uInt(out.size());
    EXPECT_EQ(deflate(&z, Z_FINISH), Z_STREAM_END);
    out.resize(z.total_out);
    deflateEnd(&z);
    return out;
}

// Two splats, SH degree 1, with hand-picked bytes.
std::vector<std::uint8_t> legacy_payload(int version, std::uint32_t declared_n = 2) {
    const int n = 2, fbits = 10;
    std::vector<std::uint8_t> p;
    auto put32 = [&](std::uint32_t v) { for (int i = 0; i < 4; ++i) p.push_back(std::uint8_t(v >> (8 * i))); };
    put32(0x5053474e), put32(std::uint32_t(version)), put32(declared_n);
    p.push_back(1), p.push_back(fbits), p.push_back(0), p.push_back(0);
    const std::int32_t pos[6] = {1024, -2048, 5, -1, 300000, -8388608};
    for (std::int32_t v : pos) p.push_back(std::uint8_t(v)), p.push_back(std::uint8_t(v >> 8)), p.push_back(std::uint8_t(v >> 16));
    p.push_back(255), p.push_back(51);                              // alphas
    for (int v : {128, 0, 255, 77, 178, 10}) p.push_back(std::uint8_t(v));   // colours
    for (int v : {160, 0, 255, 144, 100, 96}) p.push_back(std::uint8_t(v));  // scales
    if (version == 2) {
        for (int v : {128, 128, 128, 255, 128, 128}) p.push_back(std::uint8_t(v));  // (0,0,0)->w=1 ; x~1
    } else {
        // splat 0: identity (largest = w, index 3; others 0); splat 1: largest = y (index 1), x = -0.5 (negative), z = 0, w = 0.5.
        const std::uint32_t c0 = 3u << 30;
        const std::uint32_t mag = std::uint32_t(std::floor(511 * (0.5 / std::sqrt(0.5)) + 0.5));
        const std::uint32_t c1 = (((((1u << 10) | (1u << 9) | mag) << 10) | 0u) << 10) | mag;  // x, then z, then w
        put32(c0), put32(c1);
    }
    for (int i = 0; i < n * 9; ++i) p.push_back(std::uint8_t(i * 13));  // SH degree 1: 3 coefficients x rgb
    return p;
}

void check_legacy(const GaussianCloud& c, int version) {
    ASSERT_EQ(c.size(), 2u);
    ASSERT_EQ(c.sh_degree, 1);
    const float want_pos[6] = {1.0f, -2.0f, 5 / 1024.0f, -1 / 1024.0f, 300000 / 1024.0f, -8192.0f};
    for (int j = 0; j < 6; ++j) EXPECT_EQ(c.positions[j], kAxisFlip[j % 3] * want_pos[j]) << j;
    EXPECT_NEAR(c.opacities[0], 1.0, 1e-6);
    EXPECT_NEAR(c.opacities[1], 0.2, 1e-6);
    const int colours[6] = {128, 0, 255, 77, 178, 10};
    for (int i = 0; i < 2; ++i)
        for (int ch = 0; ch < 3; ++ch) EXPECT_NEAR(c.sh[i * 12 + ch], ref_dc(std::uint8_t(colours[3 * i + ch])), 1e-5);
    const int scales[6] = {160, 0, 255, 144, 100, 96};
    for (int j = 0; j < 6; ++j) EXPECT_NEAR(c.scales[j], ref_scale(std::uint8_t(scales[j])), 1e-6 * ref_scale(std::uint8_t(scales[j])));
    for (int i = 0; i < 2; ++i)
        for (int k = 0; k < 9; ++k)
            EXPECT_NEAR(c.sh[i * 12 + 3 + k], kShFlip[1 + k / 3] * ref_sh(std::uint8_t((i * 9 + k) * 13)), 1e-6) << i << " " << k;
    if (version == 2) {
        // Reference v2 decoding: x,y,z = byte/127.5 - 1, w = sqrt(max(0, 1 - |xyz|^2)); we then normalise.
        const int rb[2][3] = {{128, 128, 128}, {255, 128, 128}};
        for (int i = 0; i < 2; ++i) {
            double q[4] = {0, rb[i][0] / 127.5 - 1, rb[i][1] / 127.5 - 1, rb[i][2] / 127.5 - 1};
            q[0] = std::sqrt(std::max(0.0, 1 - (q[1] * q[1] + q[2] * q[2] + q[3] * q[3])));
            rub_to_rdf_quaternion(q);
            const double nq = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
            for (int j = 0; j < 4; ++j) EXPECT_NEAR(c.rotations[4 * i + j], q[j] / nq, 1e-6) << i << " " << j;
        }
        EXPECT_NEAR(c.rotations[0], 1.0, 1e-4);
        EXPECT_NEAR(c.rotations[5], 1.0, 1e-4);
    } else {
        EXPECT_NEAR(c.rotations[0], 1.0, 1e-6);
        const double m = std::floor(511 * (0.5 / std::sqrt(0.5)) + 0.5) / 511 * std::sqrt(0.5);
        const double y = std::sqrt(1 - 2 * m * m);
        const double nq = std::sqrt(2 * m * m + y * y);
        EXPECT_NEAR(c.rotations[4], m / nq, 1e-5);   // w
        EXPECT_NEAR(c.rotations[5], -m / nq, 1e-5);  // x
        EXPECT_NEAR(c.rotations[6], -y / nq, 1e-5);  // y (negated: RUB -> RDF)
        EXPECT_NEAR(c.rotations[7], 0.0, 1e-6);      // z
    }
}

TEST(SpzFormat, GzipVersion2) {
    const std::string path = tmp_path("synthetic_v2.spz");
    write_bytes(path, gzip(legacy_payload(2)));
    check_legacy(read_spz(path), 2);
    check_legacy(read_splat_file(path), 2);
}

TEST(SpzFormat, GzipVersion3) {
    const std::string path = tmp_path("synthetic_v3.spz");
    write_bytes(path, gzip(legacy_payload(3)));
    check_legacy(read_spz(path), 3);
}

// ---------------------------------------------------------------------------------------------------------
// Writing (version 4), round trips and cross-format agreement.

// Quantisation steps of SPZ: position 2^-fractionalBits (12 -> error <= 1/8192), alpha 1/255, colour
// 1/(255*0.15) in dc (error <= 0.0131), log scale 1/16 (error <= 1/32 in log, range [-10, 5.94]),
// SH (x*128 rounded, error <= 1/256 on [-1, 127/128]), rotation 9-bit smallest three.
void expect_within_spz_quantisation(const GaussianCloud& a, const GaussianCloud& b) {
    ASSERT_EQ(b.size(), a.size());
    ASSERT_EQ(b.sh_degree, a.sh_degree);
    const int K = a.coeffs_per_channel();
    for (std::size_t i = 0; i < a.size(); ++i) {
        for (int j = 0; j < 3; ++j) ASSERT_NEAR(b.positions[3 * i + j], a.positions[3 * i + j], 1.0 / 8192 + 1e-6) << i;
        ASSERT_NEAR(b.opacities[i], a.opacities[i], 0.5 / 255 + 1e-6) << i;
        for (int j = 0; j < 3; ++j) {
            const double la = std::min(std::max(std::log(double(a.scales[3 * i + j])), -10.0), 255 / 16.0 - 10.0);
            ASSERT_NEAR(std::log(double(b.scales[3 * i + j])), la, 1.0 / 32 + 1e-5) << i;
        }
        for (int ch = 0; ch < 3; ++ch) {
            const double dc = std::min(std::max(double(a.sh[i * K * 3 + ch]), -0.5 / 0.15), 0.5 / 0.15);
            ASSERT_NEAR(b.sh[i * K * 3 + ch], dc, 0.5 / (255 * 0.15) + 1e-5) << i;
        }
        for (int k = 3; k < K * 3; ++k) {
            const double v = std::min(std::max(double(a.sh[i * K * 3 + k]), -1.0), 127.0 / 128);
            ASSERT_NEAR(b.sh[i * K * 3 + k], v, 1.0 / 256 + 1e-6) << i << " " << k;
        }
        double dot = 0;
        for (int j = 0; j < 4; ++j) dot += double(a.rotations[4 * i + j]) * b.rotations[4 * i + j];
        ASSERT_GT(std::fabs(dot), 1.0 - 5e-6) << i;
    }
}

TEST(SpzFormat, PlyToSpzV4AgreesWithinQuantisation) {
    for (const char* name : {"small_sh3_inria.ply", "unicorn_sh3_reordered.ply", "donut_sh0.ply"}) {
        SCOPED_TRACE(name);
        const GaussianCloud a = read_ply(data_path(name));
        const std::string out = tmp_path(std::string(name) + ".spz");
        write_spz(out, a);
        const RawSpzV4 raw = decode_v4(out);  // what we wrote is a well-formed v4 file
        EXPECT_EQ(raw.version, 4u);
        EXPECT_EQ(raw.n, a.size());
        EXPECT_EQ(raw.degree, a.sh_degree);
        EXPECT_EQ(raw.fbits, 12);
        EXPECT_EQ(raw.streams, a.sh_degree > 0 ? 6 : 5);
        expect_within_spz_quantisation(a, read_spz(out));
    }
}

TEST(SpzFormat, SpzRoundTripIsStable) {
    const GaussianCloud a = read_spz(data_path("biker_v4.spz"));
    const std::string out = tmp_path("biker_roundtrip.spz");
    write_splat_file(out, a);
    const GaussianCloud b = read_spz(out);
    ASSERT_EQ(b.size(), a.size());
    // Values already on the grid come back exactly (positions, colours, alphas, scales).
    EXPECT_EQ(b.positions, a.positions);
    EXPECT_EQ(b.opacities, a.opacities);
    for (std::size_t k = 0; k < a.sh.size(); ++k) ASSERT_NEAR(b.sh[k], a.sh[k], 1e-5);
    for (std::size_t k = 0; k < a.scales.size(); ++k) ASSERT_NEAR(b.scales[k], a.scales[k], 1e-5 * a.scales[k]);
    for (std::size_t i = 0; i < a.size(); ++i) {
        double dot = 0;
        for (int j = 0; j < 4; ++j) dot += double(a.rotations[4 * i + j]) * b.rotations[4 * i + j];
        ASSERT_GT(std::fabs(dot), 1.0 - 5e-6) << i;
    }
}

// The bytes we write are RUB: each stored value is the RDF cloud's, rotated 180° about x, decoded here
// independently (zstd + the reference formulas + the sign table above), not with the library's reader.
TEST(SpzFormat, WriterStoresRub) {
    const GaussianCloud a = read_ply(data_path("small_sh3_inria.ply"));
    const std::string out = tmp_path("small_sh3_rub.spz");
    write_spz(out, a);
    const RawSpzV4 raw = decode_v4(out);
    ASSERT_EQ(raw.degree, 3);
    for (std::size_t i = 0; i < a.size(); i += 97) {
        SCOPED_TRACE(i);
        for (int j = 0; j < 3; ++j)
            ASSERT_NEAR(ref_position(&raw.s[0][(3 * i + j) * 3], raw.fbits), kAxisFlip[j] * a.positions[3 * i + j], 0.5 / 4096 + 1e-7);
        double q[4];
        ref_rotation_v3(&raw.s[4][4 * i], q);
        double dot = q[0] * a.rotations[4 * i] + q[1] * a.rotations[4 * i + 1] - q[2] * a.rotations[4 * i + 2] - q[3] * a.rotations[4 * i + 3];
        ASSERT_GT(std::fabs(dot), 1.0 - 5e-6);
        for (int k = 1; k < 16; ++k)
            for (int ch = 0; ch < 3; ++ch) {
                const double want = std::min(std::max(kShFlip[k] * double(a.sh[(i * 16 + k) * 3 + ch]), -1.0), 127.0 / 128);
                ASSERT_NEAR(ref_sh(raw.s[5][(i * 15 + (k - 1)) * 3 + ch]), want, 1.0 / 256 + 1e-6) << k;
            }
    }
}

// "Upright": the scene's vertical extent keeps its sign. small_sh3_inria's ground is at +y (RDF: y down), so most
// of its Gaussians are below... whichever way it is, the mean y of a chain's output must equal the source's.
void expect_same_scene(const GaussianCloud& a, const GaussianCloud& b, double position_tolerance) {
    ASSERT_EQ(a.size(), b.size());
    double mean_a = 0, mean_b = 0;
    for (std::size_t i = 0; i < a.size(); ++i) {
        for (int j = 0; j < 3; ++j) ASSERT_NEAR(b.positions[3 * i + j], a.positions[3 * i + j], position_tolerance) << i;
        mean_a += a.positions[3 * i + 1], mean_b += b.positions[3 * i + 1];
    }
    EXPECT_NEAR(mean_b, mean_a, position_tolerance * double(a.size()));
}

// ply -> spz -> ply and spz -> ply -> spz: positions within the fixed point's half step, nothing flipped (before:
// the .spz written from a .ply opened upside down, and y and z of every position came back negated).
TEST(SpzFormat, ConversionChainsKeepTheSceneUpright) {
    const GaussianCloud ply = read_ply(data_path("small_sh3_inria.ply"));
    const std::string spz = tmp_path("chain.spz"), ply2 = tmp_path("chain.ply");
    write_spz(spz, ply);
    write_ply(ply2, read_spz(spz));
    const RawPly raw(ply2);  // the second .ply, read independently
    for (std::size_t i = 0; i < ply.size(); ++i)
        for (int j = 0; j < 3; ++j) ASSERT_NEAR(raw.get(i, j == 0 ? "x" : j == 1 ? "y" : "z"), ply.positions[3 * i + j], 0.5 / 4096 + 1e-6);
    expect_same_scene(ply, read_ply(ply2), 0.5 / 4096 + 1e-6);

    // spz -> ply -> spz: positions, alphas, colours and scales come back byte for byte, and so does every
    // rotation (the 9-bit smallest-three encoding is re-derived from the decoded quaternion).
    const std::string biker = data_path("biker_v4.spz"), via = tmp_path("biker_via.ply"), back = tmp_path("biker_back.spz");
    write_ply(via, read_spz(biker));
    write_spz(back, read_ply(via));
    const RawSpzV4 src = decode_v4(biker), dst = decode_v4(back);
    ASSERT_EQ(src.streams, dst.streams);
    ASSERT_EQ(src.fbits, dst.fbits);
    static const char* const names[5] = {"positions", "alphas", "colours", "scales", "rotations"};
    for (int k = 0; k < src.streams; ++k) {
        std::size_t differ = 0;
        for (std::size_t b = 0; b < src.s[k].size(); ++b) differ += src.s[k][b] != dst.s[k][b];
        EXPECT_EQ(differ, 0u) << names[k] << " bytes that differ, of " << src.s[k].size();
    }
}

// PlayCanvas splat-transform, the reference converter, must read our .spz as the scene we wrote, and we must read
// its .spz as the scene it converted. Found at $RAYSPLATS_SPLAT_TRANSFORM or in the npm test-tool folder
// ($RAYSPLATS_NPM_DIR, default ~/.cache/raysplats/npm: `npm install --prefix DIR @playcanvas/splat-transform`);
// skipped when absent (no network in tests).
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

TEST(SpzFormat, SplatTransformAgreesOnOrientation) {
    const std::string tool = splat_transform();
    if (tool.empty())
        GTEST_SKIP() << "splat-transform not installed (set RAYSPLATS_SPLAT_TRANSFORM or install @playcanvas/splat-transform "
                        "into the npm test-tool folder)";
    const GaussianCloud a = read_ply(data_path("small_sh3_inria.ply"));
    const std::string ours = tmp_path("for_splat_transform.spz"), theirs_ply = tmp_path("splat_transform_of_ours.ply"),
                      theirs_spz = tmp_path("splat_transform_of_ply.spz");
    write_spz(ours, a);
    for (const auto& [in, out] : {std::pair<std::string, std::string>{ours, theirs_ply}, {data_path("small_sh3_inria.ply"), theirs_spz}}) {
        const std::string command = "timeout 120 '" + tool + "' -w '" + in + "' '" + out + "' > /dev/null 2>&1";
        ASSERT_EQ(std::system(command.c_str()), 0) << command;
    }
    for (const std::string& path : {theirs_ply, theirs_spz}) {
        SCOPED_TRACE(path);
        const GaussianCloud b = read_splat_file(path);
        ASSERT_EQ(b.size(), a.size());
        double ab = 0, aa = 0, bb = 0;
        for (std::size_t i = 0; i < a.size(); ++i) {
            for (int j = 0; j < 3; ++j) ASSERT_NEAR(b.positions[3 * i + j], a.positions[3 * i + j], 2.0 / 4096) << i;
            double dot = 0;
            for (int j = 0; j < 4; ++j) dot += double(a.rotations[4 * i + j]) * b.rotations[4 * i + j];
            ASSERT_GT(std::fabs(dot), 0.995) << i;
            // SH keep their signs (a wrong flip would negate half of them): within the reference encoder's
            // coarser SH steps (5 bits for band 1, 4 for bands 2 and 3: errors up to 1/16), and correlated.
            for (int k = 3; k < 48; ++k) {
                ASSERT_NEAR(b.sh[48 * i + k], a.sh[48 * i + k], 1.0 / 16 + 1.0 / 128) << i << " " << k;
                ab += double(a.sh[48 * i + k]) * b.sh[48 * i + k], aa += double(a.sh[48 * i + k]) * a.sh[48 * i + k];
                bb += double(b.sh[48 * i + k]) * b.sh[48 * i + k];
            }
        }
        // 1 would be exact; 4-bit steps zero the many small coefficients (0.80 measured). Flipping the 9 odd
        // coefficients of 15 would give about -0.2.
        EXPECT_GT(ab / std::sqrt(aa * bb), 0.6);
    }
}

TEST(SpzFormat, LargeCoordinatesLowerFractionalBits) {
    GaussianCloud c;
    c.resize(2, 0);
    c.positions = {5000.25f, -3.0f, 1.0f, 0.0f, 0.0f, -7000.5f};
    c.scales.assign(6, 0.1f);
    c.opacities = {0.5f, 0.5f};
    const std::string out = tmp_path("large.spz");
    write_spz(out, c);
    const RawSpzV4 raw = decode_v4(out);
    EXPECT_EQ(raw.fbits, 10);  // 7000.5 * 2^11 > 2^23
    const GaussianCloud b = read_spz(out);
    for (int j = 0; j < 6; ++j) EXPECT_NEAR(b.positions[j], c.positions[j], 1.0 / 2048);
}

// ---------------------------------------------------------------------------------------------------------
// Malformed input.

TEST(SpzFormatErrors, UnsupportedVersion) {
    auto b = read_bytes(data_path("biker_v4.spz"));
    b[4] = 5;
    const std::string path = tmp_path("version5.spz");
    write_bytes(path, b);
    expect_format_error([&] { read_spz(path); }, "version5.spz", {"unsupported SPZ version 5"});
    const std::string path1 = tmp_path("version1.spz");
    write_bytes(path1, gzip(legacy_payload(1)));
    expect_format_error([&] { read_spz(path1); }, "version1.spz", {"unsupported SPZ version 1"});
}

TEST(SpzFormatErrors, TruncatedV4) {
    auto b = read_bytes(data_path("biker_v4.spz"));
    b.resize(b.size() / 2);
    const std::string path = tmp_path("truncated_v4.spz");
    write_bytes(path, b);
    expect_format_error([&] { read_spz(path); }, "truncated_v4.spz", {"truncated", "at byte"});
    b.resize(20);
    write_bytes(path, b);
    expect_format_error([&] { read_spz(path); }, "truncated_v4.spz", {"truncated", "32"});
}

TEST(SpzFormatErrors, V4HeaderLiesAboutCount) {
    auto b = read_bytes(data_path("biker_v4.spz"));
    const std::uint32_t lie = 152746u * 100;
    std::memcpy(&b[8], &lie, 4);
    const std::string path = tmp_path("lying_v4.spz");
    write_bytes(path, b);
    expect_format_error([&] { read_spz(path); }, "lying_v4.spz", {"stream 'positions' declares 1374714 bytes", "15274600 points"});
    const std::uint32_t absurd = 0xffffffffu;
    std::memcpy(&b[8], &absurd, 4);
    write_bytes(path, b);
    expect_format_error([&] { read_spz(path); }, "lying_v4.spz", {"4294967295 points"});
}

TEST(SpzFormatErrors, CorruptV4Stream) {
    auto b = read_bytes(data_path("biker_v4.spz"));
    for (std::size_t k = 112; k < 116; ++k) b[k] ^= 0x5a;  // the zstd magic of the positions frame (after 32 + 5*16 bytes)
    const std::string path = tmp_path("corrupt_v4.spz");
    write_bytes(path, b);
    expect_format_error([&] { read_spz(path); }, "corrupt_v4.spz", {"corrupt", "positions"});
}

TEST(SpzFormatErrors, GzipHeaderLiesAndTruncation) {
    // numPoints says 1,000,000 but the stream holds 2 splats: refused from the gzip trailer, before allocating.
    const std::string path = tmp_path("lying_v3.spz");
    write_bytes(path, gzip(legacy_payload(3, 1000000)));
    expect_format_error([&] { read_spz(path); }, "lying_v3.spz", {"1000000 points"});
    // A huge count is refused from the compressed size alone.
    write_bytes(path, gzip(legacy_payload(3, 90000000)));
    expect_format_error([&] { read_spz(path); }, "lying_v3.spz", {"90000000 points", "cannot hold"});
    // Truncated gzip stream.
    auto g = gzip(legacy_payload(3));
    g.resize(g.size() - 12);
    const std::string path2 = tmp_path("truncated_v3.spz");
    write_bytes(path2, g);
    expect_format_error([&] { read_spz(path2); }, "truncated_v3.spz", {});
}

TEST(SpzFormatErrors, EmptyAndNotSpz) {
    const std::string path = tmp_path("empty.spz");
    write_bytes(path, {});
    expect_format_error([&] { read_spz(path); }, "empty.spz", {"empty"});
    const std::string path2 = tmp_path("garbage.spz");
    write_text(path2, "this is not an spz file at all");
    expect_format_error([&] { read_spz(path2); }, "garbage.spz", {"not an SPZ file"});
}

}  // namespace
}  // namespace raysplats
