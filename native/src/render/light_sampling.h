// Next-event estimation samples of the lights of light.h (internal).
#pragma once

#include <glm/glm.hpp>

#include "raysplats/render/light.h"
#include "render_math.h"

namespace raysplats {

struct LightSample {
    glm::vec3 wi;       // unit direction from the shading point towards the light
    float distance;     // to the sampled point on the light; +inf for the sun
    glm::vec3 value;    // incident radiance / pdf (solid angle): the contribution is f * cos * value * visibility
    float pdf = 0.0f;   // solid-angle pdf of the sample for MIS; 0 for delta lights (point, spot, sun of angle 0)
};

// A ray from o along unit d hitting the emitting (front) side of an area light before tmax: like Cycles
// (kernel/light/light.h lights_intersect), area lights are seen by rays (they do not occlude anything).
struct LightHit {
    float t;
    glm::vec3 radiance;  // emitted radiance towards the ray origin
    float pdf;           // solid-angle pdf with which sample_light would have chosen this point from o
};
bool intersect_light(const Light& light, const glm::vec3& o, const glm::vec3& d, float tmax, LightHit& out);

// Power heuristic (Veach 1997), as Cycles' power_heuristic.
inline float power_heuristic(float a, float b) { return a * a / (a * a + b * b); }

// Returns false when the light cannot reach p (behind an area light, outside a spot cone, zero power).
bool sample_light(const Light& light, const glm::vec3& p, Sampler& rng, LightSample& out);

}  // namespace raysplats
