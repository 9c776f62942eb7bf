// The surface scattering model of Material (internal), following Cycles' Principled BSDF.
//
// V1, Cycles 3.x (intern/cycles/kernel/svm/closure.h, CLOSURE_BSDF_PRINCIPLED_ID): a diffuse base (Lambert or the
// principled diffuse of bsdf_principled_diffuse.h), one GGX specular layer for metal and dielectric specular (Walter
// et al. 2007, "Microfacet Models for Refraction through Rough Surfaces"; Fresnel of Cycles' interpolate_fresnel_color,
// separable Smith G), and a dielectric glass lobe with exact Fresnel.
//
// V2, Cycles 4.x (same function, rewritten for Blender 4.0), from the top layer down, each layer's weight taken from
// what the layers above leave:
//   metal      weight metallic: GGX with the F82-tint Fresnel of Kutz et al., "Novel aspects of the Adobe Standard
//              Material" (Cycles fresnel_f82 / fresnel_f82tint_B): F = F0 + (1 - F0)(1 - c)^5 - B c (1 - c)^6,
//              F0 = base colour, B chosen so that F(1/7) is Schlick's value times the Specular Tint.
//   glass      weight (1 - metallic) transmission: real Fresnel R remapped to F0 = F0(ior) * tint
//              (generalized Schlick with exponent < 0), transmission (1 - R) sqrt(base colour).
//   specular   weight w = (1 - metallic)(1 - transmission): GGX, real Fresnel of eta remapped to F0(eta) * tint, where
//              F0(eta) = F0(ior) * 2 * Specular IOR Level.
//   diffuse    Lambert base colour with weight w (1 - max_rgb A), A the specular layer's albedo estimate at the view
//              direction (Cycles closure_layering_weight with bsdf_microfacet_estimate_albedo: mix(F0, 1, s), s from
//              the table ggx_gen_schlick_ior_s of microfacet_tables.h).
//   Both GGX lobes use the height-correlated Smith G2 = 1 / (1 + L_i + L_o). With multiscatter, each GGX lobe is
//   scaled by 1 + F_ms (1 - E) / E (Cycles microfacet_ggx_preserve_energy; Kulla and Conty 2017), E = ggx_E at the
//   view direction, F_ms = F_ss E_avg / (1 - F_ss (1 - E_avg)), F_ss the lobe's average Fresnel. The glass gets no
//   energy compensation (its roughness is handled by a single perturbed normal, see sample()).
// The two GGX lobes share roughness and distribution, so they are evaluated as one lobe with the weighted sum of their
// Fresnel terms (spec_fresnel). Lobes are picked by one-sample selection; the non-delta lobes share one combined pdf
// so that light sampling (NEE) and BSDF sampling agree (and can be MIS-weighted).
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
    // Non-delta samples: the diffuse lobe's part of f(wo, wi), the rest being glossy (the light passes' lobe shares,
    // Cycles' bsdf_eval_pass_diffuse_weight).
    glm::vec3 f_diffuse{0.0f}, f{0.0f};
};

// The albedos of a surface's lobes as Cycles writes its Diffuse, Glossy and Transmission Color passes: the closure
// weights in Cycles 3.x (Principled v1), the closures' albedo estimates from Cycles 4.0 on (Principled v2,
// closure_albedo).
struct LobeColors {
    glm::vec3 diffuse{0.0f}, glossy{0.0f}, transmission{0.0f};
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
    // V2 only.
    bool v2 = false;
    glm::vec3 metal_f0{0.0f}, metal_b{0.0f}, metal_weight{0.0f};  // weight includes metallic and multiscatter scale
    glm::vec3 layer_f0{0.0f}, layer_weight{0.0f};                  // dielectric specular layer
    float layer_eta = 1.0f;
    glm::vec3 glass_f0{0.0f}, glass_transmission_tint{0.0f};
    glm::vec3 spec_albedo{0.0f};  // V2: the metal and specular layers' albedo estimate at the view direction

    // `wo` (unit, towards the viewer) matters for V2 only: its layering and energy compensation depend on the view.
    Bsdf(const Material& m, const glm::vec3& base_color, const glm::vec3& shading_normal, const glm::vec3& wo,
         bool entering, LobeFilter filter = {});

    bool absorbs() const { return q_diffuse + q_spec + q_glass <= 0.0f; }
    bool has_non_delta() const { return q_diffuse > 0.0f || (q_spec > 0.0f && !spec_delta); }
    // Non-delta part: value f(wo, wi) (without the cosine) and the combined sampling pdf (solid angle).
    // `f_diffuse`, if given, receives the diffuse lobe's part of the value.
    glm::vec3 eval(const glm::vec3& wo, const glm::vec3& wi, float& pdf, glm::vec3* f_diffuse = nullptr) const;
    // The lobes' albedos at view direction `wo` (LobeColors). The glass' reflectance and transmittance are taken at
    // the shading normal, as Cycles takes them for a smooth surface.
    LobeColors colors(const glm::vec3& wo) const;
    // Samples a direction. False if the sample is absorbed.
    bool sample(const glm::vec3& wo, Sampler& rng, BsdfSample& out) const;
    // Fresnel of the specular layer at cos(wi, h) (V2: of both GGX lobes, weighted).
    glm::vec3 spec_fresnel(float cos_h) const;
    // V2 glass: reflectance and transmittance at cos(wo, m) for relative IOR eta.
    void glass_fresnel(float cos_i, float eta, glm::vec3& reflectance, glm::vec3& transmittance, float& cos_t) const;

private:
    void setup_v2(const Material& m, const glm::vec3& wo, LobeFilter filter);
};

}  // namespace raysplats
