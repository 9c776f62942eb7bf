// Niantic .spz reader (versions 2, 3, 4) and writer (version 4).
//
// Format, after the reference implementation nianticlabs/spz (src/cc/load-spz.cc, PackedGaussiansHeader,
// packGaussians / unpackGaussians) and independent v4 readers that agree with it byte for byte:
//
//  Versions 2, 3: the whole file is ONE gzip stream holding
//      header (16 bytes, little endian): uint32 magic 0x5053474e ("NGSP"), uint32 version, uint32 numPoints,
//                                       uint8 shDegree, uint8 fractionalBits, uint8 flags, uint8 reserved
//      [extension records if flags & 0x2]   (skipped: the attribute data is the LAST bytes of the payload)
//      positions  numPoints*3 * 3 bytes   24-bit signed fixed point, value = int24 / 2^fractionalBits
//      alphas     numPoints               byte/255 = opacity (the reference stores sigmoid(logit) * 255)
//      colours    numPoints*3             dc = (byte/255 - 0.5) / 0.15     (colorScale 0.15, not C0)
//      scales     numPoints*3             log scale = byte/16 - 10
//      rotations  v2: numPoints*3 bytes   x,y,z = byte/127.5 - 1, w = sqrt(1 - |xyz|^2) >= 0
//                 v3: numPoints*4 bytes   "smallest three": uint32 LE, top 2 bits = index (in x,y,z,w order)
//                                         of the largest component, then three 10-bit fields (sign bit +
//                                         9-bit magnitude m, value = m/511 * sqrt(1/2)) for the other
//                                         components in descending index order from the low bits
//      sh         numPoints*dim*3         dim = 3, 8, 15 coefficients for degree 1, 2, 3; per splat the
//                                         coefficients in order, each as r,g,b; value = (byte - 128) / 128
//  Version 4: NOT gzipped. header (32 bytes): the 16 above, except byte 15 = numStreams, then uint32
//      tocByteOffset (>= 32), 12 reserved bytes; [extension records from byte 32 up to tocByteOffset];
//      at tocByteOffset a table of numStreams entries (uint64 compressedSize, uint64 uncompressedSize);
//      then the streams back to back, each one zstd frame: positions, alphas, colours, scales, rotations
//      (smallest three, 4 bytes), sh (only if shDegree > 0), with the same encodings as version 3.
//
// Coordinate system: SPZ stores RUB (x right, y up, z back). The reference library packs in RUB and converts on
// load and save (load-spz.h: PackOptions::from / UnpackOptions::to; its ply_to_spz tool converts the RDF of 3DGS
// .ply files to RUB), and splat-transform and web viewers read .spz as RUB. The core holds every cloud in the
// RDF (COLMAP) convention of .ply and .splat (docs/design.md §4), so the reader converts RUB -> RDF and the writer
// RDF -> RUB. Both are the same 180° rotation about x, F = diag(1, -1, -1), its own inverse:
//   positions   (x, y, z) -> (x, -y, -z)          (exact on the 24-bit fixed point: rounding is symmetric)
//   rotations   (w, x, y, z) -> (w, x, -y, -z)     = F R F, whose axes are those of F R up to sign (F is diagonal,
//                                                  so F diag(s)^2 F = diag(s)^2): the reference's convertCoordinates
//   SH          each coefficient times +-1         the core's SH rotation by F (rotate_sh), which maps every real SH
//                                                  basis function of the 3DGS convention to +- itself
// so that ply -> spz -> ply and spz -> ply -> spz keep a scene upright, with ours and with other tools.
//
// Writer: version 4 (zstd), the version of current Niantic tools and of the real file in shared/data.
// fractionalBits is 12 as in the reference unless the scene does not fit 24 bits at that precision, in
// which case it is lowered until it fits (readers take it from the header). SH coefficients use all 8
// bits (the reference's 5/4-bit bucketing is an encoder choice; the decoding formula is the same).
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <zlib.h>
#include <zstd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>

#include "io/io_common.h"
#include "io/splat_formats.h"
#include "raysplats/spherical_harmonics.h"
#include "raysplats/splat_io.h"

namespace raysplats {
namespace {

constexpr std::uint32_t kMagic = 0x5053474e;  // "NGSP"
constexpr float kColorScale = 0.15f;
constexpr std::uint8_t kFlagHasExtensions = 0x2;
constexpr std::size_t kMaxPoints = 100000000;  // sanity bound (the reference refuses above 10M)

// zstd's largest expansion: an RLE block of 4 bytes (3-byte header, 1 byte) regenerates at most one block,
// 128 KiB (RFC 8878 §3.1.1.2: Block_Maximum_Size). A stream cannot decompress to more than its compressed size
// times this, so a table of contents claiming more lies, and is refused before anything is allocated for it.
constexpr std::uint64_t kZstdMaxRatio = (std::uint64_t(128) << 10) / 4;

// The factor (+1 or -1) of each SH coefficient k (0..15) under the RUB <-> RDF conversion, from the core's SH
// rotation by F = diag(1, -1, -1) (see the file comment). Exactly +-1 (checked), so the conversion is lossless.
const std::array<float, 16>& rub_rdf_sh_signs() {
    static const std::array<float, 16> signs = [] {
        const double flip[9] = {1, 0, 0, 0, -1, 0, 0, 0, -1};
        std::array<float, 16> out{};
        out[0] = 1.0f;
        for (int k = 1; k < 16; ++k) {
            float in[48] = {}, rotated[48];
            in[3 * k] = 1.0f;
            rotate_sh(3, flip, in, rotated);
            const float s = rotated[3 * k] > 0 ? 1.0f : -1.0f;
            // A rotation by F maps each basis function to +- itself: anything else is a broken SH rotation.
            for (int j = 0; j < 16; ++j)
                if (std::fabs(rotated[3 * j] - (j == k ? s : 0.0f)) > 1e-5f)
                    throw Error("internal error: the SH rotation by diag(1,-1,-1) is not a sign flip");
            out[std::size_t(k)] = s;
        }
        return out;
    }();
    return signs;
}

int sh_dim(int degree) { return degree == 0 ? 0 : degree == 1 ? 3 : degree == 2 ? 8 : 15; }

struct SpzLayout {
    std::size_t n = 0;
    int degree = 0;
    int fractional_bits = 12;
    int rot_bytes = 4;
    std::size_t sizes[6] = {0, 0, 0, 0, 0, 0};  // positions, alphas, colours, scales, rotations, sh
    std::size_t total() const { return sizes[0] + sizes[1] + sizes[2] + sizes[3] + sizes[4] + sizes[5]; }
};

SpzLayout make_layout(std::size_t n, int degree, int rot_bytes, int fractional_bits) {
    SpzLayout l;
    l.n = n, l.degree = degree, l.rot_bytes = rot_bytes, l.fractional_bits = fractional_bits;
    l.sizes[0] = n * 9;
    l.sizes[1] = n;
    l.sizes[2] = n * 3;
    l.sizes[3] = n * 3;
    l.sizes[4] = n * std::size_t(rot_bytes);
    l.sizes[5] = n * std::size_t(sh_dim(degree)) * 3;
    return l;
}

// Decodes smallest-three rotation bytes into (w, x, y, z).
inline void unpack_smallest_three(const std::uint8_t* r, float* wxyz) {
    std::uint32_t comp = io::load_u32le(r);
    constexpr std::uint32_t mask = (1u << 9) - 1;
    const int largest = int(comp >> 30);
    float xyzw[4];
    float sum = 0.0f;
    for (int i = 3; i >= 0; --i) {
        if (i == largest) continue;
        const std::uint32_t mag = comp & mask;
        const std::uint32_t neg = (comp >> 9) & 1u;
        comp >>= 10;
        float v = 0.70710678118654752f * float(mag) / float(mask);
        if (neg) v = -v;
        xyzw[i] = v;
        sum += v * v;
    }
    xyzw[largest] = std::sqrt(std::max(0.0f, 1.0f - sum));
    wxyz[0] = xyzw[3], wxyz[1] = xyzw[0], wxyz[2] = xyzw[1], wxyz[3] = xyzw[2];
}

// Encodes with the component `largest` (x y z w order; -1: the largest one) left out.
inline void pack_smallest_three(const float* wxyz, std::uint8_t* out, int largest = -1) {
    double q[4] = {wxyz[1], wxyz[2], wxyz[3], wxyz[0]};  // x y z w
    const double nq = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    if (!(nq > 0.0) || !std::isfinite(nq)) q[0] = q[1] = q[2] = 0.0, q[3] = 1.0;
    else
        for (double& v : q) v /= nq;
    if (largest < 0) {
        largest = 0;
        for (int i = 1; i < 4; ++i)
            if (std::fabs(q[i]) > std::fabs(q[largest])) largest = i;
    }
    const bool negate = q[largest] < 0;
    std::uint32_t comp = std::uint32_t(largest);
    for (int i = 0; i < 4; ++i) {
        if (i == largest) continue;
        // signbit, not < 0: a stored "-0" (sign bit set, magnitude 0, as the reference writes) reads as -0.0f and
        // must be written back the same way for an untouched round trip to keep its bytes.
        const std::uint32_t negbit = std::uint32_t(std::signbit(q[i]) ^ negate);
        const double m = std::min(511.0, std::floor(511.0 * (std::fabs(q[i]) / 0.70710678118654752) + 0.5));
        comp = (comp << 10) | (negbit << 9) | std::uint32_t(m);
    }
    io::store_u32le(out, comp);
}

// What the reader makes of a stored rotation: unpack_smallest_three, then finalize_cloud's normalisation (before
// the axis conversion, which only negates components and commutes with it).
inline void read_back_rotation(std::uint32_t comp, float out[4]) {
    std::uint8_t bytes[4];
    io::store_u32le(bytes, comp);
    float q[4];
    unpack_smallest_three(bytes, q);
    if (!io::normalise_quaternion(q, out)) out[0] = 1.0f, out[1] = out[2] = out[3] = 0.0f;
}

// The smallest-three rotation of a unit quaternion (w x y z, RUB) that reads back as it exactly, when one does:
// the nearest encoding rounds each 9-bit magnitude of the normalised quaternion, but the reader derives the
// left-out component from the other three and normalises again, so a value read from a file and written back
// can land a step away. Tries the nearest encoding, then each magnitude one step either way, also with another
// component left out (encoders do not always leave out the largest after quantisation: 3 rotations of
// biker_v4.spz leave out w although x reads back larger); keeps the nearest encoding when none reads back
// exactly (an edited rotation).
void pack_rotation(const float* wxyz, std::uint8_t* out) {
    pack_smallest_three(wxyz, out);
    float back[4];
    read_back_rotation(io::load_u32le(out), back);
    if (io::same_quaternion(back, wxyz)) return;
    for (int left_out = 0; left_out < 4; ++left_out) {
        std::uint8_t encoding[4];
        pack_smallest_three(wxyz, encoding, left_out);
        const std::uint32_t nearest = io::load_u32le(encoding);
        for (int trial = 0; trial < 27; ++trial) {
            std::uint32_t comp = nearest;
            bool valid = true;
            for (int field = 0, t = trial; field < 3; ++field, t /= 3) {
                const int magnitude = int((comp >> (10 * field)) & 511u) + t % 3 - 1;
                valid &= magnitude >= 0 && magnitude <= 511;
                comp = (comp & ~(511u << (10 * field))) | (std::uint32_t(magnitude & 511) << (10 * field));
            }
            if (!valid) continue;
            read_back_rotation(comp, back);
            if (io::same_quaternion(back, wxyz)) {
                io::store_u32le(out, comp);
                return;
            }
        }
    }
}

inline std::uint8_t to_u8(double x) {
    if (!(x > 0.0)) return 0;
    if (x >= 255.0) return 255;
    return static_cast<std::uint8_t>(std::lround(x));
}

// Decodes the six attribute arrays into a cloud (activations applied, no repair yet).
void decode_attributes(const SpzLayout& l, const std::uint8_t* const s[6], GaussianCloud& c) {
    c.resize(l.n, l.degree);
    const int dim = sh_dim(l.degree);
    const int K = dim + 1;
    const float pos_scale = 1.0f / float(1u << l.fractional_bits);
    const std::array<float, 16>& signs = rub_rdf_sh_signs();
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, l.n, io::kGrain), [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i) {
            for (int j = 0; j < 3; ++j) {
                const std::uint8_t* p = s[0] + (3 * i + j) * 3;
                std::int32_t v = std::int32_t(p[0]) | (std::int32_t(p[1]) << 8) | (std::int32_t(p[2]) << 16);
                if (v & 0x800000) v -= 0x1000000;  // sign extension
                c.positions[3 * i + j] = float(j == 0 ? v : -v) * pos_scale;  // RUB -> RDF
            }
            c.opacities[i] = s[1][i] / 255.0f;
            float* sh = &c.sh[i * std::size_t(K) * 3];
            for (int j = 0; j < 3; ++j) sh[j] = (s[2][3 * i + j] / 255.0f - 0.5f) / kColorScale;
            for (int j = 0; j < 3; ++j) c.scales[3 * i + j] = std::exp(s[3][3 * i + j] / 16.0f - 10.0f);
            float* q = &c.rotations[4 * i];
            if (l.rot_bytes == 4) {
                unpack_smallest_three(s[4] + 4 * i, q);
            } else {
                const std::uint8_t* rb = s[4] + 3 * i;
                const float x = rb[0] / 127.5f - 1.0f, y = rb[1] / 127.5f - 1.0f, z = rb[2] / 127.5f - 1.0f;
                q[0] = std::sqrt(std::max(0.0f, 1.0f - (x * x + y * y + z * z)));
                q[1] = x, q[2] = y, q[3] = z;
            }
            q[2] = -q[2], q[3] = -q[3];  // RUB -> RDF
            const std::uint8_t* shb = s[5] + i * std::size_t(dim) * 3;
            for (int k = 0; k < dim * 3; ++k) sh[3 + k] = signs[std::size_t(1 + k / 3)] * ((float(shb[k]) - 128.0f) / 128.0f);
        }
    });
}

void check_header_fields(const std::string& path, std::uint32_t version, std::uint32_t n, int degree, int fbits) {
    if (n > kMaxPoints)
        throw FileFormatError(path, "SPZ header declares " + std::to_string(n) + " points, more than the supported " +
                                        std::to_string(kMaxPoints), 8);
    if (degree > 3)
        throw FileFormatError(path, "SPZ SH degree " + std::to_string(degree) + " is not supported (0..3)", 12);
    if (fbits > 23) throw FileFormatError(path, "SPZ fractionalBits " + std::to_string(fbits) + " is out of range", 13);
    (void)version;
}

GaussianCloud read_spz_gzip(const io::FileBytes& f) {
    const std::string& path = f.path();
    z_stream zs{};
    zs.next_in = const_cast<Bytef*>(f.data());
    zs.avail_in = static_cast<uInt>(std::min<std::size_t>(f.size(), 0x7fffffff));
    if (inflateInit2(&zs, 16 + MAX_WBITS) != Z_OK) throw FileFormatError(path, "zlib initialisation failed");
    struct Guard {
        z_stream* z;
        ~Guard() { inflateEnd(z); }
    } guard{&zs};
    std::size_t produced = 0;
    // Inflates exactly `want` bytes into dst (or fewer if the stream ends: returns the count).
    auto inflate_into = [&](std::uint8_t* dst, std::size_t want) -> std::size_t {
        std::size_t got = 0;
        while (got < want) {
            zs.next_out = dst + got;
            zs.avail_out = static_cast<uInt>(std::min<std::size_t>(want - got, 1u << 30));
            const uInt before = zs.avail_out;
            const int rc = inflate(&zs, Z_NO_FLUSH);
            got += before - zs.avail_out;
            if (rc == Z_STREAM_END) break;
            if (rc == Z_BUF_ERROR && zs.avail_in == 0) break;  // input exhausted: truncated
            if (rc != Z_OK && rc != Z_BUF_ERROR)
                throw FileFormatError(path, std::string("gzip data is corrupt: ") + (zs.msg ? zs.msg : "inflate error") +
                                                " (decompressed offset " + std::to_string(produced + got) + ")",
                                      zs.total_in);
        }
        produced += got;
        return got;
    };
    std::uint8_t hdr[16];
    if (inflate_into(hdr, 16) != 16) throw FileFormatError(path, "SPZ gzip stream is truncated: ends inside the 16-byte header");
    if (io::load_u32le(hdr) != kMagic) throw FileFormatError(path, "gzip content is not SPZ: no 'NGSP' magic after decompression");
    const std::uint32_t version = io::load_u32le(hdr + 4);
    if (version != 2 && version != 3)
        throw FileFormatError(path, "unsupported SPZ version " + std::to_string(version) + " in gzip stream (supported: 2, 3; 4 is not gzipped)", 4);
    const std::uint32_t n = io::load_u32le(hdr + 8);
    const int degree = hdr[12], fbits = hdr[13], flags = hdr[14];
    check_header_fields(path, version, n, degree, fbits);
    const SpzLayout l = make_layout(n, degree, version >= 3 ? 4 : 3, fbits);
    const std::size_t total = l.total();
    // Deflate cannot expand more than ~1032:1: a header whose data cannot fit the compressed size lies.
    if (total / 1032 > f.size())
        throw FileFormatError(path, "SPZ header declares " + std::to_string(n) + " points (" + std::to_string(total) +
                                        " bytes of data) but the compressed file of " + std::to_string(f.size()) +
                                        " bytes cannot hold them", 8);
    // The gzip trailer holds the uncompressed size modulo 2^32: check it before allocating.
    if (f.size() >= 18 && !(flags & kFlagHasExtensions)) {
        const std::uint32_t isize = io::load_u32le(f.data() + f.size() - 4);
        if (isize != std::uint32_t(16 + total))
            throw FileFormatError(path, "SPZ data size does not match the header: " + std::to_string(n) + " points need " +
                                            std::to_string(16 + total) + " decompressed bytes, the gzip trailer says " +
                                            std::to_string(isize) + " (truncated or corrupt file)",
                                  f.size() - 4);
    }
    std::vector<std::uint8_t> payload;
    if (flags & kFlagHasExtensions) {
        // Extension records sit between the header and the data; the data is the last `total` bytes.
        constexpr std::size_t kMaxExtensionBytes = 1 << 20;
        payload.resize(total + kMaxExtensionBytes);
        const std::size_t got = inflate_into(payload.data(), payload.size());
        if (got < total)
            throw FileFormatError(path, "SPZ data is truncated: " + std::to_string(n) + " points need " + std::to_string(total) +
                                            " bytes after the header, the stream has " + std::to_string(got));
        std::memmove(payload.data(), payload.data() + (got - total), total);
        payload.resize(total);
    } else {
        payload.resize(total);
        const std::size_t got = inflate_into(payload.data(), total);
        if (got < total)
            throw FileFormatError(path, "SPZ data is truncated: " + std::to_string(n) + " points need " + std::to_string(total) +
                                            " bytes after the header, the stream ends after " + std::to_string(got) +
                                            " (decompressed offset " + std::to_string(16 + got) + ")",
                                  zs.total_in);
    }
    const std::uint8_t* s[6];
    std::size_t off = 0;
    for (int k = 0; k < 6; ++k) s[k] = payload.data() + off, off += l.sizes[k];
    GaussianCloud c;
    decode_attributes(l, s, c);
    return c;
}

GaussianCloud read_spz_v4(const io::FileBytes& f) {
    const std::string& path = f.path();
    const std::uint8_t* d = f.data();
    const std::size_t size = f.size();
    if (size < 32) throw FileFormatError(path, "SPZ file is truncated: " + std::to_string(size) + " bytes, the v4 header needs 32", size);
    const std::uint32_t version = io::load_u32le(d + 4);
    if (version != 4)
        throw FileFormatError(path, "unsupported SPZ version " + std::to_string(version) +
                                        " (uncompressed NGSP header: only version 4; 2 and 3 are gzip files)", 4);
    const std::uint32_t n = io::load_u32le(d + 8);
    const int degree = d[12], fbits = d[13];
    const int num_streams = d[15];
    const std::uint32_t toc = io::load_u32le(d + 16);
    check_header_fields(path, version, n, degree, fbits);
    const SpzLayout l = make_layout(n, degree, 4, fbits);
    int stream_index[6];
    int expected_streams = 0;
    for (int k = 0; k < 6; ++k) stream_index[k] = l.sizes[k] > 0 ? expected_streams++ : -1;
    if (num_streams != expected_streams)
        throw FileFormatError(path, "SPZ v4 has " + std::to_string(num_streams) + " streams; " + std::to_string(expected_streams) +
                                        " expected for " + std::to_string(n) + " points of SH degree " + std::to_string(degree), 15);
    if (toc < 32 || std::uint64_t(toc) + std::uint64_t(num_streams) * 16 > size)
        throw FileFormatError(path, "SPZ v4 table of contents (offset " + std::to_string(toc) + ") lies outside the file", 16);
    std::size_t comp_off[6] = {}, comp_size[6] = {};
    std::uint64_t off = std::uint64_t(toc) + std::uint64_t(num_streams) * 16;
    static const char* const kNames[6] = {"positions", "alphas", "colours", "scales", "rotations", "sh"};
    for (int k = 0; k < 6; ++k) {
        const int si = stream_index[k];
        if (si < 0) continue;
        const std::uint8_t* e = d + toc + std::size_t(si) * 16;
        const std::uint64_t cs = io::load_u64le(e), us = io::load_u64le(e + 8);
        if (us != l.sizes[k])
            throw FileFormatError(path, std::string("SPZ v4 stream '") + kNames[k] + "' declares " + std::to_string(us) +
                                            " bytes; " + std::to_string(l.sizes[k]) + " expected for " + std::to_string(n) + " points",
                                  toc + std::size_t(si) * 16 + 8);
        if (cs > size - off)
            throw FileFormatError(path, std::string("SPZ file is truncated: stream '") + kNames[k] + "' needs " + std::to_string(cs) +
                                            " bytes at byte " + std::to_string(off) + ", the file has " + std::to_string(size),
                                  off);
        // A stream of non-zero size cannot be stored in zero bytes.
        if (cs == 0) throw FileFormatError(path, std::string("SPZ v4 stream '") + kNames[k] + "' is empty", off);
        if (us / kZstdMaxRatio > cs)
            throw FileFormatError(path, std::string("SPZ v4 stream '") + kNames[k] + "' cannot hold the " + std::to_string(n) +
                                            " points the header declares: " + std::to_string(us) + " bytes from " +
                                            std::to_string(cs) + " compressed bytes is more than zstd can expand (" +
                                            std::to_string(kZstdMaxRatio) + ":1)",
                                  toc + std::size_t(si) * 16);
        comp_off[k] = std::size_t(off), comp_size[k] = std::size_t(cs);
        off += cs;
    }
    // Every declared size was checked against n and against what its compressed bytes can expand to, so the
    // allocation is bounded by the file's size; allocate and decompress (streams in parallel).
    std::vector<std::uint8_t> streams[6];
    std::string errors[6];
    tbb::parallel_for(0, 6, [&](int k) {
        if (stream_index[k] < 0) return;
        streams[k].resize(l.sizes[k]);
        const std::size_t r = ZSTD_decompress(streams[k].data(), streams[k].size(), d + comp_off[k], comp_size[k]);
        if (ZSTD_isError(r)) errors[k] = std::string("zstd error in stream '") + kNames[k] + "': " + ZSTD_getErrorName(r);
        else if (r != l.sizes[k])
            errors[k] = std::string("stream '") + kNames[k] + "' decompresses to " + std::to_string(r) + " bytes, " +
                        std::to_string(l.sizes[k]) + " expected";
    });
    for (int k = 0; k < 6; ++k)
        if (!errors[k].empty()) throw FileFormatError(path, "SPZ data is corrupt or truncated: " + errors[k], comp_off[k]);
    const std::uint8_t* s[6];
    for (int k = 0; k < 6; ++k) s[k] = streams[k].data();
    GaussianCloud c;
    decode_attributes(l, s, c);
    return c;
}

}  // namespace

namespace io {
bool gzip_holds_spz(const std::uint8_t* data, std::size_t size) {
    if (size < 2 || data[0] != 0x1f || data[1] != 0x8b) return false;
    z_stream zs{};
    zs.next_in = const_cast<Bytef*>(data);
    zs.avail_in = static_cast<uInt>(std::min<std::size_t>(size, 0x7fffffff));
    if (inflateInit2(&zs, 16 + MAX_WBITS) != Z_OK) return false;
    std::uint8_t magic[4];
    zs.next_out = magic;
    zs.avail_out = 4;
    int rc = Z_OK;
    while (zs.avail_out > 0 && (rc == Z_OK || rc == Z_BUF_ERROR) && zs.avail_in > 0) rc = inflate(&zs, Z_NO_FLUSH);
    const bool complete = zs.avail_out == 0;
    inflateEnd(&zs);
    return complete && load_u32le(magic) == kMagic;
}

// 'NGSP' (version 4), or gzip (versions 2 and 3); under a .splat name only gzip that inflates to 'NGSP'.
Evidence detect_spz(const std::uint8_t* d, std::size_t size, const std::string&, bool headerless_name) {
    if (starts_with(d, size, "NGSP", 4)) return Evidence::Signature;
    if (size >= 2 && d[0] == 0x1f && d[1] == 0x8b && (!headerless_name || gzip_holds_spz(d, size)))
        return Evidence::Signature;
    return Evidence::None;
}

SplatFileSummary probe_spz(const FileBytes& f) {
    const std::string& path = f.path();
    std::uint8_t hdr[16];
    if (f.size() >= 2 && f.data()[0] == 0x1f && f.data()[1] == 0x8b) {
        z_stream zs{};
        zs.next_in = const_cast<Bytef*>(f.data());
        zs.avail_in = static_cast<uInt>(std::min<std::size_t>(f.size(), 0x7fffffff));
        if (inflateInit2(&zs, 16 + MAX_WBITS) != Z_OK) throw FileFormatError(path, "zlib initialisation failed");
        zs.next_out = hdr;
        zs.avail_out = 16;
        int rc = Z_OK;
        while (zs.avail_out > 0 && (rc == Z_OK || rc == Z_BUF_ERROR) && zs.avail_in > 0) rc = inflate(&zs, Z_NO_FLUSH);
        const bool complete = zs.avail_out == 0;
        inflateEnd(&zs);
        if (!complete) throw FileFormatError(path, "SPZ gzip stream is corrupt or ends inside the 16-byte header");
        if (load_u32le(hdr) != kMagic) throw FileFormatError(path, "gzip content is not SPZ: no 'NGSP' magic after decompression");
    } else if (f.size() >= 16 && load_u32le(f.data()) == kMagic) {
        std::memcpy(hdr, f.data(), 16);
    } else {
        throw FileFormatError(path, "not an SPZ file: neither gzip data nor the 'NGSP' magic", 0);
    }
    const std::uint32_t n = load_u32le(hdr + 8);
    check_header_fields(path, load_u32le(hdr + 4), n, hdr[12], hdr[13]);
    return {SplatFormat::Spz, n, hdr[12]};
}
}  // namespace io

namespace io {
GaussianCloud read_spz(const FileBytes& f, const ReadOptions& options, LoadReport* report) {
    const std::string& path = f.path();
    if (f.size() == 0) throw FileFormatError(path, "file is empty");
    GaussianCloud c;
    if (f.size() >= 2 && f.data()[0] == 0x1f && f.data()[1] == 0x8b) {
        c = read_spz_gzip(f);
    } else if (f.size() >= 4 && io::load_u32le(f.data()) == kMagic) {
        c = read_spz_v4(f);
    } else {
        throw FileFormatError(path, "not an SPZ file: neither gzip data nor the 'NGSP' magic", 0);
    }
    io::finalize_cloud(c, options, report);
    return c;
}
}  // namespace io

GaussianCloud read_spz(const std::string& path, const ReadOptions& options, LoadReport* report) {
    return io::read_spz(io::FileBytes(path), options, report);
}

void write_spz(const std::string& path, const GaussianCloud& cloud) {
    io::check_writable(cloud);
    const std::size_t n = cloud.size();
    if (n > 0xffffffffu) throw InvalidArgument("too many Gaussians for SPZ: " + std::to_string(n));
    const int degree = cloud.sh_degree;
    const int K = cloud.coeffs_per_channel();
    // Largest |coordinate| decides the fixed-point precision (24-bit signed: |v| * 2^fb < 2^23).
    double max_abs = 0.0;
    for (float v : cloud.positions)
        if (std::isfinite(v)) max_abs = std::max(max_abs, double(std::fabs(v)));
    int fbits = 12;
    while (fbits > 0 && std::round(max_abs * double(1 << fbits)) > 8388607.0) --fbits;
    if (std::round(max_abs) > 8388607.0)
        throw InvalidArgument("a Gaussian position (|coordinate| = " + std::to_string(max_abs) +
                              ") is too large for SPZ's 24-bit fixed point");
    const SpzLayout l = make_layout(n, degree, 4, fbits);
    std::vector<std::uint8_t> s[6];
    for (int k = 0; k < 6; ++k) s[k].resize(l.sizes[k]);
    const double pscale = double(1 << fbits);
    const int dim = sh_dim(degree);
    const std::array<float, 16>& signs = rub_rdf_sh_signs();
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, io::kGrain), [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i) {
            for (int j = 0; j < 3; ++j) {
                const double pv = j == 0 ? double(cloud.positions[3 * i]) : -double(cloud.positions[3 * i + j]);  // RDF -> RUB
                const std::int32_t v = std::isfinite(pv) ? std::int32_t(std::lround(pv * pscale)) : 0;
                std::uint8_t* p = &s[0][(3 * i + j) * 3];
                p[0] = std::uint8_t(v), p[1] = std::uint8_t(v >> 8), p[2] = std::uint8_t(v >> 16);
            }
            s[1][i] = to_u8(double(cloud.opacities[i]) * 255.0);
            const float* sh = &cloud.sh[i * std::size_t(K) * 3];
            for (int j = 0; j < 3; ++j) s[2][3 * i + j] = to_u8(double(sh[j]) * (kColorScale * 255.0) + 0.5 * 255.0);
            for (int j = 0; j < 3; ++j)
                s[3][3 * i + j] = to_u8((std::log(std::fmax(double(cloud.scales[3 * i + j]), 1e-30)) + 10.0) * 16.0);
            const float* q = &cloud.rotations[4 * i];
            const float rub[4] = {q[0], q[1], -q[2], -q[3]};  // RDF -> RUB
            pack_rotation(rub, &s[4][4 * i]);
            std::uint8_t* shb = s[5].data() + i * std::size_t(dim) * 3;
            for (int k = 0; k < dim * 3; ++k)
                shb[k] = to_u8(std::round(double(signs[std::size_t(1 + k / 3)] * sh[3 + k]) * 128.0) + 128.0);
        }
    });
    // Compress the streams in parallel, one zstd frame each (level 12: ~ the size of the reference's files).
    std::vector<std::uint8_t> comp[6];
    std::string errors[6];
    tbb::parallel_for(0, 6, [&](int k) {
        if (s[k].empty()) return;
        comp[k].resize(ZSTD_compressBound(s[k].size()));
        const std::size_t r = ZSTD_compress(comp[k].data(), comp[k].size(), s[k].data(), s[k].size(), 12);
        if (ZSTD_isError(r)) errors[k] = ZSTD_getErrorName(r);
        else comp[k].resize(r);
    });
    for (int k = 0; k < 6; ++k)
        if (!errors[k].empty()) throw FileFormatError(path, "cannot write: zstd compression failed: " + errors[k]);
    int num_streams = 0;
    for (int k = 0; k < 6; ++k) num_streams += s[k].empty() ? 0 : 1;
    std::vector<std::uint8_t> head(32 + std::size_t(num_streams) * 16, 0);
    io::store_u32le(&head[0], kMagic);
    io::store_u32le(&head[4], 4);
    io::store_u32le(&head[8], std::uint32_t(n));
    head[12] = std::uint8_t(degree);
    head[13] = std::uint8_t(fbits);
    head[14] = 0;  // flags: not antialiased, no extensions
    head[15] = std::uint8_t(num_streams);
    io::store_u32le(&head[16], 32);  // table of contents right after the header
    std::size_t e = 32;
    for (int k = 0; k < 6; ++k) {
        if (s[k].empty()) continue;
        io::store_u64le(&head[e], comp[k].size());
        io::store_u64le(&head[e + 8], s[k].size());
        e += 16;
    }
    io::AtomicFileWriter out(path);
    out.write(head.data(), head.size());
    for (int k = 0; k < 6; ++k)
        if (!s[k].empty()) out.write(comp[k].data(), comp[k].size());
    out.commit();
}

}  // namespace raysplats
