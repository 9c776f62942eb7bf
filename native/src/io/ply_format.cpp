// INRIA 3DGS .ply reader and writer (docs/design.md §4). A SuperSplat compressed PLY is recognised by its header and
// read by compressed_ply_format.cpp.
//
// Reader: ascii, binary_little_endian and binary_big_endian; properties looked up by name in any order; any
// PLY scalar type (char/int8, uchar/uint8, short/int16, ushort/uint16, int/int32, uint/uint32,
// float/float32, double/float64) converted to float; extra properties ignored; elements before 'vertex'
// are skipped and elements after it ignored. The file is memory mapped and binary records are decoded in
// parallel (TBB) straight into the Gaussian arrays.
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include "io/io_common.h"
#include "io/ply_header.h"
#include "io/splat_formats.h"
#include "raysplats/splat_io.h"

namespace raysplats {
namespace {

using io::PlyElement;
using io::PlyFormat;
using io::PlyHeader;
using io::PlyProperty;
using io::PlyType;
using io::ply_type_size;

// Canonical field order inside the reader: x y z, f_dc_0..2, opacity, scale_0..2, rot_0..3, f_rest_0..M-1.
constexpr int kNumRequired = 14;
const char* const kRequired[kNumRequired] = {"x",       "y",       "z",       "f_dc_0", "f_dc_1", "f_dc_2", "opacity",
                                             "scale_0", "scale_1", "scale_2", "rot_0",  "rot_1",  "rot_2",  "rot_3"};

constexpr int kMaxRest = 45;  // f_rest values of SH degree 3: 3 channels x 15 coefficients

struct FieldMap {
    std::vector<int> prop_index;  // canonical field -> index into the vertex element's properties
    int degree = 0;
    int rest_count = 0;
};

// Throws the error for a PLY whose vertices carry none of the Gaussian properties: says whether it is a mesh
// (it has faces) or a point cloud, and where such files are imported instead.
[[noreturn]] void throw_not_a_splat_file(const std::string& path, const PlyHeader& h, const PlyElement& v) {
    std::uint64_t faces = 0;
    for (const PlyElement& e : h.elements)
        if (e.name == "face" || e.name == "tristrips") faces += e.count;
    bool colours = false;
    for (const PlyProperty& p : v.props) colours |= p.name == "red" || p.name == "diffuse_red";
    const std::string what =
        faces > 0 ? "a mesh PLY (" + std::to_string(v.count) + " vertices, " + std::to_string(faces) + " faces)"
                  : std::string(colours ? "a coloured point cloud PLY (" : "a point cloud PLY (") + std::to_string(v.count) +
                        " points)";
    throw FileFormatError(path,
                          what + ", not a Gaussian splat file: its vertices have none of the Gaussian "
                                 "properties (f_dc_0, opacity, scale_0, rot_0, ...); import it with "
                                 "File > Import > Stanford PLY",
                          v.header_offset);
}

FieldMap map_fields(const std::string& path, const PlyHeader& h, const PlyElement& v) {
    FieldMap m;
    m.prop_index.assign(kNumRequired, -1);
    std::vector<int> rest;
    for (std::size_t i = 0; i < v.props.size(); ++i) {
        const std::string& name = v.props[i].name;
        for (int k = 0; k < kNumRequired; ++k)
            if (name == kRequired[k]) {
                if (m.prop_index[k] >= 0) throw FileFormatError(path, "property '" + name + "' appears twice in element 'vertex'");
                m.prop_index[k] = int(i);
            }
        if (name.compare(0, 7, "f_rest_") == 0) {
            int idx = -1;
            const char* b = name.data() + 7;
            const char* e = name.data() + name.size();
            const auto r = std::from_chars(b, e, idx);
            if (r.ec != std::errc() || r.ptr != e || idx < 0 || b == e)
                throw FileFormatError(path, "unrecognised SH property '" + name + "' (expected f_rest_<index>)",
                                      v.props[i].header_offset);
            // Checked before `rest` grows to the index: SH degree 3 has 45 f_rest values, 0..44.
            if (idx >= kMaxRest)
                throw FileFormatError(path, "SH property '" + name + "' is beyond SH degree 3 (f_rest_0..f_rest_" +
                                                std::to_string(kMaxRest - 1) + ")",
                                      v.props[i].header_offset);
            if (std::size_t(idx) >= rest.size()) rest.resize(std::size_t(idx) + 1, -1);
            if (rest[std::size_t(idx)] >= 0) throw FileFormatError(path, "property '" + name + "' appears twice in element 'vertex'");
            rest[std::size_t(idx)] = int(i);
        }
    }
    // Positions alone (no Gaussian property at all) are an ordinary mesh or point cloud, not a broken splat file.
    bool any_gaussian_property = !rest.empty();
    for (int k = 3; k < kNumRequired; ++k) any_gaussian_property |= m.prop_index[k] >= 0;
    if (!any_gaussian_property) throw_not_a_splat_file(path, h, v);
    for (int k = 0; k < kNumRequired; ++k)
        if (m.prop_index[k] < 0)
            throw FileFormatError(path, std::string("missing required property '") + kRequired[k] + "' in element 'vertex'",
                                  v.header_offset);
    int count = 0;
    for (int r : rest) count += r >= 0;
    if (count != 0 && count != 9 && count != 24 && count != 45)
        throw FileFormatError(path, "element 'vertex' has " + std::to_string(count) +
                                        " f_rest_* properties; expected 0, 9, 24 or 45 (SH degree 0, 1, 2 or 3)");
    for (std::size_t k = 0; k < rest.size(); ++k)
        if (rest[k] < 0)
            throw FileFormatError(path, "f_rest_* properties are not numbered 0.." + std::to_string(count - 1) + ": f_rest_" +
                                            std::to_string(k) + " is missing");
    m.rest_count = count;
    m.degree = count == 0 ? 0 : count == 9 ? 1 : count == 24 ? 2 : 3;
    for (int r : rest) m.prop_index.push_back(r);
    for (int idx : m.prop_index)
        if (v.props[std::size_t(idx)].is_list)
            throw FileFormatError(path, "property '" + v.props[std::size_t(idx)].name + "' of element 'vertex' is a list");
    return m;
}

// The activations of the INRIA layout, in double (the writer inverts them exactly for the float values it writes:
// see write_ply).
inline float decode_opacity(double logit) { return float(1.0 / (1.0 + std::exp(-logit))); }
inline float decode_scale(double log_scale) { return float(std::exp(log_scale)); }

// The rotation to store for the cloud's unit quaternion q: q itself when the reader's normalisation gives it back
// unchanged, else the nearest float quaternion (each component within one ulp) that it does (normalising a
// float quaternion is not idempotent in float), so that reading what we wrote gives q exactly.
void stored_rotation(const float* q, float out[4]) {
    float back[4];
    std::copy(q, q + 4, out);
    if (!io::normalise_quaternion(q, back) || io::same_quaternion(back, q)) return;
    for (int trial = 0; trial < 81; ++trial) {
        float candidate[4];
        for (int j = 0, t = trial; j < 4; ++j, t /= 3) {
            const int step = t % 3 - 1;  // -1, 0, +1 ulp
            candidate[j] = step == 0 ? q[j] : std::nextafter(q[j], step * std::numeric_limits<float>::infinity());
        }
        if (io::normalise_quaternion(candidate, back) && io::same_quaternion(back, q)) {
            std::copy(candidate, candidate + 4, out);
            return;
        }
    }
    // Other lengths: each component rounds on its own, which reaches combinations the ulp steps miss. First lengths
    // a little off 1, then up to 4 (trained scenes store quaternions of length up to ~3; rare components of
    // theirs normalise to values no near-unit float quaternion reaches).
    for (int t = 1; t <= 1024; ++t) {
        const double length = t <= 256 ? 1.0 + (t % 2 ? 1 : -1) * double((t + 1) / 2) * 0x1p-26 : 1.0 + (t - 256) / 256.0;
        float candidate[4];
        for (int j = 0; j < 4; ++j) candidate[j] = float(double(q[j]) * length);
        if (io::normalise_quaternion(candidate, back) && io::same_quaternion(back, q)) {
            std::copy(candidate, candidate + 4, out);
            return;
        }
    }
}

// Stores one splat from its canonical field values (activations applied here, repair in finalize_cloud).
inline void store_splat(GaussianCloud& c, std::size_t i, const double* f, int K) {
    for (int j = 0; j < 3; ++j) c.positions[3 * i + j] = float(f[j]);
    float* sh = &c.sh[std::size_t(i) * K * 3];
    for (int ch = 0; ch < 3; ++ch) sh[ch] = float(f[3 + ch]);
    // f_rest is channel-major: f_rest_{ch*(K-1) + j} is coefficient j+1 of channel ch.
    for (int ch = 0; ch < 3; ++ch)
        for (int j = 0; j < K - 1; ++j) sh[(j + 1) * 3 + ch] = float(f[kNumRequired + ch * (K - 1) + j]);
    c.opacities[i] = decode_opacity(f[6]);
    for (int j = 0; j < 3; ++j) c.scales[3 * i + j] = decode_scale(f[7 + j]);
    for (int j = 0; j < 4; ++j) c.rotations[4 * i + j] = float(f[10 + j]);
}

template <bool BigEndian>
void decode_binary(GaussianCloud& c, const std::uint8_t* base, std::size_t n, const PlyElement& v, const FieldMap& m) {
    const int K = c.coeffs_per_channel();
    const std::size_t nf = m.prop_index.size();
    std::vector<std::size_t> offs(nf);
    std::vector<PlyType> types(nf);
    bool all_float_le = !BigEndian;
    for (std::size_t k = 0; k < nf; ++k) {
        const PlyProperty& p = v.props[std::size_t(m.prop_index[k])];
        offs[k] = p.offset;
        types[k] = p.type;
        all_float_le &= p.type == PlyType::Float32;
    }
    const std::size_t rs = v.record_size;
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, io::kGrain), [&](const tbb::blocked_range<std::size_t>& r) {
        double f[kNumRequired + 45];
        for (std::size_t i = r.begin(); i != r.end(); ++i) {
            const std::uint8_t* rec = base + i * rs;
            if (all_float_le) {
                for (std::size_t k = 0; k < nf; ++k) {
                    float x;
                    std::memcpy(&x, rec + offs[k], 4);
                    f[k] = x;
                }
            } else {
                for (std::size_t k = 0; k < nf; ++k) f[k] = io::load_ply_value<BigEndian>(rec + offs[k], types[k]);
            }
            store_splat(c, i, f, K);
        }
    });
}

// ASCII reading: a cursor over whitespace-separated tokens.
struct AsciiCursor {
    const char* d;
    std::size_t size, pos;
    const std::string& path;

    bool next(const char*& b, const char*& e) {
        while (pos < size && std::isspace(static_cast<unsigned char>(d[pos]))) ++pos;
        if (pos >= size) return false;
        b = d + pos;
        while (pos < size && !std::isspace(static_cast<unsigned char>(d[pos]))) ++pos;
        e = d + pos;
        return true;
    }
    double number(const char* what, std::uint64_t item) {
        const char *b, *e;
        if (!next(b, e))
            throw FileFormatError(path, "file is truncated: ends in " + std::string(what) + " of element " + std::to_string(item), pos);
        double v = 0.0;
        const char* bb = (*b == '+') ? b + 1 : b;
        const auto r = std::from_chars(bb, e, v);
        if (r.ec == std::errc::result_out_of_range) {
            v = (*bb == '-') ? -std::numeric_limits<double>::infinity() : std::numeric_limits<double>::infinity();
        } else if (r.ec != std::errc() || r.ptr != e) {
            throw FileFormatError(path, "bad number '" + std::string(b, e) + "' in " + what + " of element " + std::to_string(item),
                                  std::uint64_t(b - d));
        }
        return v;
    }
};

void skip_ascii_element(AsciiCursor& cur, const PlyElement& e) {
    for (std::uint64_t i = 0; i < e.count; ++i)
        for (const PlyProperty& p : e.props) {
            if (p.is_list) {
                const double cnt = cur.number(("list count of property '" + p.name + "'").c_str(), i);
                if (!(cnt >= 0) || cnt > 1e9 || cnt != std::floor(cnt))
                    throw FileFormatError(cur.path, "bad list count '" + std::to_string(cnt) + "' in property '" + p.name +
                                                        "' of element '" + e.name + "' (must be a whole number)",
                                          cur.pos);
                for (std::uint64_t k = 0; k < std::uint64_t(cnt); ++k) cur.number(("property '" + p.name + "'").c_str(), i);
            } else {
                cur.number(("property '" + p.name + "'").c_str(), i);
            }
        }
}

}  // namespace

namespace io {
// A file named .splat must start with 'ply' and a line end: its first float may spell "ply" by chance.
Evidence detect_ply(const std::uint8_t* d, std::size_t size, const std::string&, bool headerless_name) {
    const bool ply = headerless_name ? starts_with(d, size, "ply\n", 4) || starts_with(d, size, "ply\r", 4)
                                     : starts_with(d, size, "ply", 3);
    return ply ? Evidence::Signature : Evidence::None;
}

SplatFileSummary probe_ply(const FileBytes& f) {
    const PlyHeader h = io::parse_ply_header(f);
    if (io::is_compressed_ply(h)) return io::probe_compressed_ply(f.data(), f.size(), f.path(), h);
    for (const PlyElement& e : h.elements)
        if (e.name == "vertex") {
            const FieldMap m = map_fields(f.path(), h, e);
            return {SplatFormat::Ply, e.count, m.degree};
        }
    throw FileFormatError(f.path(), "PLY file has no 'vertex' element");
}
}  // namespace io

namespace io {
GaussianCloud read_ply(const FileBytes& f, const ReadOptions& options, LoadReport* report) {
    const std::string& path = f.path();
    const PlyHeader h = io::parse_ply_header(f);
    if (io::is_compressed_ply(h)) return io::read_compressed_ply_data(f.data(), f.size(), path, h, options, report);
    std::size_t vi = h.elements.size();
    for (std::size_t i = 0; i < h.elements.size(); ++i)
        if (h.elements[i].name == "vertex") {
            vi = i;
            break;
        }
    if (vi == h.elements.size()) {
        const std::string first = h.elements.empty() ? std::string("none") : "'" + h.elements[0].name + "'";
        throw FileFormatError(path, "PLY file has no 'vertex' element (first element: " + first + ")");
    }
    const PlyElement& v = h.elements[vi];
    const FieldMap m = map_fields(path, h, v);
    const std::uint64_t n64 = v.count;
    const std::size_t size = f.size();

    GaussianCloud cloud;
    if (h.format == PlyFormat::Ascii) {
        AsciiCursor cur{reinterpret_cast<const char*>(f.data()), size, h.data_offset, path};
        for (std::size_t i = 0; i < vi; ++i) skip_ascii_element(cur, h.elements[i]);
        if (v.has_list)
            for (const PlyProperty& p : v.props)
                if (p.is_list) throw FileFormatError(path, "list property '" + p.name + "' in element 'vertex' is not supported");
        // Every value takes at least 2 bytes (a digit and a separator): refuse impossible counts before allocating.
        const std::uint64_t remaining = size - cur.pos;
        const std::uint64_t nprops = v.props.size();
        if (n64 > (remaining + 1) / (2 * nprops))
            throw FileFormatError(path, "file is truncated: the header declares " + std::to_string(n64) + " vertices of " +
                                            std::to_string(nprops) + " values but only " + std::to_string(remaining) +
                                            " bytes of ASCII data follow",
                                  cur.pos);
        const std::size_t n = static_cast<std::size_t>(n64);
        cloud.resize(n, m.degree);
        const int K = cloud.coeffs_per_channel();
        std::vector<double> all(v.props.size());
        double fv[kNumRequired + 45];
        for (std::size_t i = 0; i < n; ++i) {
            for (std::size_t k = 0; k < v.props.size(); ++k) all[k] = cur.number(("property '" + v.props[k].name + "'").c_str(), i);
            for (std::size_t k = 0; k < m.prop_index.size(); ++k) fv[k] = all[std::size_t(m.prop_index[k])];
            store_splat(cloud, i, fv, K);
        }
    } else {
        std::uint64_t off = h.data_offset;
        const bool be = h.format == PlyFormat::BinaryBE;
        // Skip elements before 'vertex' (fixed-size ones in one step, ones with lists record by record).
        for (std::size_t ei = 0; ei < vi; ++ei) {
            const PlyElement& e = h.elements[ei];
            if (!e.has_list) {
                if (e.record_size && e.count > (size - std::min<std::uint64_t>(off, size)) / e.record_size)
                    throw FileFormatError(path, "file is truncated in element '" + e.name + "'", off);
                off += e.count * e.record_size;
                continue;
            }
            for (std::uint64_t r = 0; r < e.count; ++r)
                for (const PlyProperty& p : e.props) {
                    if (!p.is_list) {
                        off += ply_type_size(p.type);
                    } else {
                        const std::size_t cs = ply_type_size(p.count_type);
                        if (off + cs > size) throw FileFormatError(path, "file is truncated in element '" + e.name + "'", off);
                        const double cnt = be ? io::load_ply_value<true>(f.data() + off, p.count_type)
                                              : io::load_ply_value<false>(f.data() + off, p.count_type);
                        if (!(cnt >= 0)) throw FileFormatError(path, "negative list count in element '" + e.name + "'", off);
                        off += cs + std::uint64_t(cnt) * ply_type_size(p.type);
                    }
                    if (off > size) throw FileFormatError(path, "file is truncated in element '" + e.name + "'", off);
                }
        }
        if (v.has_list)
            for (const PlyProperty& p : v.props)
                if (p.is_list) throw FileFormatError(path, "list property '" + p.name + "' in element 'vertex' is not supported");
        const std::uint64_t rs = v.record_size;
        const std::uint64_t available = size > off ? size - off : 0;
        // Refuse a count the file cannot hold before allocating anything for it.
        if (n64 > available / rs)
            throw FileFormatError(path, "file is truncated: the header declares " + std::to_string(n64) + " vertices of " +
                                            std::to_string(rs) + " bytes (" + std::to_string(n64) + " x " + std::to_string(rs) +
                                            " bytes) but only " + std::to_string(available) + " bytes follow the header",
                                  off);
        const std::size_t n = static_cast<std::size_t>(n64);
        cloud.resize(n, m.degree);
        if (be) decode_binary<true>(cloud, f.data() + off, n, v, m);
        else decode_binary<false>(cloud, f.data() + off, n, v, m);
    }
    io::finalize_cloud(cloud, options, report);
    return cloud;
}
}  // namespace io

GaussianCloud read_ply(const std::string& path, const ReadOptions& options, LoadReport* report) {
    return io::read_ply(io::FileBytes(path), options, report);
}

void write_ply(const std::string& path, const GaussianCloud& cloud) {
    io::check_writable(cloud);
    const std::size_t n = cloud.size();
    const int K = cloud.coeffs_per_channel();
    const int rest = 3 * (K - 1);
    std::string header = "ply\nformat binary_little_endian 1.0\nelement vertex " + std::to_string(n) + "\n";
    for (const char* p : {"x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"})
        header += std::string("property float ") + p + "\n";
    for (int j = 0; j < rest; ++j) header += "property float f_rest_" + std::to_string(j) + "\n";
    for (const char* p : {"opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"})
        header += std::string("property float ") + p + "\n";
    header += "end_header\n";
    const std::size_t nfloats = 9 + std::size_t(rest) + 8;
    const std::size_t rs = nfloats * 4;

    io::AtomicFileWriter out(path);
    out.write(header.data(), header.size());
    constexpr std::size_t kChunk = 1 << 16;
    std::vector<std::uint8_t> buf(std::min(n, kChunk) * rs);
    for (std::size_t c0 = 0; c0 < n; c0 += kChunk) {
        const std::size_t c1 = std::min(n, c0 + kChunk);
        tbb::parallel_for(tbb::blocked_range<std::size_t>(c0, c1, 4096), [&](const tbb::blocked_range<std::size_t>& r) {
            for (std::size_t i = r.begin(); i != r.end(); ++i) {
                std::uint8_t* p = buf.data() + (i - c0) * rs;
                auto put = [&p](float v) {
                    io::store_f32le(p, v);
                    p += 4;
                };
                for (int j = 0; j < 3; ++j) put(cloud.positions[3 * i + j]);
                put(0.0f), put(0.0f), put(0.0f);
                const float* sh = &cloud.sh[i * std::size_t(K) * 3];
                for (int ch = 0; ch < 3; ++ch) put(sh[ch]);
                for (int ch = 0; ch < 3; ++ch)
                    for (int j = 1; j < K; ++j) put(sh[j * 3 + ch]);
                // Clamp before logit / log so that the file holds no Inf (fmin/fmax also map NaN to the bound).
                // The stored value is one the reader maps back to the cloud's exactly (stored_value_for), so an
                // untouched round trip keeps every value, and a file we wrote is rewritten byte for byte.
                const double a = std::fmin(std::fmax(double(cloud.opacities[i]), 1e-7), 1.0 - 1e-7);
                put(io::stored_value_for(cloud.opacities[i], float(std::log(a / (1.0 - a))), decode_opacity));
                for (int j = 0; j < 3; ++j)
                    put(io::stored_value_for(cloud.scales[3 * i + j],
                                             float(std::log(std::fmax(double(cloud.scales[3 * i + j]), 1e-30))), decode_scale));
                float q[4];
                stored_rotation(&cloud.rotations[4 * i], q);
                for (int j = 0; j < 4; ++j) put(q[j]);
            }
        });
        out.write(buf.data(), (c1 - c0) * rs);
    }
    out.commit();
}

}  // namespace raysplats
