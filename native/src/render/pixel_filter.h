// The pixel filter (RenderSettings::pixel_filter, filter_width), applied the way Cycles applies it: by importance
// sampling. Each camera sample's offset from the pixel centre is drawn from the filter's distribution, separably in
// x and y, and every sample weighs the same, so a pixel's mean is the filter-weighted integral of the image around
// it (Cycles: scene/film.cpp filter_table, kernel/film lookups of the inverted CDF).
//
// Widths are Cycles' (Render > Film > Pixel Filter, in pixels): the box spans [-w/2, w/2]; the Gaussian is
// exp(-8 x^2 / w^2) (sigma = w/4) on [-3w/2, 3w/2]; Blackman-Harris is the 4-term window spanning [-w, w].
// A box of width 1 reproduces the plain jitter of earlier versions bit for bit (0.5 + 1 * (u - 0.5) == u for the
// sampler's multiples of 2^-24).
#pragma once

#include <vector>

#include "raysplats/render/render_settings.h"

namespace raysplats {

class PixelFilterSampler {
public:
    PixelFilterSampler(PixelFilter filter, float width);
    // Where along one axis a sample falls, in pixels from the pixel's left (top) edge, for u uniform in [0, 1).
    float position(float u) const;
    // The farthest a sample of `filter` falls from its pixel's centre, in pixels, along either axis.
    static float reach(PixelFilter filter, float width);

private:
    PixelFilter filter_;
    float width_;
    // Non-box filters: the inverse of the filter's CDF at u = i / (size - 1), as offsets from the centre.
    std::vector<float> inverse_cdf_;
};

}  // namespace raysplats
