#include "raysplats/color_adjustment.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <cmath>
#include <string>

#include "core/color_math.h"
#include "core/linear_algebra.h"
#include "raysplats/errors.h"
#include "raysplats/gaussian_cloud.h"

namespace raysplats {
namespace {

constexpr std::size_t kGrain = 4096;
constexpr double kPi = 3.14159265358979323846;
// Rec. 709 luma weights (of the display values, as image editors' saturation does).
constexpr double kLuma[3] = {0.2126, 0.7152, 0.0722};
// Gain per unit temperature on red (and its negative on blue).
constexpr double kTemperatureGain = 0.2;

la::Mat3 diagonal(double r, double g, double b) {
    la::Mat3 m;
    m(0, 0) = r, m(1, 1) = g, m(2, 2) = b;
    return m;
}

// The DC offset of the map in SH units: (M 0.5 + b - 0.5) / SH_C0 per channel.
void dc_offset(const AffineColorMap& map, double out[3]) {
    for (int r = 0; r < 3; ++r) {
        const double half = 0.5 * (map.matrix[3 * r] + map.matrix[3 * r + 1] + map.matrix[3 * r + 2]);
        out[r] = (half + map.offset[r] - 0.5) / kShC0;
    }
}

}  // namespace

AffineColorMap color_adjustment_map(const ColorAdjustment& a) {
    const double values[5] = {a.exposure, a.brightness, a.saturation, a.hue, a.temperature};
    const char* names[5] = {"exposure", "brightness", "saturation", "hue", "temperature"};
    for (int i = 0; i < 5; ++i)
        if (!std::isfinite(values[i]))
            throw InvalidArgument(std::string("colour adjustment '") + names[i] + "' is not a finite number");
    const double gain = std::exp2(a.exposure);
    const la::Mat3 exposure = diagonal(gain, gain, gain);
    const la::Mat3 temperature = diagonal(1.0 + kTemperatureGain * a.temperature, 1.0, 1.0 - kTemperatureGain * a.temperature);
    la::Mat3 saturation;  // s I + (1 - s) L, L with every row the luma weights
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) saturation(r, c) = (r == c ? a.saturation : 0.0) + (1.0 - a.saturation) * kLuma[c];
    // Rodrigues' rotation about the unit grey axis u = (1, 1, 1) / sqrt 3: cos θ I + sin θ [u]x + (1 - cos θ) u u^T.
    const double theta = 2.0 * kPi * a.hue, cos_t = std::cos(theta), sin_t = std::sin(theta);
    const double u = 1.0 / std::sqrt(3.0);
    la::Mat3 hue;
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) hue(r, c) = (r == c ? cos_t : 0.0) + (1.0 - cos_t) * u * u;
    hue(0, 1) -= sin_t * u, hue(1, 0) += sin_t * u;
    hue(0, 2) += sin_t * u, hue(2, 0) -= sin_t * u;
    hue(1, 2) -= sin_t * u, hue(2, 1) += sin_t * u;
    const la::Mat3 m = hue * (saturation * (temperature * exposure));
    AffineColorMap map;
    for (int i = 0; i < 9; ++i) map.matrix[i] = m.m[i];
    for (int r = 0; r < 3; ++r) map.offset[r] = a.brightness;
    return map;
}

void apply_color_adjustment(const ColorAdjustment& adjustment, int sh_degree, float* sh, std::size_t count) {
    if (sh_degree < 0 || sh_degree > 3)
        throw InvalidArgument("SH degree " + std::to_string(sh_degree) + " is not 0..3");
    if (adjustment.is_identity()) return;
    const AffineColorMap map = color_adjustment_map(adjustment);
    double offset[3];
    dc_offset(map, offset);
    const int coeffs = sh_coeff_count(sh_degree);
    const double* m = map.matrix;
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, count, kGrain), [&](const auto& range) {
        for (std::size_t i = range.begin(); i != range.end(); ++i) {
            for (int k = 0; k < coeffs; ++k) {
                float* f = &sh[(i * std::size_t(coeffs) + std::size_t(k)) * 3];
                const double r = f[0], g = f[1], b = f[2];
                for (int c = 0; c < 3; ++c)
                    f[c] = float(m[3 * c] * r + m[3 * c + 1] * g + m[3 * c + 2] * b + (k == 0 ? offset[c] : 0.0));
            }
        }
    });
}

void splat_corner_colors(const ColorAdjustment& adjustment, const float* sh_dc, const float* opacity,
                         std::size_t face_count, const std::int32_t* face_corner_start,
                         const std::int32_t* face_corner_count, std::size_t corner_count, std::uint8_t* out_rgba) {
    for (std::size_t f = 0; f < face_count; ++f) {
        const std::int64_t start = face_corner_start[f], n = face_corner_count[f];
        if (start < 0 || n < 0 || std::size_t(start + n) > corner_count)
            throw InvalidArgument("face " + std::to_string(f) + " has corners outside the mesh's " +
                                  std::to_string(corner_count));
    }
    const AffineColorMap map = color_adjustment_map(adjustment);
    double offset[3];
    dc_offset(map, offset);
    const bool identity = adjustment.is_identity();
    const double* m = map.matrix;
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, face_count, kGrain), [&](const auto& range) {
        for (std::size_t f = range.begin(); f != range.end(); ++f) {
            const float* dc = &sh_dc[3 * f];
            std::uint8_t rgba[4];
            for (int c = 0; c < 3; ++c) {
                // Unadjusted, exactly the import's colours (gaussians_to_polygons' corner colours).
                const float adjusted = identity ? dc[c]
                    : float(m[3 * c] * dc[0] + m[3 * c + 1] * dc[1] + m[3 * c + 2] * dc[2] + offset[c]);
                rgba[c] = sh_dc_to_srgb_byte(adjusted);
            }
            rgba[3] = opacity ? unit_to_byte(opacity[f]) : 255;
            for (std::int64_t k = 0; k < face_corner_count[f]; ++k)
                for (int c = 0; c < 4; ++c) out_rgba[4 * std::size_t(face_corner_start[f] + k) + c] = rgba[c];
        }
    });
}

void byte_colors_to_linear(const std::uint8_t* rgba8, std::size_t count, float* out_rgba) {
    for (std::size_t i = 0; i < 4 * count; ++i)
        out_rgba[i] = (i % 4 == 3) ? rgba8[i] / 255.0f : srgb_to_linear(rgba8[i] / 255.0f);
}

}  // namespace raysplats
