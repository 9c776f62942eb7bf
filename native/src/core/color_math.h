// Colour numerics shared by the core, the renderer and the file formats (internal): the sRGB transfer and the
// display colour of a Gaussian's degree-0 SH term. One definition each; where call sites clamp differently, the
// clamp is named here or written at the call site, so that every caller keeps its exact results.
#pragma once

#include <cmath>
#include <cstdint>

#include "raysplats/spherical_harmonics.h"

namespace raysplats {

// sRGB (IEC 61966-2-1) display value to linear, extended above 1 with the same power law (the renderer's colours
// may exceed 1).
inline float srgb_to_linear(float c) {
    if (c <= 0.04045f) return c / 12.92f;
    return std::pow((c + 0.055f) / 1.055f, 2.4f);
}
inline float linear_to_srgb(float c) {
    if (c <= 0.0031308f) return 12.92f * c;
    return 1.055f * std::pow(c, 1.0f / 2.4f) - 0.055f;
}

// srgb_to_linear for the renderer's per-pixel conversions (BlendSpace::Display): on [0, 1) by linear interpolation in
// a table of 4097 values of the exact curve (the interpolation error is at most f'' h^2 / 8 = 3.0 / 4096^2 / 8 =
// 2.2e-8, below the float resolution of the result near 1), elsewhere srgb_to_linear. About 10x cheaper than powf,
// which made display-space renders measurably slower (bench_render; docs/benchmarks.md).
inline float srgb_to_linear_tabulated(float c) {
    struct Table {
        float v[4097];
        Table() {
            for (int i = 0; i <= 4096; ++i) {
                const double x = i / 4096.0;
                v[i] = float(x <= 0.04045 ? x / 12.92 : std::pow((x + 0.055) / 1.055, 2.4));
            }
        }
    };
    static const Table table;
    if (!(c >= 0.0f && c < 1.0f)) return srgb_to_linear(c);
    const float x = c * 4096.0f;
    const int i = int(x);
    const float f = x - float(i);
    return table.v[i] + f * (table.v[i + 1] - table.v[i]);
}

// c limited to [0, 1]; NaN stays NaN.
inline float clamp_unit(float c) { return c < 0.0f ? 0.0f : (c > 1.0f ? 1.0f : c); }

// The transfer for colours stored in [0, 1] (mesh colour attributes, 8-bit sRGB): clamped first.
inline float srgb_to_linear_clamped(float c) { return srgb_to_linear(clamp_unit(c)); }
inline float linear_to_srgb_clamped(float c) { return linear_to_srgb(clamp_unit(c)); }

// Display (sRGB) colour channel of a Gaussian's degree-0 SH coefficient f_dc, 0.5 + SH_C0 f_dc (reference 3DGS
// SH2RGB; docs/design.md §4), unclamped, and its inverse.
inline double sh_dc_to_display(double f_dc) { return 0.5 + kShC0 * f_dc; }
inline double display_to_sh_dc(double display) { return (display - 0.5) / kShC0; }
// The same in single precision, as the renderer precomputes degree-0 colours (its images depend on this rounding,
// which can differ from float(sh_dc_to_display(f_dc)) in the last bit).
inline float sh_dc_to_display_single(float f_dc) { return 0.5f + float(kShC0) * f_dc; }

// Linear colour channel of a Gaussian's degree-0 SH term for mesh colour attributes: the display value clamped to
// [0, 1] (docs/design.md §4) and decoded.
inline float sh_dc_to_linear_unit(double f_dc) { return srgb_to_linear_clamped(float(sh_dc_to_display(f_dc))); }

// A value in [0, 1] as a byte, rounded (clamped first; NaN gives 0), as 8-bit colours store it.
inline std::uint8_t unit_to_byte(double v) { return v > 0.0 ? (v < 1.0 ? std::uint8_t(v * 255.0 + 0.5) : 255) : 0; }

// The sRGB byte of a Gaussian's degree-0 SH term for byte colour attributes (Blender stores byte colours sRGB-encoded
// and gives them to shaders and Python as linear, srgb_to_linear(byte / 255), the sh_dc_to_linear_unit of the float
// attribute they replaced to 8-bit precision): the display value clamped to [0, 1].
inline std::uint8_t sh_dc_to_srgb_byte(double f_dc) { return unit_to_byte(sh_dc_to_display(f_dc)); }

}  // namespace raysplats
