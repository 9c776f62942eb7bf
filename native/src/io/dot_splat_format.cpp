// antimatter15 .splat reader and writer: headerless 32-byte records, little endian:
//   float32 position[3], float32 scale[3] (linear), uint8 rgba, uint8 rotation[4] (w x y z as q*128+128).
// Colour: rgb = 0.5 + C0 * dc (so dc = (rgb/255 - 0.5) / C0), alpha = linear opacity. Only SH degree 0.
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstring>

#include "io/io_common.h"
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

}  // namespace

GaussianCloud read_dot_splat(const std::string& path, const ReadOptions& options, LoadReport* report) {
    io::FileBytes f(path);
    if (f.size() == 0) throw FileFormatError(path, "file is empty");
    if (f.size() % kRecord != 0)
        throw FileFormatError(path, "size " + std::to_string(f.size()) + " bytes is not a multiple of the 32-byte .splat record (" +
                                        std::to_string(f.size() % kRecord) + " trailing bytes: truncated or not a .splat file)",
                              f.size() - f.size() % kRecord);
    const std::size_t n = f.size() / kRecord;
    GaussianCloud c;
    c.resize(n, 0);
    const std::uint8_t* base = f.data();
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, io::kGrain), [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i) {
            const std::uint8_t* p = base + i * kRecord;
            for (int j = 0; j < 3; ++j) c.positions[3 * i + j] = load_f32le(p + 4 * j);
            for (int j = 0; j < 3; ++j) c.scales[3 * i + j] = load_f32le(p + 12 + 4 * j);
            for (int j = 0; j < 3; ++j) c.sh[3 * i + j] = float((p[24 + j] / 255.0 - 0.5) / io::kShC0);
            c.opacities[i] = float(p[27] / 255.0);
            for (int j = 0; j < 4; ++j) c.rotations[4 * i + j] = float((p[28 + j] - 128.0) / 128.0);
        }
    });
    io::finalize_cloud(c, options, report);
    return c;
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
                for (int j = 0; j < 3; ++j) p[24 + j] = to_byte((0.5 + io::kShC0 * cloud.sh[i * K3 + j]) * 255.0);
                p[27] = to_byte(double(cloud.opacities[i]) * 255.0);
                const float* q = &cloud.rotations[4 * i];
                const double nq = std::sqrt(double(q[0]) * q[0] + double(q[1]) * q[1] + double(q[2]) * q[2] + double(q[3]) * q[3]);
                for (int j = 0; j < 4; ++j) {
                    const double v = nq > 0.0 ? q[j] / nq : (j == 0 ? 1.0 : 0.0);
                    p[28 + j] = to_byte(v * 128.0 + 128.0);
                }
            }
        });
        out.write(buf.data(), (c1 - c0) * kRecord);
    }
    out.commit();
}

}  // namespace raysplats
