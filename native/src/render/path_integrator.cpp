#include "path_integrator.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include "bsdf.h"

namespace raysplats {

inline Surface PathIntegrator::surface(const Segment& seg, const Ray& ray) const {
    const MeshRecord& m = *s_.meshes[s_.top[seg.top_geom].index];
    const std::uint32_t* idx = m.desc.indices + 3 * std::size_t(seg.prim);
    const float* vd = m.vertex_data();
    auto vtx = [&](std::uint32_t i) { return glm::vec3(vd[3 * i], vd[3 * i + 1], vd[3 * i + 2]); };
    const glm::vec3 v0 = vtx(idx[0]), v1 = vtx(idx[1]), v2 = vtx(idx[2]);
    Surface sf;
    sf.p = ray.o + seg.t * ray.d;
    sf.ng = glm::normalize(m.normal_matrix * glm::cross(v1 - v0, v2 - v0));
    const float b0 = 1.0f - seg.u - seg.v, b1 = seg.u, b2 = seg.v;
    sf.ns = sf.ng;
    if (m.desc.normals) {
        const float* n = m.desc.normals;
        auto nrm = [&](std::uint32_t i) { return glm::vec3(n[3 * i], n[3 * i + 1], n[3 * i + 2]); };
        const glm::vec3 ni = m.normal_matrix * (b0 * nrm(idx[0]) + b1 * nrm(idx[1]) + b2 * nrm(idx[2]));
        const float len = glm::length(ni);
        if (len > 0.0f) sf.ns = ni / len;
        if (glm::dot(sf.ns, sf.ng) < 0.0f) sf.ns = -sf.ns;
    }
    if (m.desc.uvs) {
        const float* t = m.desc.uvs;
        auto uv = [&](std::uint32_t i) { return glm::vec2(t[2 * i], t[2 * i + 1]); };
        sf.uv = b0 * uv(idx[0]) + b1 * uv(idx[1]) + b2 * uv(idx[2]);
    }
    sf.material = m.desc.face_materials ? m.desc.face_materials[seg.prim] : m.desc.material;
    return sf;
}

// The nearest area light that `ray` sees before its tmax (Cycles lights_intersect); -1 if none.
inline int PathIntegrator::nearest_light_hit(const Ray& ray, LightHit& hit) const {
    int best = -1;
    float tmax = ray.tmax;
    for (std::size_t i = 0; i < s_.lights.size(); ++i) {
        LightHit h;
        if (intersect_light(s_.lights[i], ray.o, ray.d, tmax, h) && h.t > ray.tmin) {
            hit = h;
            tmax = h.t;
            best = int(i);
        }
    }
    return best;
}

// The segment of `ray`, adding the emission of an area light in front of its mesh hit (lights do not
// occlude: the ray goes on behind the light, as in Cycles). `mis_pdf` > 0: the ray was sampled from a
// non-delta BSDF with that pdf and the light's emission is weighted against next-event estimation.
inline Segment PathIntegrator::trace_with_lights(const Ray& ray, const Segment* first, float mis_pdf,
                                                 const glm::vec3& beta, glm::vec3& radiance, Sampler& rng,
                                                 Counters& c) const {
    LightHit lh{};  // (set by nearest_light_hit; initialised for GCC's maybe-uninitialized)
    if (s_.lights.empty() || nearest_light_hit(ray, lh) < 0) return first ? *first : tracer_.trace(ray, rng, c);
    if (first && (first->mesh || first->terminated) && first->t < lh.t) return *first;
    Ray near = ray;
    near.tmax = lh.t;
    Segment s1 = tracer_.trace(near, rng, c);
    if (s1.mesh || s1.terminated) return s1;
    const float w = mis_pdf > 0.0f ? power_heuristic(mis_pdf, lh.pdf) : 1.0f;
    radiance += beta * s1.transmittance * lh.radiance * w;
    Ray far = ray;
    far.tmin = lh.t;
    const Segment s2 = trace_with_lights(far, nullptr, mis_pdf, beta * s1.transmittance, radiance, rng, c);
    Segment seg = s2;
    seg.radiance = s1.radiance + s1.transmittance * s2.radiance;
    seg.shading = s1.shading;
    seg.shading.append_behind(s2.shading, s1.transmittance, rng);
    seg.transmittance = s1.transmittance * s2.transmittance;
    if (s1.depth < kInf) {
        seg.depth = s1.depth;
        seg.normal = s1.normal;
        seg.depth_at_mesh = s1.depth_at_mesh;
    }
    return seg;
}

// Display blend space (BlendSpace::Display, docs/design.md §4 and §6): a run of Gaussians along a ray (one
// segment) is composited in display space as trained, D = sum T_i a_i c_i with display colours c_i, and meets what
// lies behind it, the linear radiance L_behind (the mesh it ends on, shaded with its lights and bounces, or the
// world), in that space too:
//     L = linear(D + T * display(L_behind)).
// So an unedited splat scene looks as in a splat viewer (its background the world's colour), and a mesh seen through
// haze is tinted as a viewer would tint it. Everything else stays linear light: mesh shading, lights, BSDFs, the
// film. Reflections and refractions see the splats the same way (each run on a secondary ray is combined with its own
// L_behind, innermost first: a perfect mirror shows the viewer's image), and shadow rays take only transmittance,
// which is not a colour. An area light hit inside a run is added in linear light, weighted by the transmittance in
// front of it, like the run's front (not composited into D). The camera ray's first run is not combined per sample:
// the film combines the means of D, T and T L_behind over the pixel's samples (SampleRecord), so that stochastic
// compositing, whose sample is one display colour or what lies behind, converges to the sorted image, and noise in
// L_behind is averaged in linear light.
namespace {
struct DisplayRun {
    glm::vec3 outer_radiance;  // the path's radiance before the run (at the enclosing run's level)
    glm::vec3 outer_beta;      // the throughput at the run, relative to the enclosing run
    glm::vec3 display;         // D
    float transmittance;       // T
};
}  // namespace

// Bounces follow Cycles: NEE at the camera hit and after each of max_bounces bounces, and the ray leaving the
// last vertex still collects the emitters it sees (world, area lights, mesh emission) without further shading
// (Cycles' PATH_RAY_TERMINATE_AFTER_TRANSPARENT).
SampleRecord PathIntegrator::path(Ray ray, Sampler& rng, Counters& c, const Segment* first) const {
    glm::vec3 radiance(0.0f), beta(1.0f);
    bool camera_segment = true;
    float alpha = 0.0f;
    float depth = kInf;
    glm::vec3 normal(0.0f);
    std::uint32_t camera_gaussians = 0;  // composited or accepted along the camera segment
    bool normal_at_mesh = false;  // depth is the camera segment's mesh hit, whose normal the surface gives
    int bounce = 0, passes = 0;
    bool after_diffuse = false;  // Cycles PATH_RAY_DIFFUSE: the last bounce was diffuse
    bool last = false;           // the ray leaving the last vertex: emission only
    float mis_pdf = 0.0f;        // pdf of the BSDF sample that made `ray` (0: camera or delta)
    const Material default_material;
    // Display blend space: the runs of Gaussians whose composite waits for the radiance behind them, innermost last.
    // While one is open, `radiance` and `beta` are relative to it (beta_outer: the product of the enclosing betas).
    const bool display = st_.blend_space == BlendSpace::Display;
    thread_local std::vector<DisplayRun> runs;
    runs.clear();
    bool first_trace = true, camera_run = false;  // camera_run: runs[0] is the camera ray's first segment
    glm::vec3 beta_outer(1.0f);
    // After a bounce: the next ray is the last one (emission only) past max_bounces; false when Russian roulette
    // ends the path.
    auto next_vertex = [&](glm::vec3& weight) {
        if (bounce >= st_.max_bounces) {
            last = true;
        } else {
            ++bounce;
            if (bounce > 3) {
                // Russian roulette keeps long paths unbiased and cheap.
                const glm::vec3 b = weight * beta_outer;  // the whole path's throughput
                const float q = std::min(0.95f, std::max(b.x, std::max(b.y, b.z)));
                if (rng.next() >= q) return false;
                weight /= q;
            }
        }
        return true;
    };
    for (;;) {
        Segment seg = trace_with_lights(ray, first, mis_pdf, beta, radiance, rng, c);
        first = nullptr;
        // What the radiance behind the segment is weighted with here (a display run applies its own T later).
        float behind_weight = seg.transmittance;
        // A segment holding LIT or BAKED_SHADOWED Gaussians is combined in linear light: their shaded radiance is
        // linear and is added below at this level, and a bounce off them replaces what lies behind. Its baked
        // Gaussians' display composite D is then taken to linear on its own (L = linear(D) + T L_behind), an
        // approximation only where baked and shaded splats overlap along a ray.
        const bool display_run = display && seg.gaussians > 0 && seg.shading.empty();
        if (display && seg.gaussians > 0 && !display_run)
            for (int ch = 0; ch < 3; ++ch) seg.radiance[ch] = srgb_to_linear_tabulated(seg.radiance[ch]);
        if (display_run) {
            // Splat radiance is baked reflected light: seen from the last vertex it would be one bounce too many
            // (the ray still takes their transmittance).
            runs.push_back({radiance, beta, last ? glm::vec3(0.0f) : seg.radiance, seg.transmittance});
            camera_run = camera_run || first_trace;
            radiance = glm::vec3(0.0f);
            beta_outer *= beta;
            beta = glm::vec3(1.0f);
            behind_weight = 1.0f;
        } else if (!last) {
            radiance += beta * seg.radiance;
        }
        first_trace = false;
        if (camera_segment) {
            camera_gaussians += seg.gaussians;
            if (depth == kInf && seg.depth < kInf) {
                depth = seg.depth;
                normal = seg.normal;
                normal_at_mesh = seg.depth_at_mesh;
            }
        }
        // LIT and BAKED_SHADOWED Gaussians (gaussian_shading.h): next-event estimation at the segment's shading
        // point, and a diffuse bounce off it. Where a mesh lies behind semi-transparent Gaussians the path goes on
        // either way: it bounces with probability p = a / (a + T) (a: the largest channel of the composited albedo)
        // and the chosen branch's weight is divided by its probability.
        bool gaussian_bounce = false;
        Ray bounce_ray{};
        float bounce_pdf = 0.0f;
        glm::vec3 bounce_beta(0.0f);
        if (!last && !seg.shading.empty()) {
            const GaussianShadingPoint& sp = seg.shading;
            float p_bounce = 0.0f;
            if (sp.lit()) {
                const float a = std::max(sp.albedo_sum.x, std::max(sp.albedo_sum.y, sp.albedo_sum.z));
                p_bounce = seg.mesh && !seg.terminated ? a / (a + seg.transmittance) : 1.0f;
            }
            radiance += beta * tracer_.shader().direct(sp, p_bounce, rng, c);
            if (p_bounce > 0.0f) {
                if (p_bounce >= 1.0f || rng.next() < p_bounce) {
                    gaussian_bounce = true;
                    bounce_ray = tracer_.shader().bounce_ray(sp, rng, bounce_pdf);
                    bounce_pdf *= p_bounce;
                    bounce_beta = beta * sp.albedo_sum / p_bounce;
                } else {
                    beta /= 1.0f - p_bounce;
                }
            }
        }
        if (seg.terminated) {
            if (camera_segment) alpha = 1.0f;
            if (!gaussian_bounce) break;
        } else if (!seg.mesh) {
            if (camera_segment) {
                alpha = 1.0f - (1.0f - alpha) * seg.transmittance;
                if (!st_.transparent_background) radiance += beta * behind_weight * world_;
            } else {
                radiance += beta * behind_weight * world_;
            }
            if (!gaussian_bounce) break;
        } else if (gaussian_bounce && camera_segment) {
            alpha = 1.0f;  // the mesh behind covers the pixel
            if (normal_at_mesh) {
                const Surface sf = surface(seg, ray);
                normal = glm::dot(sf.ng, ray.d) < 0.0f ? sf.ng : -sf.ng;
                normal_at_mesh = false;
            }
        }
        if (gaussian_bounce) {
            camera_segment = false;
            beta = bounce_beta;
            after_diffuse = true;
            mis_pdf = bounce_pdf;
            if (!next_vertex(beta)) break;
            ray = bounce_ray;
            continue;
        }
        beta *= behind_weight;
        const Surface sf = surface(seg, ray);
        const Material& mat = s_.materials.empty() ? default_material : s_.materials[sf.material];
        const bool entering = glm::dot(sf.ng, ray.d) < 0.0f;
        const glm::vec3 ng = entering ? sf.ng : -sf.ng;  // facing the incoming ray
        if (normal_at_mesh) {
            normal = ng;
            normal_at_mesh = false;
        }
        const float eps =
            1e-4f * std::max(1.0f, std::max(std::abs(sf.p.x), std::max(std::abs(sf.p.y), std::abs(sf.p.z))));
        if (mat.alpha < 1.0f && rng.next() >= mat.alpha && ++passes < 256) {
            // Stochastic coverage: continue straight through.
            if (camera_segment) alpha = 1.0f - (1.0f - alpha) * seg.transmittance;
            ray = Ray{sf.p - ng * eps, ray.d, 0.0f, kInf};
            continue;
        }
        if (camera_segment) {
            alpha = 1.0f;
            if (depth == kInf) {
                depth = seg.t;
                normal = ng;
            }
            camera_segment = false;
        }
        radiance += beta * glm::vec3(mat.emission_color[0], mat.emission_color[1], mat.emission_color[2]) *
                    mat.emission_strength;
        if (last) break;
        glm::vec3 ns = entering ? sf.ns : -sf.ns;
        const glm::vec3 wo = -ray.d;
        if (glm::dot(ns, wo) <= 0.0f) ns = ng;
        LobeFilter filter;
        if (after_diffuse) {
            filter.reflective = st_.caustics_reflective;
            filter.refractive = st_.caustics_refractive;
        }
        const Bsdf bsdf(mat, material_base_color(mat, sf.uv), ns, wo, entering, filter);
        if (bsdf.absorbs()) break;
        const glm::vec3 p_out = sf.p + ng * eps;
        if (bsdf.has_non_delta()) {
            for (const Light& l : s_.lights) {
                LightSample ls;
                if (!sample_light(l, p_out, rng, ls)) continue;
                if (glm::dot(ls.wi, ng) <= 0.0f) continue;
                float pdf;
                const glm::vec3 f = bsdf.eval(wo, ls.wi, pdf);
                const float cos_i = glm::dot(ns, ls.wi);
                if (cos_i <= 0.0f || (f.x <= 0.0f && f.y <= 0.0f && f.z <= 0.0f)) continue;
                const float vis = shadow_.shadow(p_out, ls.wi, ls.distance, false, c);
                // Lights that rays can hit share the estimate with BSDF sampling (power heuristic).
                const float w = ls.pdf > 0.0f ? power_heuristic(ls.pdf, pdf) : 1.0f;
                if (vis > 0.0f) radiance += beta * f * cos_i * ls.value * (vis * w);
            }
        }
        BsdfSample bs;
        if (!bsdf.sample(wo, rng, bs)) break;
        beta *= bs.weight;
        if (!(beta.x > 0.0f || beta.y > 0.0f || beta.z > 0.0f)) break;
        after_diffuse = bs.diffuse;
        mis_pdf = bs.delta ? 0.0f : bs.pdf;
        if (!next_vertex(beta)) break;
        const bool below = glm::dot(bs.wi, ng) < 0.0f;
        ray = Ray{sf.p + (below ? -ng : ng) * eps, bs.wi, 0.0f, kInf};
    }
    // Close the runs, innermost first: L = linear(D + T display(L_behind)).
    const std::size_t kept = camera_run ? 1 : 0;
    while (runs.size() > kept) {
        const DisplayRun& r = runs.back();
        glm::vec3 l;
        for (int ch = 0; ch < 3; ++ch)
            l[ch] = srgb_to_linear_tabulated(r.display[ch] + r.transmittance * linear_to_srgb(radiance[ch]));
        radiance = r.outer_radiance + r.outer_beta * l;
        runs.pop_back();
    }
    SampleRecord record;
    if (display) {
        // The camera run goes to the film as its parts (see SampleRecord); a path without one is all behind
        // (D = 0, T = 1).
        glm::vec3 front(0.0f), d(0.0f), behind = radiance;
        float t = 1.0f;
        if (camera_run) {
            front = runs[0].outer_radiance;
            d = runs[0].display;
            t = runs[0].transmittance;
            behind = t * radiance;
        }
        radiance = front;
        record.display_radiance = {d.x, d.y, d.z};
        record.display_transmittance = t;
        record.behind_radiance = {behind.x, behind.y, behind.z};
        record.display_blend = true;
    }
    record.radiance = {radiance.x, radiance.y, radiance.z};
    record.alpha = alpha;
    record.depth = depth;
    record.normal = {normal.x, normal.y, normal.z};
    record.gaussian_count = float(camera_gaussians);
    return record;
}

}  // namespace raysplats
