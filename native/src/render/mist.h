// The Mist pass's function of distance (internal; film.h, SampleRecord::mist). Cycles, kernel/film/data_passes.h,
// film_write_data_passes: every surface a camera ray meets adds (1 - mist(d)) * its weight (the transmittance in front
// of it times its alpha) to the pixel, and the pass is 1 minus that sum, so that what no surface covers (the world)
// has mist 1; mist(d) = clamp((d - start) / depth, 0, 1) ^ falloff, d the surface's distance from the camera
// (kernel/camera/camera.h, camera_distance: along the view axis for an orthographic camera, the ray's length else).
#pragma once

#include <algorithm>
#include <cmath>

#include "raysplats/render/light.h"

namespace raysplats {

// 1 - mist(distance): what a surface at `distance` adds to the Mist pass's sum per unit weight.
inline float mist_clearance(const World& world, float distance) {
    // Cycles' film: mist_inv_depth = depth > 0 ? 1 / depth : 0.
    const float inv_depth = world.mist_depth > 0.0f ? 1.0f / world.mist_depth : 0.0f;
    float mist = std::clamp((distance - world.mist_start) * inv_depth, 0.0f, 1.0f);
    if (world.mist_falloff == 2.0f) mist *= mist;
    else if (world.mist_falloff == 0.5f) mist = std::sqrt(mist);
    else if (world.mist_falloff != 1.0f) mist = std::pow(mist, world.mist_falloff);
    return 1.0f - mist;
}

}  // namespace raysplats
