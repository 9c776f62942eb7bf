// The surface scattering model of Material (internal), following Cycles 3.x's Principled BSDF v1
// (intern/cycles/kernel/svm/closure.h, CLOSURE_BSDF_PRINCIPLED_ID): a diffuse base (Lambert or the principled
// diffuse of bsdf_principled_diffuse.h), one GGX specular layer for metal and dielectric specular (Walter et al.
// 2007, "Microfacet Models for Refraction through Rough Surfaces"; Fresnel of Cycles' interpolate_fresnel_color),
// and a dielectric glass lobe with exact Fresnel. Lobes are picked by one-sample selection; the non-delta lobes
// share one combined pdf so that light sampling (NEE) and BSDF sampling agree (and can be MIS-weighted).
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

// The principled diffuse factor of DiffuseModel::Principled (multiplies base / pi), for unit n, wo, wi.
float principled_diffuse_factor(float roughness, const glm::vec3& n, const glm::vec3& wo, const glm::vec3& wi);

// Which lobes a vertex keeps. Cycles' "caustics tricks" (svm/closure.h): with caustics_reflective (refractive)
// off, a path whose last bounce was diffuse (PATH_RAY_DIFFUSE) gets no glossy/specular reflection (refraction)
// closures, and a surface left without closures absorbs.
struct LobeFilter {
    bool reflective = true;  // metal / specular layer and the glass' reflection
    bool refractive = true;  // the glass' refraction
};

struct BsdfSample {
    glm::vec3 wi{0.0f};
    glm::vec3 weight{0.0f};  // f cos / pdf, or the delta lobe's weight
    float pdf = 0.0f;        // combined solid-angle pdf of the non-delta lobes (0 for a delta sample)
    bool delta = false;
    bool transmitted = false;
    bool diffuse = false;    // the diffuse lobe was sampled (Cycles LABEL_DIFFUSE)
};

struct Bsdf {
    glm::vec3 n;          // shading normal, on the side of wo
    glm::vec3 base;
    float roughness = 0.5f;
    float alpha = 0.25f;  // GGX roughness alpha = roughness^2
    float ior = 1.45f;
    bool entering = true;  // wo is on the outside (front) of the surface
    bool principled_diffuse = false;
    float w_diffuse = 1, w_spec = 0, w_glass_reflect = 0, w_glass_refract = 0;
    glm::vec3 cspec0{0.04f};   // F0 colour of the specular layer
    float spec_eta = 1.5f, spec_f0 = 0.04f;  // dielectric IOR from `specular`, and its normal-incidence Fresnel
    float q_diffuse = 1, q_spec = 0, q_glass = 0;  // lobe selection probabilities
    bool spec_delta = false;

    Bsdf(const Material& m, const glm::vec3& base_color, const glm::vec3& shading_normal, bool entering,
         LobeFilter filter = {});

    bool absorbs() const { return q_diffuse + q_spec + q_glass <= 0.0f; }
    bool has_non_delta() const { return q_diffuse > 0.0f || (q_spec > 0.0f && !spec_delta); }
    // Non-delta part: value f(wo, wi) (without the cosine) and the combined sampling pdf (solid angle).
    glm::vec3 eval(const glm::vec3& wo, const glm::vec3& wi, float& pdf) const;
    // Samples a direction. False if the sample is absorbed.
    bool sample(const glm::vec3& wo, Sampler& rng, BsdfSample& out) const;
    // Fresnel of the specular layer at cos(wi, h).
    glm::vec3 spec_fresnel(float cos_h) const;
};

}  // namespace raysplats
