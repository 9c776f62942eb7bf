// Visibility of light samples (internal; docs/design.md §6): the product of Gaussian transmittance and mesh occlusion
// along a shadow ray, so that splats cast soft, semi-transparent shadows on meshes.
#pragma once

#include <glm/glm.hpp>

#include "ray.h"
#include "raysplats/render/render_settings.h"
#include "render_math.h"
#include "scene_impl.h"

namespace raysplats {

class ShadowVisibility {
public:
    ShadowVisibility(const Scene::Impl& scene, const RenderSettings& settings) : s_(scene), st_(settings) {}

    // Visibility of a light sample: Gaussian transmittance x mesh occlusion (meshes_only: meshes alone). `time`:
    // the shutter time of the path it shades (Ray::time).
    float shadow(const glm::vec3& o, const glm::vec3& d, float dist, float time, bool meshes_only, Counters& c) const;

    // Fraction of the lights' unshadowed irradiance that reaches a Gaussian centre past the meshes.
    float gaussian_light_visibility(const glm::vec3& p, float time, Sampler& rng, Counters& c) const;

private:
    const Scene::Impl& s_;
    const RenderSettings& st_;
};

}  // namespace raysplats
