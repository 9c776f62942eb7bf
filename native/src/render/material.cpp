#include "raysplats/render/material.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "bsdf.h"
#include "raysplats/errors.h"

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

glm::vec3 schlick(const glm::vec3& f0, float cos_theta) {
    const float m = std::clamp(1.0f - cos_theta, 0.0f, 1.0f);
    const float m5 = m * m * m * m * m;
    return f0 + (glm::vec3(1.0f) - f0) * m5;
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

glm::vec3 reflect_dir(const glm::vec3& wo, const glm::vec3& m) { return 2.0f * glm::dot(wo, m) * m - wo; }

void require(bool ok, const char* what, const std::string& problem) {
    if (!ok) throw InvalidArgument(std::string(what) + ": " + problem);
}

}  // namespace

void Material::validate(const char* what) const {
    for (float v : {base_color[0], base_color[1], base_color[2], metallic, roughness, specular, transmission, ior,
                    emission_color[0], emission_color[1], emission_color[2], emission_strength, alpha})
        require(std::isfinite(v), what, "has a NaN or Inf parameter");
    require(base_color[0] >= 0 && base_color[1] >= 0 && base_color[2] >= 0, what, "base colour must be >= 0");
    require(metallic >= 0 && metallic <= 1, what, "metallic must be in [0, 1]");
    require(roughness >= 0 && roughness <= 1, what, "roughness must be in [0, 1]");
    require(specular >= 0 && specular <= 1, what, "specular must be in [0, 1]");
    require(transmission >= 0 && transmission <= 1, what, "transmission must be in [0, 1]");
    require(alpha >= 0 && alpha <= 1, what, "alpha must be in [0, 1]");
    require(ior > 0, what, "IOR must be > 0");
    require(emission_strength >= 0 && emission_color[0] >= 0 && emission_color[1] >= 0 && emission_color[2] >= 0,
            what, "emission must be >= 0");
    if (base_color_texture.pixels) {
        require(base_color_texture.width > 0 && base_color_texture.height > 0, what, "texture size must be > 0");
        const int c = base_color_texture.channels;
        require(c == 1 || c == 3 || c == 4, what, "texture channels must be 1, 3 or 4");
    }
}

glm::vec3 material_base_color(const Material& m, const glm::vec2& uv) {
    const ImageTexture& tex = m.base_color_texture;
    if (!tex.pixels) return {m.base_color[0], m.base_color[1], m.base_color[2]};
    // Bilinear, repeat wrap, texel centres at (i + 0.5) / width.
    const float x = uv.x * tex.width - 0.5f, y = uv.y * tex.height - 0.5f;
    const float fx = std::floor(x), fy = std::floor(y);
    const float tx = x - fx, ty = y - fy;
    auto wrap = [](long i, int n) { long r = i % n; return int(r < 0 ? r + n : r); };
    auto texel = [&](long i, long j) {
        const float* p = tex.pixels + (std::size_t(wrap(j, tex.height)) * tex.width + wrap(i, tex.width)) * tex.channels;
        glm::vec3 c = tex.channels == 1 ? glm::vec3(p[0]) : glm::vec3(p[0], p[1], p[2]);
        if (tex.srgb) c = glm::vec3(srgb_to_linear(c.x), srgb_to_linear(c.y), srgb_to_linear(c.z));
        return c;
    };
    const long i = long(fx), j = long(fy);
    const glm::vec3 c = (1 - tx) * (1 - ty) * texel(i, j) + tx * (1 - ty) * texel(i + 1, j) +
                        (1 - tx) * ty * texel(i, j + 1) + tx * ty * texel(i + 1, j + 1);
    return c * glm::vec3(m.base_color[0], m.base_color[1], m.base_color[2]) / 1.0f;
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

Bsdf::Bsdf(const Material& m, const glm::vec3& base_color, const glm::vec3& shading_normal, bool entering_)
    : n(shading_normal), base(base_color), ior(m.ior), entering(entering_) {
    alpha = std::max(m.roughness * m.roughness, 1e-4f);
    spec_delta = m.roughness < kDeltaRoughness;
    w_metal = m.metallic;
    w_glass = (1.0f - m.metallic) * m.transmission;
    w_diffuse = (1.0f - m.metallic) * (1.0f - m.transmission);
    w_dielectric_spec = m.specular > 0.0f ? w_diffuse : 0.0f;
    f0_dielectric = 0.08f * m.specular;
    const float p_spec = w_metal + 0.25f * w_dielectric_spec;
    const float sum = w_diffuse + p_spec + w_glass;
    q_diffuse = w_diffuse / sum;
    q_spec = p_spec / sum;
    q_glass = w_glass / sum;
}

glm::vec3 Bsdf::eval(const glm::vec3& wo, const glm::vec3& wi, float& pdf) const {
    pdf = 0.0f;
    const float cos_i = glm::dot(n, wi), cos_o = glm::dot(n, wo);
    if (cos_i <= 0.0f || cos_o <= 0.0f) return glm::vec3(0.0f);
    glm::vec3 f = w_diffuse * base * kInvPi;
    pdf = q_diffuse * cos_i * kInvPi;
    if (q_spec > 0.0f && !spec_delta) {
        const glm::vec3 h = glm::normalize(wo + wi);
        const float cos_h = std::max(glm::dot(n, h), 0.0f), oh = std::max(glm::dot(wo, h), 1e-6f);
        const float d = ggx_d(cos_h, alpha);
        const float g = smith_g1(cos_o, alpha) * smith_g1(cos_i, alpha);
        const glm::vec3 fr = w_metal * schlick(base, oh) + w_dielectric_spec * schlick(glm::vec3(f0_dielectric), oh);
        f += fr * (d * g / (4.0f * cos_o * cos_i));
        pdf += q_spec * d * cos_h / (4.0f * oh);
    }
    return f;
}

bool Bsdf::sample(const glm::vec3& wo, Sampler& rng, glm::vec3& wi, glm::vec3& weight, bool& delta,
                  bool& transmitted) const {
    const float u = rng.next(), u1 = rng.next(), u2 = rng.next();
    transmitted = false;
    delta = false;
    if (u < q_glass) {
        // Dielectric interface; a rough one perturbs the normal with a GGX microfacet (single-scattering
        // approximation) and then refracts or reflects exactly.
        glm::vec3 m = spec_delta ? n : sample_ggx_normal(n, alpha, u1, u2);
        float cos_i = glm::dot(wo, m);
        if (cos_i <= 0.0f) m = n, cos_i = glm::dot(wo, n);
        const float eta = entering ? ior : 1.0f / ior;
        float cos_t;
        const float f = fresnel_dielectric(cos_i, eta, cos_t);
        delta = true;
        if (rng.next() < f) {
            wi = reflect_dir(wo, m);
            weight = glm::vec3(w_glass / q_glass);
        } else {
            wi = glm::normalize(-wo / eta + (cos_i / eta - cos_t) * m);
            weight = base * (w_glass / q_glass);
            transmitted = true;
        }
        return true;
    }
    if (u < q_glass + q_spec && spec_delta) {
        wi = reflect_dir(wo, n);
        const float c = std::max(glm::dot(wo, n), 0.0f);
        weight = (w_metal * schlick(base, c) + w_dielectric_spec * schlick(glm::vec3(f0_dielectric), c)) / q_spec;
        delta = true;
        return glm::dot(wi, n) > 0.0f;
    }
    if (u < q_glass + q_spec) {
        const glm::vec3 h = sample_ggx_normal(n, alpha, u1, u2);
        wi = reflect_dir(wo, h);
    } else {
        // Cosine-weighted hemisphere (Malley's method).
        const float r = std::sqrt(u1), phi = 2.0f * kPi * u2;
        glm::vec3 t, b;
        make_frame(n, t, b);
        wi = r * std::cos(phi) * t + r * std::sin(phi) * b + std::sqrt(std::max(0.0f, 1.0f - u1)) * n;
    }
    float pdf;
    const glm::vec3 f = eval(wo, wi, pdf);
    if (!(pdf > 0.0f)) return false;
    // Non-delta lobes use the one-sample combined pdf; pdf already includes q of each non-delta lobe.
    weight = f * glm::dot(n, wi) / pdf;
    return true;
}

}  // namespace raysplats
