// The ray every tracer of the renderer takes, and the traversal statistics they count (internal).
#pragma once

#include <cstdint>
#include <limits>

#include <glm/glm.hpp>

namespace raysplats {

constexpr float kInf = std::numeric_limits<float>::infinity();

// The segment [tmin, tmax] of the ray o + t d (world space; d as the camera or the BSDF made it).
struct Ray {
    glm::vec3 o, d;
    float tmin, tmax;
    // A camera ray (or its continuation through a surface it passed): the distance from the camera at t = 0, which
    // the Mist pass measures (mist.h). Negative for every other ray, which computes no mist.
    float camera_distance = -1.0f;
    // Motion blur: when in the shutter the ray is traced, 0 at its opening and 1 at its closing (Embree's
    // RTCRay::time, at which instances with time steps are placed). A camera ray draws it and every ray of its path
    // keeps it; without motion it is 0 and nothing reads it.
    float time = 0.0f;
};

// Per tile, summed into Film::stats: traversals, Gaussians composited, and the Gaussian / group tests the callbacks
// made (LaneState::candidates, LaneState::group_candidates).
struct Counters {
    std::uint64_t traced = 0, gaussian_hits = 0, candidates = 0, group_candidates = 0;
};

}  // namespace raysplats
