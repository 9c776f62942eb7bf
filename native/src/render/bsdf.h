// The surface scattering model of Material (internal): a Lambertian base, GGX reflection (Walter et al. 2007,
// "Microfacet Models for Refraction through Rough Surfaces") for metals and the dielectric specular layer, and
// a dielectric glass lobe with exact Fresnel. Lobes are picked by one-sample selection; the non-delta lobes
// share one combined pdf so that light sampling (NEE) and BSDF sampling agree.
#pragma once

#include <glm/glm.hpp>

#include "raysplats/render/material.h"
#include "render_math.h"

namespace raysplats {

constexpr float kDeltaRoughness = 0.02f;  // below this roughness the GGX lobes are perfectly specular

// Linear base colour of a material at the UVs (texture if present).
glm::vec3 material_base_color(const Material& m, const glm::vec2& uv);

// Exact unpolarised Fresnel reflectance for a ray from a medium into one with relative index eta = n_t / n_i.
// Sets cos_t; returns 1 on total internal reflection.
float fresnel_dielectric(float cos_i, float eta, float& cos_t);

struct Bsdf {
    glm::vec3 n;          // shading normal, on the side of wo
    glm::vec3 base;
    float alpha = 0.25f;  // GGX roughness alpha = roughness^2
    float ior = 1.45f;
    bool entering = true;  // wo is on the outside (front) of the surface
    float w_diffuse = 1, w_metal = 0, w_dielectric_spec = 0, w_glass = 0;
    float f0_dielectric = 0.04f;
    float q_diffuse = 1, q_spec = 0, q_glass = 0;  // lobe selection probabilities
    bool spec_delta = false;

    Bsdf(const Material& m, const glm::vec3& base_color, const glm::vec3& shading_normal, bool entering);

    bool has_non_delta() const { return q_diffuse > 0.0f || (q_spec > 0.0f && !spec_delta); }
    // Non-delta part: value f(wo, wi) (without the cosine) and the combined sampling pdf (solid angle).
    glm::vec3 eval(const glm::vec3& wo, const glm::vec3& wi, float& pdf) const;
    // Samples wi; weight = f cos / pdf (or the delta lobe's weight). False if the sample is absorbed.
    bool sample(const glm::vec3& wo, Sampler& rng, glm::vec3& wi, glm::vec3& weight, bool& delta, bool& transmitted) const;
};

}  // namespace raysplats
