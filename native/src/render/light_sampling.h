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
};

// Returns false when the light cannot reach p (behind an area light, outside a spot cone, zero power).
bool sample_light(const Light& light, const glm::vec3& p, Sampler& rng, LightSample& out);

}  // namespace raysplats
