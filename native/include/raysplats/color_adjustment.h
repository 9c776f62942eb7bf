// Colour adjustments of a Gaussian object: exposure, brightness, saturation, hue and temperature, applied
// to the Gaussians' SH so that the render, the viewport's colour attribute and every export show the same colours.
//
// All five are affine maps of the display colour c (docs/design.md §4: c(d) = 0.5 + Σ_k Y_k(d) f_k, sRGB display
// values), so together they are one map c' = M c + b, applied in this order:
//   exposure     c *= 2^exposure                                  (stops)
//   temperature  c *= (1 + 0.2 t, 1, 1 - 0.2 t)                    (t in [-1, 1]: warmer > 0, cooler < 0)
//   saturation   c = L c + s (c - L c), L c = Rec. 709 luma on all three channels (s = 1: unchanged, 0: grey)
//   hue          rotation of c about the grey axis (1, 1, 1) by 2π hue (hue in turns)
//   brightness   c += brightness                                   (display units)
// Because c is linear in the SH coefficients, the map applies exactly to the SH: f_0' = M f_0 + (M 0.5 + b - 0.5) /
// SH_C0 for the DC term (Y_0 = SH_C0 is constant), f_k' = M f_k for every higher coefficient. View-dependent colour is
// adjusted exactly (before the clamp at 0), and a degree-0 scene gets the same colours as a degree-3 one.
#pragma once

#include <cstddef>
#include <cstdint>

namespace raysplats {

struct ColorAdjustment {
    double exposure = 0.0;     // stops
    double brightness = 0.0;   // added to the display colour
    double saturation = 1.0;   // 1 unchanged, 0 grey
    double hue = 0.0;          // turns
    double temperature = 0.0;  // -1 cool .. 1 warm

    bool is_identity() const {
        return exposure == 0.0 && brightness == 0.0 && saturation == 1.0 && hue == 0.0 && temperature == 0.0;
    }
};

// The adjustment as the affine map of display colours c' = matrix c + offset (matrix row-major 3x3).
struct AffineColorMap {
    double matrix[9];
    double offset[3];
};
AffineColorMap color_adjustment_map(const ColorAdjustment& adjustment);  // throws InvalidArgument if not finite

// Adjusts SH coefficients in place: `count` Gaussians of sh_coeff_count(sh_degree) coefficients, layout [i][k][rgb].
// Multi-threaded.
void apply_color_adjustment(const ColorAdjustment& adjustment, int sh_degree, float* sh, std::size_t count);

// The colour attribute of a splat mesh (objects/polygon_mesh.py's "gs_color", a byte colour attribute): per corner the sRGB
// bytes of the adjusted SH DC colour (clamped to [0, 1]; Blender gives them to shaders as linear RGB) and A = the face's
// opacity x 255, rounded. sh_dc and opacity per face; corners of face f are [face_corner_start[f], +
// face_corner_count[f]) in out_rgba (4 bytes per corner, corner_count of them; corners of no face are left as they
// are). Throws InvalidArgument for corners outside corner_count.
void splat_corner_colors(const ColorAdjustment& adjustment, const float* sh_dc, const float* opacity,
                         std::size_t face_count, const std::int32_t* face_corner_start,
                         const std::int32_t* face_corner_count, std::size_t corner_count, std::uint8_t* out_rgba);

// Byte colours as Blender reads them (its `.color`): `count` RGBA byte quadruples, sRGB RGB and linear A, to linear
// floats (4 per colour).
void byte_colors_to_linear(const std::uint8_t* rgba8, std::size_t count, float* out_rgba);

}  // namespace raysplats
