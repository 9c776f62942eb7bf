#include "bsdf.h"

#include <algorithm>
#include <cmath>

#include "microfacet_tables.h"

namespace raysplats {
namespace {

float ggx_d(float cos_h, float a) {
    const float a2 = a * a;
    const float c2 = cos_h * cos_h;
    const float d = c2 * (a2 - 1.0f) + 1.0f;
    return a2 / (kPi * d * d);
}

float smith_g1(float cos_v, float a) {
    const float c2 = std::max(cos_v * cos_v, 1e-12f);
    const float tan2 = (1.0f - c2) / c2;
    return 2.0f / (1.0f + std::sqrt(1.0f + a * a * tan2));
}

// GGX normal distribution sampled proportionally to D(h) cos(theta_h).
glm::vec3 sample_ggx_normal(const glm::vec3& n, float a, float u1, float u2) {
    const float phi = 2.0f * kPi * u1;
    const float cos2 = (1.0f - u2) / (1.0f + (a * a - 1.0f) * u2);
    const float cos_t = std::sqrt(std::max(cos2, 0.0f));
    const float sin_t = std::sqrt(std::max(1.0f - cos2, 0.0f));
    glm::vec3 t, b;
    make_frame(n, t, b);
    return glm::normalize(sin_t * std::cos(phi) * t + sin_t * std::sin(phi) * b + cos_t * n);
}

// Height-correlated Smith masking-shadowing (Heitz 2014, eq. 72 and 99), as Cycles 4.x evaluates GGX.
float smith_g2(float cos_o, float cos_i, float a) {
    auto lambda = [a](float c) {
        const float c2 = std::max(c * c, 1e-12f);
        return 0.5f * (std::sqrt(1.0f + a * a * std::max(1.0f / c2 - 1.0f, 0.0f)) - 1.0f);
    };
    return 1.0f / (1.0f + lambda(cos_o) + lambda(cos_i));
}

glm::vec3 reflect_dir(const glm::vec3& wo, const glm::vec3& m) { return 2.0f * glm::dot(wo, m) * m - wo; }

float f0_from_ior(float ior) { return (ior - 1.0f) * (ior - 1.0f) / ((ior + 1.0f) * (ior + 1.0f)); }

// Cycles bsdf_util.h ior_from_F0.
float ior_from_f0(float f0) {
    const float r = std::sqrt(std::clamp(f0, 0.0f, 0.99f));
    return (1.0f + r) / (1.0f - r);
}

// Generalized Schlick with exponent < 0 (Cycles microfacet_fresnel): the real Fresnel of eta remapped from its own
// F0 .. 1 to f0 .. 1.
glm::vec3 remapped_fresnel(float cos_i, float eta, const glm::vec3& f0, float& cos_t) {
    const float f0_real = f0_from_ior(eta);
    const float s = std::clamp((fresnel_dielectric(cos_i, eta, cos_t) - f0_real) / (1.0f - f0_real), 0.0f, 1.0f);
    return glm::mix(f0, glm::vec3(1.0f), s);
}

// Cycles bsdf_util.h fresnel_f82 and fresnel_f82tint_B (F82-tint; Kutz et al., Adobe Standard Material).
glm::vec3 fresnel_f82(float cos_i, const glm::vec3& f0, const glm::vec3& b) {
    const float s = std::clamp(1.0f - cos_i, 0.0f, 1.0f);
    const float s5 = s * s * s * s * s;
    return glm::clamp(glm::mix(f0, glm::vec3(1.0f), s5) - b * (cos_i * s5 * s), 0.0f, 1.0f);
}
glm::vec3 fresnel_f82tint_b(const glm::vec3& f0, const glm::vec3& tint) {
    const float f = 6.0f / 7.0f, f5 = f * f * f * f * f;
    return glm::mix(f0, glm::vec3(1.0f), f5) * (7.0f / (f5 * f)) * (glm::vec3(1.0f) - tint);
}

float max3(const glm::vec3& v) { return std::max(v.x, std::max(v.y, v.z)); }
float average(const glm::vec3& v) { return (v.x + v.y + v.z) / 3.0f; }

}  // namespace

glm::vec3 material_base_color(const Material& m, const glm::vec2& uv) {
    const ImageTexture& tex = m.base_color_texture;
    if (!tex.pixels) return {m.base_color[0], m.base_color[1], m.base_color[2]};
    // The texture replaces the base colour, as a link into Blender's Base Color socket replaces its value.
    // Bilinear with texel centres at (i + 0.5) / width, the lookup of Blender's Image Texture node with
    // interpolation "Linear" (Cycles kernel_tex_image_interp, INTERPOLATION_LINEAR); "Closest" is drawn bilinear
    // too. Wrapping is "Repeat" (EXTENSION_REPEAT, the node's default): u and u + 1 look up the same texel.
    const float x = uv.x * tex.width - 0.5f, y = uv.y * tex.height - 0.5f;
    const float fx = std::floor(x), fy = std::floor(y);
    const float tx = x - fx, ty = y - fy;
    auto wrap = [](long i, int n) { long r = i % n; return int(r < 0 ? r + n : r); };
    auto texel = [&](long i, long j) {
        const float* p = tex.pixels + (std::size_t(wrap(j, tex.height)) * tex.width + wrap(i, tex.width)) * tex.channels;
        return tex.channels == 1 ? glm::vec3(p[0]) : glm::vec3(p[0], p[1], p[2]);
    };
    const long i = long(fx), j = long(fy);
    glm::vec3 c = (1 - tx) * (1 - ty) * texel(i, j) + tx * (1 - ty) * texel(i + 1, j) +
                  (1 - tx) * ty * texel(i, j + 1) + tx * ty * texel(i + 1, j + 1);
    // sRGB is decoded after filtering, as Cycles does for 8-bit sRGB images (svm_image_texture with
    // NODE_IMAGE_COMPRESS_AS_SRGB: kernel_tex_image_interp, then color_srgb_to_linear_v4).
    if (tex.srgb) c = glm::vec3(srgb_to_linear(c.x), srgb_to_linear(c.y), srgb_to_linear(c.z));
    return c;
}

float fresnel_dielectric(float cos_i, float eta, float& cos_t) {
    const float sin2_t = (1.0f - cos_i * cos_i) / (eta * eta);
    if (sin2_t >= 1.0f) {
        cos_t = 0.0f;
        return 1.0f;
    }
    cos_t = std::sqrt(1.0f - sin2_t);
    const float rs = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    const float rp = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    return 0.5f * (rs * rs + rp * rp);
}

float principled_diffuse_factor(float roughness, const glm::vec3& n, const glm::vec3& wo, const glm::vec3& wi) {
    // Cycles 3.x bsdf_principled_diffuse_compute_brdf with PRINCIPLED_DIFFUSE_FULL.
    auto schlick_weight = [](float c) {
        const float m = std::clamp(1.0f - c, 0.0f, 1.0f);
        return m * m * m * m * m;
    };
    const float fv = schlick_weight(glm::dot(n, wo)), fl = schlick_weight(glm::dot(n, wi));
    const float rr = roughness * (glm::dot(wi, wo) + 1.0f);  // 2 roughness cos^2(theta_d)
    return (1.0f - 0.5f * fv) * (1.0f - 0.5f * fl) + rr * (fl + fv + fl * fv * (rr - 1.0f));
}

Bsdf::Bsdf(const Material& m, const glm::vec3& base_color, const glm::vec3& shading_normal, const glm::vec3& wo,
           bool entering_, LobeFilter filter)
    : n(shading_normal), base(base_color), roughness(m.roughness), ior(m.ior), entering(entering_) {
    alpha = std::max(m.roughness * m.roughness, 1e-4f);
    spec_delta = m.roughness < kDeltaRoughness;
    if (m.principled_version == PrincipledVersion::V2) {
        setup_v2(m, wo, filter);
        return;
    }
    principled_diffuse = m.diffuse_model == DiffuseModel::Principled;
    // Cycles 3.x principled weights: diffuse (1 - metallic)(1 - transmission), glass (1 - metallic) transmission,
    // specular layer 1 - glass (present when specular or metallic is non-zero).
    const float w_glass = (1.0f - m.metallic) * m.transmission;
    w_diffuse = (1.0f - m.metallic) * (1.0f - m.transmission);
    w_spec = (m.specular > 0.0f || m.metallic > 0.0f) && filter.reflective ? 1.0f - w_glass : 0.0f;
    w_glass_reflect = filter.reflective ? w_glass : 0.0f;
    w_glass_refract = filter.refractive ? w_glass : 0.0f;
    cspec0 = glm::mix(glm::vec3(0.08f * m.specular), base, m.metallic);
    // Cycles: ior = 2 / (1 - sqrt(0.08 specular)) - 1, F0 = fresnel_dielectric_cos(1, ior).
    spec_eta = 2.0f / (1.0f - std::sqrt(std::min(0.08f * m.specular, 0.99f))) - 1.0f;
    spec_f0 = (spec_eta - 1.0f) * (spec_eta - 1.0f) / ((spec_eta + 1.0f) * (spec_eta + 1.0f));
    // Lobe selection: the specular layer by its average normal-incidence reflectance (at least 1/4 of its
    // weight so that grazing Fresnel is sampled too), the glass by its weight.
    const float p_spec = w_spec * std::max(0.25f, (cspec0.x + cspec0.y + cspec0.z) / 3.0f);
    const float p_glass = w_glass_reflect > 0.0f || w_glass_refract > 0.0f ? w_glass : 0.0f;
    const float sum = w_diffuse + p_spec + p_glass;
    if (sum <= 0.0f) {
        q_diffuse = q_spec = q_glass = 0.0f;  // no closure left: the surface absorbs
        return;
    }
    q_diffuse = w_diffuse / sum;
    q_spec = p_spec / sum;
    q_glass = p_glass / sum;
}

void Bsdf::setup_v2(const Material& m, const glm::vec3& wo, LobeFilter filter) {
    v2 = true;
    principled_diffuse = m.diffuse_model == DiffuseModel::Principled;
    const float mu = std::clamp(glm::dot(n, wo), 1e-4f, 1.0f);
    const glm::vec3 tint = glm::max(glm::vec3(m.specular_tint[0], m.specular_tint[1], m.specular_tint[2]), 0.0f);
    const glm::vec3 clamped_base = glm::min(base, glm::vec3(1.0f));
    // Multiple-scattering compensation of a GGX lobe of average Fresnel fss (Cycles microfacet_ggx_preserve_energy):
    // energy_scale * darkening = 1 + F_ms (1 - E) / E.
    float e = 1.0f, e_avg = 1.0f;
    if (m.multiscatter) e = ggx_E(m.roughness, mu), e_avg = ggx_E_avg(m.roughness);
    auto compensation = [&](const glm::vec3& fss) {
        const glm::vec3 fms = fss * e_avg / (glm::vec3(1.0f) - fss * (1.0f - e_avg));
        return glm::vec3(1.0f) + fms * ((1.0f - e) / e);
    };
    float weight = 1.0f;
    float glossy_weight = 0.0f;  // of the lobes present, for the selection probability
    glm::vec3 glossy_albedo(0.0f);
    if (m.metallic > 0.0f) {
        if (filter.reflective) {
            metal_f0 = clamped_base;
            const glm::vec3 f82 = glm::min(tint, glm::vec3(1.0f));
            metal_b = f82 == glm::vec3(1.0f) ? glm::vec3(0.0f) : fresnel_f82tint_b(metal_f0, f82);
            // Cycles fresnel_f82_Fss: the average of the F82 Fresnel, mix(F0, 1, 1/21) - B / 126.
            metal_weight = m.metallic * compensation(glm::mix(metal_f0, glm::vec3(1.0f), 1.0f / 21.0f) - metal_b / 126.0f);
            glossy_weight += m.metallic;
            glossy_albedo += m.metallic * glm::mix(metal_f0, glm::vec3(1.0f), ggx_schlick_s(m.roughness, mu));
        }
        weight *= 1.0f - m.metallic;
    }
    const float w_glass = weight * m.transmission;
    if (w_glass > 0.0f && (filter.reflective || filter.refractive)) {
        w_glass_reflect = filter.reflective ? w_glass : 0.0f;
        w_glass_refract = filter.refractive ? w_glass : 0.0f;
        glass_f0 = glm::min(f0_from_ior(m.ior) * tint, glm::vec3(1.0f));
        glass_transmission_tint = glm::sqrt(clamped_base);
    }
    weight *= 1.0f - m.transmission;
    // The specular layer's IOR from "Specular IOR Level" (Cycles: f0 *= 2 level, eta = ior_from_F0(f0)).
    float eta = m.ior, f0 = f0_from_ior(m.ior);
    if (m.specular != 0.5f) {
        f0 *= 2.0f * m.specular;
        eta = ior_from_f0(f0);
        if (m.ior < 1.0f) eta = 1.0f / eta;
    }
    w_diffuse = weight;
    if (filter.reflective && eta != 1.0f && weight > 0.0f) {
        layer_eta = eta;
        layer_f0 = glm::min(f0 * tint, glm::vec3(1.0f));
        const float f0_eta = f0_from_ior(eta);
        const float s_avg = std::clamp((fresnel_dielectric_Fss(eta) - f0_eta) / (1.0f - f0_eta), 0.0f, 1.0f);
        const glm::vec3 comp = compensation(glm::mix(layer_f0, glm::vec3(1.0f), s_avg));
        layer_weight = weight * comp;
        // The layer's albedo at this view (bsdf_albedo: estimate times the multiscatter darkening comp * E).
        const glm::vec3 albedo = glm::mix(layer_f0, glm::vec3(1.0f), ggx_gen_schlick_ior_s(m.roughness, mu, eta)) *
                                 (m.multiscatter ? comp * e : glm::vec3(1.0f));
        w_diffuse = weight * std::clamp(1.0f - max3(albedo), 0.0f, 1.0f);
        glossy_weight += weight;
        glossy_albedo += weight * albedo;
    }
    spec_albedo = glossy_albedo;
    w_spec = glossy_weight > 0.0f ? 1.0f : 0.0f;
    const float p_spec = glossy_weight > 0.0f ? std::max(0.25f * glossy_weight, average(glossy_albedo)) : 0.0f;
    const float p_glass = w_glass_reflect > 0.0f || w_glass_refract > 0.0f ? w_glass : 0.0f;
    const float sum = w_diffuse + p_spec + p_glass;
    if (sum <= 0.0f) {
        q_diffuse = q_spec = q_glass = 0.0f;
        return;
    }
    q_diffuse = w_diffuse / sum;
    q_spec = p_spec / sum;
    q_glass = p_glass / sum;
}

void Bsdf::glass_fresnel(float cos_i, float eta, glm::vec3& reflectance, glm::vec3& transmittance, float& cos_t) const {
    reflectance = remapped_fresnel(cos_i, eta, glass_f0, cos_t);
    transmittance = (glm::vec3(1.0f) - reflectance) * glass_transmission_tint;
    if (w_glass_reflect <= 0.0f) reflectance = glm::vec3(0.0f);
    if (w_glass_refract <= 0.0f) transmittance = glm::vec3(0.0f);
}

glm::vec3 Bsdf::spec_fresnel(float cos_h) const {
    if (v2) {
        const float c = std::clamp(cos_h, 0.0f, 1.0f);
        glm::vec3 f(0.0f);
        if (max3(metal_weight) > 0.0f) f += metal_weight * fresnel_f82(c, metal_f0, metal_b);
        if (max3(layer_weight) > 0.0f) {
            float cos_t;
            f += layer_weight * remapped_fresnel(c, layer_eta, layer_f0, cos_t);
        }
        return f;
    }
    // Cycles interpolate_fresnel_color: blend cspec0 -> white by the normalised dielectric Fresnel.
    float cos_t;
    const float fh = (fresnel_dielectric(std::clamp(cos_h, 0.0f, 1.0f), spec_eta, cos_t) - spec_f0) / (1.0f - spec_f0);
    return cspec0 * (1.0f - fh) + glm::vec3(fh);
}

glm::vec3 Bsdf::eval(const glm::vec3& wo, const glm::vec3& wi, float& pdf, glm::vec3* f_diffuse) const {
    pdf = 0.0f;
    const float cos_i = glm::dot(n, wi), cos_o = glm::dot(n, wo);
    if (f_diffuse) *f_diffuse = glm::vec3(0.0f);
    if (cos_i <= 0.0f || cos_o <= 0.0f) return glm::vec3(0.0f);
    glm::vec3 f(0.0f);
    if (q_diffuse > 0.0f) {
        f = w_diffuse * base * kInvPi;
        if (principled_diffuse) f *= principled_diffuse_factor(roughness, n, wo, wi);
        pdf = q_diffuse * cos_i * kInvPi;
        if (f_diffuse) *f_diffuse = f;
    }
    if (q_spec > 0.0f && !spec_delta) {
        const glm::vec3 h = glm::normalize(wo + wi);
        const float cos_h = std::max(glm::dot(n, h), 0.0f), oh = std::max(glm::dot(wo, h), 1e-6f);
        const float d = ggx_d(cos_h, alpha);
        const float g = v2 ? smith_g2(cos_o, cos_i, alpha) : smith_g1(cos_o, alpha) * smith_g1(cos_i, alpha);
        f += w_spec * spec_fresnel(glm::dot(wi, h)) * (d * g / (4.0f * cos_o * cos_i));
        pdf += q_spec * d * cos_h / (4.0f * oh);
    }
    return f;
}

bool Bsdf::sample(const glm::vec3& wo, Sampler& rng, BsdfSample& out) const {
    const float u = rng.next(), u1 = rng.next(), u2 = rng.next();
    out = BsdfSample{};
    if (absorbs()) return false;
    if (u < q_glass) {
        // Dielectric interface; a rough one perturbs the normal with a GGX microfacet (single-scattering
        // approximation) and then refracts or reflects exactly. Reflection with probability F, so the weights
        // are those of Cycles' closures F and base (1 - F) divided by the probabilities.
        glm::vec3 m = spec_delta ? n : sample_ggx_normal(n, alpha, u1, u2);
        float cos_i = glm::dot(wo, m);
        if (cos_i <= 0.0f) m = n, cos_i = glm::dot(wo, n);
        const float eta = entering ? ior : 1.0f / ior;
        float cos_t;
        out.delta = true;
        if (v2) {
            // Reflect or refract in proportion to the average reflectance and transmittance (Cycles
            // bsdf_microfacet_sample's pdf_reflect).
            glm::vec3 r, t;
            glass_fresnel(cos_i, eta, r, t, cos_t);
            const float ar = average(r), at = average(t);
            if (!(ar + at > 0.0f)) return false;
            const float p = ar / (ar + at);
            if (rng.next() < p) {
                out.wi = reflect_dir(wo, m);
                out.weight = r * (w_glass_reflect / (p * q_glass));
            } else {
                out.wi = glm::normalize(-wo / eta + (cos_i / eta - cos_t) * m);
                out.weight = t * (w_glass_refract / ((1.0f - p) * q_glass));
                out.transmitted = true;
            }
            return out.weight.x > 0.0f || out.weight.y > 0.0f || out.weight.z > 0.0f;
        }
        const float f = fresnel_dielectric(cos_i, eta, cos_t);
        if (rng.next() < f) {
            out.wi = reflect_dir(wo, m);
            out.weight = glm::vec3(w_glass_reflect / q_glass);
        } else {
            out.wi = glm::normalize(-wo / eta + (cos_i / eta - cos_t) * m);
            out.weight = base * (w_glass_refract / q_glass);
            out.transmitted = true;
        }
        return out.weight.x > 0.0f || out.weight.y > 0.0f || out.weight.z > 0.0f;
    }
    if (u < q_glass + q_spec && spec_delta) {
        out.wi = reflect_dir(wo, n);
        out.weight = w_spec * spec_fresnel(std::max(glm::dot(wo, n), 0.0f)) / q_spec;
        out.delta = true;
        return glm::dot(out.wi, n) > 0.0f;
    }
    if (u < q_glass + q_spec) {
        const glm::vec3 h = sample_ggx_normal(n, alpha, u1, u2);
        out.wi = reflect_dir(wo, h);
    } else {
        // Cosine-weighted hemisphere (Malley's method).
        const float r = std::sqrt(u1), phi = 2.0f * kPi * u2;
        glm::vec3 t, b;
        make_frame(n, t, b);
        out.wi = r * std::cos(phi) * t + r * std::sin(phi) * b + std::sqrt(std::max(0.0f, 1.0f - u1)) * n;
        out.diffuse = true;
    }
    const glm::vec3 f = eval(wo, out.wi, out.pdf, &out.f_diffuse);
    out.f = f;
    if (!(out.pdf > 0.0f)) return false;
    // Non-delta lobes use the one-sample combined pdf; pdf already includes q of each non-delta lobe.
    out.weight = f * glm::dot(n, out.wi) / out.pdf;
    return true;
}

LobeColors Bsdf::colors(const glm::vec3& wo) const {
    LobeColors c;
    if (absorbs()) return c;
    c.diffuse = w_diffuse * base;
    if (w_glass_reflect > 0.0f || w_glass_refract > 0.0f) {
        const float cos_o = std::clamp(glm::dot(n, wo), 0.0f, 1.0f);
        const float eta = entering ? ior : 1.0f / ior;
        float cos_t;
        if (v2) {
            // One glass closure whose albedo is its reflectance and transmittance (Cycles 4.x closure_albedo).
            glm::vec3 r, t;
            glass_fresnel(cos_o, eta, r, t, cos_t);
            c.glossy += w_glass_reflect * r;
            c.transmission += w_glass_refract * t;
        } else {
            // Cycles 3.x: a reflection closure of weight F and a refraction closure of weight base (1 - F).
            const float f = fresnel_dielectric(cos_o, eta, cos_t);
            c.glossy += glm::vec3(w_glass_reflect * f);
            c.transmission += w_glass_refract * (1.0f - f) * base;
        }
    }
    // Cycles 3.x: the specular layer's closure weight (its Fresnel is applied in its evaluation); 4.x: its albedo.
    c.glossy += v2 ? spec_albedo : glm::vec3(w_spec);
    return c;
}

}  // namespace raysplats
