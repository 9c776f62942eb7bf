// The layout the data-pass and denoising-guide tests share: a 32 x 24 orthographic camera (ortho scale 8) 10 units
// above a mesh floor z = 0 that covers x < 0, and two flat Gaussians (sigma 0.7, opacity 0.9) in the plane z = 2 at
// x = -1.5 (over the floor) and x = 1.5 (over the world); their closed forms need the layer's alpha at each pixel.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>

#include "raysplats/render/render_settings.h"

namespace raysplats::testing::half_floor {

constexpr int kWidth = 32, kHeight = 24;
constexpr float kCameraHeight = 10.0f, kOrthoScale = 8.0f;
constexpr float kLayerZ = 2.0f, kSigma = 0.7f, kOpacity = 0.9f, kCentreX = 1.5f;

// Every sample through the pixel centre (no jitter).
inline RenderSettings pixel_centre_settings(Compositing compositing, int samples) {
    RenderSettings s;
    s.width = kWidth, s.height = kHeight, s.samples = samples;
    s.jitter = false;
    s.compositing = compositing;
    return s;
}

// The world x and y of pixel (i, j)'s centre ray (row 0 at the top).
inline void pixel_point(int i, int j, double& x, double& y) {
    const double half_w = 0.5 * kOrthoScale, half_h = half_w * kHeight / kWidth;
    x = (2.0 * (i + 0.5) / kWidth - 1.0) * half_w;
    y = (1.0 - 2.0 * (j + 0.5) / kHeight) * half_h;
}

// The Gaussian layer's alpha at (x, y) of its plane, as the core clamps and cuts it (its disks end at Mahalanobis
// radius 3, gaussian_primitives.h): 1 - prod(1 - a_i).
inline double layer_alpha(double x, double y) {
    double transmittance = 1.0;
    for (double cx : {double(kCentreX), -double(kCentreX)}) {
        const double r2 = ((x - cx) * (x - cx) + y * y) / (kSigma * kSigma);
        double a = kOpacity * std::exp(-0.5 * r2);
        a = a < 1.0 / 255.0 || r2 > 9.0 ? 0.0 : std::min(a, 0.99);
        transmittance *= 1.0 - a;
    }
    return 1.0 - transmittance;
}

// What the closed forms need of pixel (i, j): its index in the film, its centre ray's world x and y, the Gaussian
// layer's alpha there and whether the floor lies behind.
struct Pixel {
    int i, j;
    std::size_t index;
    double x, y, alpha;
    bool on_floor;
};

// Calls check(pixel) for every pixel, row by row.
template <class Check>
void for_each_pixel(Check&& check) {
    for (int j = 0; j < kHeight; ++j)
        for (int i = 0; i < kWidth; ++i) {
            Pixel px{i, j, std::size_t(j) * kWidth + i, 0.0, 0.0, 0.0, false};
            pixel_point(i, j, px.x, px.y);
            px.alpha = layer_alpha(px.x, px.y);
            px.on_floor = px.x < 0.0;
            check(px);
        }
}

}  // namespace raysplats::testing::half_floor
