#include "gaussian_shading.h"

#include <algorithm>
#include <cmath>

#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>

#include "light_sampling.h"

namespace raysplats {

void GaussianShadingPoint::add(float w, const glm::vec3& point, const glm::vec3& normal, float shadow_bias,
                               Sampler& rng) {
    weight += w;
    // Weighted reservoir sampling (Chao 1982): the k-th candidate replaces the kept one with probability
    // w_k / (w_1 + ... + w_k), so each is kept with probability w_i / W.
    if (rng.next() * weight < w) {
        p = point;
        n = normal;
        bias = shadow_bias;
    }
}

void GaussianShadingPoint::append_behind(const GaussianShadingPoint& behind, float t_front, Sampler& rng) {
    const float w = behind.weight * t_front;
    if (!(w > 0.0f)) return;
    albedo_sum += behind.albedo_sum * t_front;
    shadowed_sum += behind.shadowed_sum * t_front;
    weight += w;
    if (rng.next() * weight < w) {
        p = behind.p;
        n = behind.n;
        bias = behind.bias;
        time = behind.time;
    }
}

namespace {

// Linear degree-0 colour of a cloud's Gaussian i, as GaussianSet::store_linear_rgb computes it.
glm::vec3 dc_linear(const GaussianCloud& cloud, std::size_t i) {
    const float* dc = &cloud.sh[i * std::size_t(cloud.coeffs_per_channel()) * 3];
    glm::vec3 c;
    for (int ch = 0; ch < 3; ++ch) c[ch] = srgb_to_linear(std::max(0.0f, sh_dc_to_display_single(dc[ch])));
    return c;
}

}  // namespace

float grey_world_albedo_scale(const GaussianSet& set) {
    const GaussianCloud& cloud = *set.cloud;
    struct Sums {
        double weighted_luminance = 0.0, weight = 0.0;
    };
    const Sums sums = tbb::parallel_reduce(
        tbb::blocked_range<std::size_t>(0, cloud.size(), 8192), Sums{},
        [&](const tbb::blocked_range<std::size_t>& r, Sums s) {
            for (std::size_t i = r.begin(); i != r.end(); ++i) {
                const float a = std::clamp(cloud.opacities[i], 0.0f, 1.0f);
                s.weighted_luminance += double(a) * luminance(dc_linear(cloud, i));
                s.weight += a;
            }
            return s;
        },
        [](Sums a, const Sums& b) {
            a.weighted_luminance += b.weighted_luminance;
            a.weight += b.weight;
            return a;
        });
    const double mean = sums.weight > 0.0 ? sums.weighted_luminance / sums.weight : 0.0;
    // A black object stays black (its albedo is 0 whatever the scale).
    return mean > 1e-6 ? float(kGreyWorldAlbedo / mean) : 1.0f;
}

GaussianShader::GaussianShader(const Scene::Impl& scene, const RenderSettings& settings,
                               const ShadowVisibility& shadow)
    : s_(scene), shadow_(shadow) {
    const std::size_t n = scene.gaussians.size();
    shading_.resize(n);
    albedo_scale_.assign(n, 1.0f);
    for (std::size_t i = 0; i < n; ++i) {
        const GaussianSet& set = *scene.gaussians[i];
        shading_[i] = set.shading.value_or(settings.gaussian_shading);
        if (shading_[i] != GaussianShading::Baked) any_non_baked_ = true;
        if (shading_[i] == GaussianShading::Lit) albedo_scale_[i] = grey_world_albedo_scale(set);
    }
}

glm::vec3 GaussianShader::albedo(const GaussianSet& set, std::uint32_t prim) const {
    const glm::vec3 c = set.linear_rgb.empty()
                            ? dc_linear(*set.cloud, set.cloud_index[prim])
                            : glm::vec3(set.linear_rgb[3 * prim], set.linear_rgb[3 * prim + 1], set.linear_rgb[3 * prim + 2]);
    return glm::min(c * albedo_scale_[set.index], glm::vec3(1.0f));
}

float GaussianShader::shadow_bias(const GaussianSet& set, std::uint32_t prim) {
    // row0 = axis_0 / sigma_0 (object space), so axis_0 sigma_0 = row0 / |row0|^2; A maps it to the world.
    const glm::vec3& r = set.prims[prim].row0;
    const float len2 = glm::dot(r, r);
    return len2 > 0.0f ? kShadowBiasSigmas * glm::length(set.linear * (r / len2)) : 0.0f;
}

glm::vec3 GaussianShader::direct(const GaussianShadingPoint& sp, float bounce_pdf_scale, Sampler& rng,
                                 Counters& c) const {
    const bool lit = sp.lit();
    const bool shadowed = sp.shadowed_sum.x > 0.0f || sp.shadowed_sum.y > 0.0f || sp.shadowed_sum.z > 0.0f;
    const float eps = 1e-4f * std::max(1.0f, std::max(std::abs(sp.p.x), std::max(std::abs(sp.p.y), std::abs(sp.p.z))));
    glm::vec3 irradiance_over_pi(0.0f);
    float light_total = 0.0f, light_visible = 0.0f;
    for (const Light& l : s_.lights) {
        LightSample ls;
        if (!sample_light(l, sp.p, rng, ls)) continue;
        const float cos_n = glm::dot(sp.n, ls.wi);
        const bool lights_lit = lit && cos_n > 0.0f;
        if (!lights_lit && !shadowed) continue;
        // The shadow ray leaves the Gaussian's plane on the light's side and starts `bias` along its direction, so
        // that the Gaussian's own surface (its neighbours within about one standard deviation) does not shadow it.
        // Starting along the ray rather than off the plane keeps every shadow edge of farther occluders exact.
        const glm::vec3 side = cos_n >= 0.0f ? sp.n : -sp.n;
        const float remaining = ls.distance - sp.bias;
        const float vis = remaining > 0.0f
                              ? shadow_.shadow(sp.p + side * eps + ls.wi * sp.bias, ls.wi, remaining, sp.time, false, c)
                              : 1.0f;
        if (lights_lit && vis > 0.0f) {
            // Lambert: f = rho / pi; area lights share the estimate with the bounce ray (power heuristic).
            const float bounce_pdf = bounce_pdf_scale * cos_n * kInvPi;
            const float w = ls.pdf > 0.0f ? power_heuristic(ls.pdf, bounce_pdf) : 1.0f;
            irradiance_over_pi += ls.value * (cos_n * kInvPi * vis * w);
        }
        const float e = luminance(ls.value);
        if (shadowed && e > 0.0f) {
            light_total += e;
            light_visible += e * vis;
        }
    }
    glm::vec3 out = sp.albedo_sum * irradiance_over_pi;
    if (shadowed) out += sp.shadowed_sum * (light_total > 0.0f ? light_visible / light_total : 1.0f);
    return out;
}

Ray GaussianShader::bounce_ray(const GaussianShadingPoint& sp, Sampler& rng, float& pdf) const {
    // Cosine-weighted hemisphere (Malley's method): f cos / pdf = rho for a Lambertian surface.
    const float u1 = rng.next(), u2 = rng.next();
    const float r = std::sqrt(u1), phi = 2.0f * kPi * u2;
    const float cos_t = std::sqrt(std::max(0.0f, 1.0f - u1));
    glm::vec3 t, b;
    make_frame(sp.n, t, b);
    const glm::vec3 wi = glm::normalize(r * std::cos(phi) * t + r * std::sin(phi) * b + cos_t * sp.n);
    pdf = cos_t * kInvPi;
    const float eps = 1e-4f * std::max(1.0f, std::max(std::abs(sp.p.x), std::max(std::abs(sp.p.y), std::abs(sp.p.z))));
    // As shadow rays: the Gaussian's neighbours within `bias` along the ray are its own surface.
    Ray ray{sp.p + sp.n * eps, wi, sp.bias, kInf};
    ray.time = sp.time;
    return ray;
}

}  // namespace raysplats
