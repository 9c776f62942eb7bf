// antimatter15 .splat reader and writer: headerless 32-byte records, little endian:
//   float32 position[3], float32 scale[3] (linear), uint8 rgba, uint8 rotation[4] (w x y z as q*128+128).
// Colour: rgb = 0.5 + C0 * dc (so dc = (rgb/255 - 0.5) / C0), alpha = linear opacity. Only SH degree 0.
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>

#include "core/color_math.h"
#include "io/io_common.h"
#include "io/splat_formats.h"
#include "raysplats/splat_io.h"

namespace raysplats {
namespace {

constexpr std::size_t kRecord = 32;

inline float load_f32le(const std::uint8_t* p) {
    const std::uint32_t u = io::load_u32le(p);
    float v;
    std::memcpy(&v, &u, 4);
    return v;
}

// Rounds to the nearest byte, clamped to 0..255 (NaN gives 0).
inline std::uint8_t to_byte(double x) {
    if (!(x > 0.0)) return 0;
    if (x >= 255.0) return 255;
    return static_cast<std::uint8_t>(std::lround(x));
}

// The reader's rotation of four stored bytes: (b - 128) / 128, then finalize_cloud's normalisation.
inline bool decode_rotation(const int k[4], float q[4]) {
    const float raw[4] = {float(k[0] / 128.0), float(k[1] / 128.0), float(k[2] / 128.0), float(k[3] / 128.0)};
    return io::normalise_quaternion(raw, q);
}

// The four rotation bytes of a unit quaternion q (w x y z). Stored bytes hold q * |k| for some length |k| near
// 128, rounded (writers differ: the antimatter15 converter truncates (q/|q|)*128+128), and the reader normalises,
// so rounding q * 128 often gives a byte vector that reads back as another quaternion: 44 % of the records of a
// real file changed on an untouched round trip. So: the bytes k whose reading is q exactly, trying q * 128
// rounded first and then every length (k's largest component c = 128 .. 1, the others in proportion; the
// original bytes are among these, since k / c = q / q_max exactly up to float rounding), preferring the length
// nearest 128 (what normalising writers store). A quaternion no bytes read back as (an edited one) gets the
// nearest bytes, q * 128 rounded.
void encode_rotation(const float* q_in, std::uint8_t* out) {
    // q as it is (normalising an already normalised float quaternion again may move it by an ulp, and then no
    // bytes read back as it), unless it is not a usable rotation.
    float q[4];
    std::copy(q_in, q_in + 4, q);
    float unit[4];
    if (!io::normalise_quaternion(q_in, unit)) q[0] = 1.0f, q[1] = q[2] = q[3] = 0.0f;
    else if (std::fabs(double(unit[0]) - q[0]) + std::fabs(double(unit[1]) - q[1]) + std::fabs(double(unit[2]) - q[2]) +
                 std::fabs(double(unit[3]) - q[3]) > 1e-6)
        std::copy(unit, unit + 4, q);  // not a unit quaternion (a cloud made by hand): its direction
    int k[4];
    float back[4];
    for (int j = 0; j < 4; ++j) k[j] = int(to_byte(q[j] * 128.0 + 128.0)) - 128;
    const bool exact_first = decode_rotation(k, back) && io::same_quaternion(back, q);
    if (!exact_first) {
        int largest = 0;
        for (int j = 1; j < 4; ++j)
            if (std::fabs(q[j]) > std::fabs(q[largest])) largest = j;
        const double q_max = std::fabs(double(q[largest]));
        double best_distance = 1e30;
        for (int c = 128; c >= 1 && q_max > 0; --c) {
            int trial[4];
            bool fits = true;
            for (int j = 0; j < 4; ++j) {
                trial[j] = int(std::lround(double(q[j]) * c / q_max));
                fits &= trial[j] >= -128 && trial[j] <= 127;
            }
            if (!fits || !decode_rotation(trial, back) || !io::same_quaternion(back, q)) continue;
            const double length = std::sqrt(double(trial[0]) * trial[0] + double(trial[1]) * trial[1] +
                                            double(trial[2]) * trial[2] + double(trial[3]) * trial[3]);
            if (std::fabs(length - 128.0) < best_distance) {
                best_distance = std::fabs(length - 128.0);
                std::copy(trial, trial + 4, k);
            }
        }
    }
    for (int j = 0; j < 4; ++j) out[j] = std::uint8_t(k[j] + 128);
}

}  // namespace

namespace io {
// No header: only the name says a file is .splat (and then other formats need their full signature).
Evidence detect_dot_splat(const std::uint8_t*, std::size_t, const std::string& name, bool) {
    return lower_extension(name) == ".splat" ? Evidence::Name : Evidence::None;
}

// The count from the size: the file is nothing but records.
SplatFileSummary probe_dot_splat(const FileBytes& f) { return {SplatFormat::Splat, f.size() / kRecord, 0}; }

GaussianCloud read_dot_splat(const FileBytes& f, const ReadOptions& options, LoadReport* report) {
    const std::string& path = f.path();
    if (f.size() == 0) throw FileFormatError(path, "file is empty");
    if (f.size() % kRecord != 0)
        throw FileFormatError(path, "size " + std::to_string(f.size()) + " bytes is not a multiple of the 32-byte .splat record (" +
                                        std::to_string(f.size() % kRecord) + " trailing bytes: truncated or not a .splat file)",
                              f.size() - f.size() % kRecord);
    const std::size_t n = f.size() / kRecord;
    GaussianCloud c;
    c.resize(n, 0);
    const std::uint8_t* base = f.data();
    // The format stores linear scales, so a sign is possible, and some writers leave one (a scale is the length of
    // an axis: its sign means nothing, the covariance R diag(s)^2 R^T is the same). Read as its magnitude, counted:
    // passed on as stored, the core's own check (GaussianCloud::check_values) refused the cloud later.
    std::atomic<std::size_t> negative{0};
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, io::kGrain), [&](const tbb::blocked_range<std::size_t>& r) {
        std::size_t local_negative = 0;
        for (std::size_t i = r.begin(); i != r.end(); ++i) {
            const std::uint8_t* p = base + i * kRecord;
            for (int j = 0; j < 3; ++j) c.positions[3 * i + j] = load_f32le(p + 4 * j);
            bool any_negative = false;
            for (int j = 0; j < 3; ++j) {
                const float s = load_f32le(p + 12 + 4 * j);
                any_negative |= s < 0.0f;
                c.scales[3 * i + j] = std::fabs(s);
            }
            local_negative += any_negative;
            for (int j = 0; j < 3; ++j) c.sh[3 * i + j] = float(display_to_sh_dc(p[24 + j] / 255.0));
            c.opacities[i] = float(p[27] / 255.0);
            for (int j = 0; j < 4; ++j) c.rotations[4 * i + j] = float((p[28 + j] - 128.0) / 128.0);
        }
        negative += local_negative;
    });
    io::finalize_cloud(c, options, report);  // resets the report
    if (report && negative) {
        report->negative_scale_repaired = negative;
        report->warnings.push_back(std::to_string(negative.load()) +
                                   " splat(s) with a negative scale: read as its magnitude");
    }
    return c;
}
}  // namespace io

GaussianCloud read_dot_splat(const std::string& path, const ReadOptions& options, LoadReport* report) {
    return io::read_dot_splat(io::FileBytes(path), options, report);
}

void write_dot_splat(const std::string& path, const GaussianCloud& cloud) {
    io::check_writable(cloud);
    const std::size_t n = cloud.size();
    const std::size_t K3 = std::size_t(cloud.coeffs_per_channel()) * 3;
    io::AtomicFileWriter out(path);
    constexpr std::size_t kChunk = 1 << 16;
    std::vector<std::uint8_t> buf(std::min(n, kChunk) * kRecord);
    for (std::size_t c0 = 0; c0 < n; c0 += kChunk) {
        const std::size_t c1 = std::min(n, c0 + kChunk);
        tbb::parallel_for(tbb::blocked_range<std::size_t>(c0, c1, 4096), [&](const tbb::blocked_range<std::size_t>& r) {
            for (std::size_t i = r.begin(); i != r.end(); ++i) {
                std::uint8_t* p = buf.data() + (i - c0) * kRecord;
                for (int j = 0; j < 3; ++j) io::store_f32le(p + 4 * j, cloud.positions[3 * i + j]);
                for (int j = 0; j < 3; ++j) io::store_f32le(p + 12 + 4 * j, cloud.scales[3 * i + j]);
                // Rounded to the nearest step (the antimatter15 converter truncates; decoding is the same).
                for (int j = 0; j < 3; ++j) p[24 + j] = to_byte(sh_dc_to_display(cloud.sh[i * K3 + j]) * 255.0);
                p[27] = to_byte(double(cloud.opacities[i]) * 255.0);
                encode_rotation(&cloud.rotations[4 * i], p + 28);
            }
        });
        out.write(buf.data(), (c1 - c0) * kRecord);
    }
    out.commit();
}

}  // namespace raysplats
