// The integrator (DESIGN §6). Per ray: the closest opaque mesh hit bounds the segment; the Gaussians on it are
// gathered k at a time in exact (t, id) order by the user-geometry callback (gaussian_geometry.cpp) and
// composited front to back, C += T a_i c_i, T *= 1 - a_i; the ray is re-traced from the k-th hit until the
// segment is done or T < threshold. The mesh hit is then shaded, weighted by T, with next-event estimation
// whose shadow rays carry Gaussian transmittance x mesh occlusion.
#include "raysplats/render/renderer.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <limits>
#include <mutex>
#include <string>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "bsdf.h"
#include "light_sampling.h"
#include "raysplats/errors.h"
#include "render_math.h"
#include "scene_impl.h"

namespace raysplats {

void RenderSettings::validate() const {
    auto require = [](bool ok, const std::string& problem) {
        if (!ok) throw InvalidArgument("render settings: " + problem);
    };
    require(width > 0 && height > 0, "image size must be at least 1 x 1 (got " + std::to_string(width) + " x " +
                                         std::to_string(height) + ")");
    require(width <= 65536 && height <= 65536 && std::int64_t(width) * height <= (std::int64_t(1) << 28),
            "image size " + std::to_string(width) + " x " + std::to_string(height) + " is too large (max 2^28 pixels)");
    require(samples >= 1 && samples <= (1 << 20), "samples per pixel must be in 1 .. 1048576 (got " + std::to_string(samples) + ")");
    require(max_bounces >= 0 && max_bounces <= 1024, "max bounces must be in 0 .. 1024 (got " + std::to_string(max_bounces) + ")");
    require(std::isfinite(transmittance_threshold) && transmittance_threshold >= 0.0f && transmittance_threshold < 1.0f,
            "transmittance threshold must be in [0, 1)");
    require(gather_buffer_size >= 1 && gather_buffer_size <= 128,
            "gather buffer size must be in 1 .. 128 (got " + std::to_string(gather_buffer_size) + ")");
    require(tile_size >= 1 && tile_size <= 4096, "tile size must be in 1 .. 4096 (got " + std::to_string(tile_size) + ")");
}

namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();
// RenderSettings::speculative_ends: a camera ray first traverses up to this factor times the end of its
// neighbours' (previous sample's) segments. bench_render, showroom_1.5M sorted, CPU per ray: 1.0 sent 23 % of the
// rays on (1.93 us), 1.01 4 % (1.87-1.89 us), 1.02 3 % (1.90 us); 1.05 and more tested more Gaussians per ray.
constexpr float kSpeculativeMargin = 1.01f;

struct Ray {
    glm::vec3 o, d;
    float tmin, tmax;
};

struct Counters {
    std::uint64_t traced = 0, gaussian_hits = 0, candidates = 0, group_candidates = 0;
};

struct Segment {
    glm::vec3 radiance{0.0f};  // premultiplied Gaussian radiance
    float transmittance = 1.0f;
    bool terminated = false;   // T fell below the threshold (or a stochastic Gaussian was accepted)
    bool mesh = false;
    unsigned top_geom = RTC_INVALID_GEOMETRY_ID;
    unsigned prim = 0;
    float t = kInf, u = 0.0f, v = 0.0f;
    float depth = kInf;        // first point where opacity reaches 0.5
    glm::vec3 normal{0.0f};
    float end = kInf;          // where the segment ended: its terminating Gaussian or mesh hit (+inf: escaped)
};

struct Surface {
    glm::vec3 p, ng, ns;  // ng, ns: outward (front-face) normals, world
    glm::vec2 uv{0.0f};
    std::uint32_t material = 0;
};

class Integrator {
public:
    Integrator(const Scene::Impl& scene, const RenderSettings& settings)
        : s_(scene), st_(settings), world_(glm::vec3(scene.world.color[0], scene.world.color[1], scene.world.color[2]) *
                                           scene.world.strength) {}

    void init_rayhit(RTCRayHit& rh, const Ray& ray, float tnear) const {
        rh.ray.org_x = ray.o.x;
        rh.ray.org_y = ray.o.y;
        rh.ray.org_z = ray.o.z;
        rh.ray.dir_x = ray.d.x;
        rh.ray.dir_y = ray.d.y;
        rh.ray.dir_z = ray.d.z;
        rh.ray.tnear = tnear;
        rh.ray.tfar = ray.tmax;
        rh.ray.time = 0.0f;
        rh.ray.mask = 0xffffffffu;
        rh.ray.id = 0;
        rh.ray.flags = 0;
        rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
        rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
    }

    void record_mesh(Segment& seg, float t, unsigned geom, unsigned inst, unsigned prim, float u, float v) const {
        seg.mesh = true;
        seg.top_geom = inst != RTC_INVALID_GEOMETRY_ID ? inst : geom;
        seg.prim = prim;
        seg.t = t;
        seg.end = t;
        seg.u = u;
        seg.v = v;
    }

    // The Gaussian set of a hit on top-level instance `geom` (a chunk); turns the chunk-local primID into the
    // set's primitive index.
    const GaussianSet& gaussian_of(unsigned geom, std::uint32_t& prim) const {
        const TopGeometry& tg = s_.top[geom];
        prim += tg.offset;
        return *s_.gaussians[tg.index];
    }

    // Composites one Gaussian onto the segment (front to back).
    void composite(Segment& seg, const Ray& ray, std::uint32_t geom, std::uint32_t prim, float t, float alpha,
                   Sampler& rng, Counters& c) const {
        const GaussianSet& set = gaussian_of(geom, prim);
        glm::vec3 color = set.color(prim, ray.o);
        if (st_.meshes_shadow_gaussians) color *= gaussian_light_visibility(set.world_center(prim), rng, c);
        const float t_before = seg.transmittance;
        seg.radiance += t_before * alpha * color;
        seg.transmittance = t_before * (1.0f - alpha);
        if (t_before > 0.5f && seg.transmittance <= 0.5f) {
            seg.depth = t;
            glm::vec3 n = set.flat ? set.world_normal(prim) : -ray.d;
            seg.normal = glm::dot(n, ray.d) > 0.0f ? -n : n;
        }
        ++c.gaussian_hits;
    }

    void init_lane(LaneState& L) const {
        L.capacity = st_.gather_buffer_size;
        L.transmittance_threshold = st_.transmittance_threshold;
    }

    // Moves one traversal's statistics from the lane to the counters.
    static void count_traversal(LaneState& L, Counters& c) {
        ++c.traced;
        c.candidates += L.candidates;
        c.group_candidates += L.group_candidates;
        L.candidates = 0;
        L.group_candidates = 0;
    }

    // Consumes one sorted gathering pass of a ray that ended at `end` (the ray's tmax or a speculative end):
    // composites the buffer; true when the segment is complete, false when the ray must be re-traced from its last
    // hit (the buffer overflowed) or from `end` (the speculative end came too early).
    bool consume_gather(Segment& seg, LaneState& L, const Ray& ray, float end, float tfar, unsigned geom,
                        unsigned inst, unsigned prim, float u, float v, Sampler& rng, Counters& c) const {
        count_traversal(L, c);
        for (int i = 0; i < L.count; ++i) {
            const GatherHit& h = L.hits[i];
            if (h.t > tfar) break;  // behind the mesh hit found later in the traversal
            composite(seg, ray, h.geom, h.prim, h.t, h.alpha, rng, c);
            if (seg.transmittance < st_.transmittance_threshold) {
                seg.terminated = true;
                seg.end = h.t;
                return true;
            }
        }
        if (geom != RTC_INVALID_GEOMETRY_ID) {
            record_mesh(seg, tfar, geom, inst, prim, u, v);
            if (seg.transmittance > 0.5f) seg.depth = seg.t;
            return true;
        }
        // Every Gaussian up to `end` was gathered unless the buffer overflowed or was cut (and compositing did not
        // terminate within it: the cut came early by a rounding of LaneState::prefix).
        if (L.count == L.capacity || L.saturated) {
            const GatherHit& last = L.hits[L.count - 1];
            L.after_t = last.t;
            L.after_key = gather_key(last.geom, last.prim);
            L.has_after = true;
            return false;
        }
        if (!(end < ray.tmax)) return true;
        L.after_t = end;  // the speculative end came too early: go on behind everything this pass could see
        L.after_key = ~std::uint64_t(0);
        L.has_after = true;
        return false;
    }

    // A new gathering pass of a ray's segment: an empty buffer, compositing on from the segment's transmittance.
    static void begin_gather_pass(LaneState& L, const Segment& seg) {
        L.count = 0;
        L.saturated = false;
        L.base_transmittance = seg.transmittance;
    }

    // Sorted gathering of a ray with single-ray queries, from the state left by earlier passes.
    void trace_sorted_from(Segment& seg, LaneState& L, const Ray& ray, Sampler& rng, Counters& c) const {
        TraceContext ctx(&L, TraceMode::Gather);
        for (;;) {
            RTCRayHit rh;
            init_rayhit(rh, ray, L.has_after ? L.after_t : ray.tmin);
            begin_gather_pass(L, seg);
            rtcIntersect1(s_.scene, &ctx, &rh);
            if (consume_gather(seg, L, ray, ray.tmax, rh.ray.tfar, rh.hit.geomID, rh.hit.instID[0], rh.hit.primID, rh.hit.u,
                               rh.hit.v, rng, c))
                return;
        }
    }

    Segment trace_sorted(const Ray& ray, Sampler& rng, Counters& c) const {
        Segment seg;
        LaneState L;
        init_lane(L);
        trace_sorted_from(seg, L, ray, rng, c);
        return seg;
    }

    void consume_stochastic(Segment& seg, LaneState& L, const Ray& ray, float tfar, unsigned geom, unsigned inst,
                            unsigned prim, float u, float v, Sampler& rng, Counters& c) const {
        count_traversal(L, c);
        if (geom == RTC_INVALID_GEOMETRY_ID) return;
        // Every top-level geometry is an instance (a mesh or a chunk of Gaussians).
        if (s_.top[inst].kind == TopGeometry::Gaussians) {
            // Accepted with probability alpha: the estimator of sum T_i a_i c_i is c of the nearest accepted.
            const GaussianSet& set = gaussian_of(inst, prim);
            glm::vec3 color = set.color(prim, ray.o);
            if (st_.meshes_shadow_gaussians) color *= gaussian_light_visibility(set.world_center(prim), rng, c);
            seg.radiance = color;
            seg.transmittance = 0.0f;
            seg.terminated = true;
            seg.depth = tfar;
            const glm::vec3 n = set.flat ? set.world_normal(prim) : -ray.d;
            seg.normal = glm::dot(n, ray.d) > 0.0f ? -n : n;
            ++c.gaussian_hits;
            return;
        }
        record_mesh(seg, tfar, geom, inst, prim, u, v);
        seg.depth = seg.t;
    }

    Segment trace_stochastic(const Ray& ray, Sampler& rng, Counters& c) const {
        Segment seg;
        LaneState L;
        L.seed = rng.next_u32();
        TraceContext ctx(&L, TraceMode::Stochastic);
        RTCRayHit rh;
        init_rayhit(rh, ray, ray.tmin);
        rtcIntersect1(s_.scene, &ctx, &rh);
        consume_stochastic(seg, L, ray, rh.ray.tfar, rh.hit.geomID, rh.hit.instID[0], rh.hit.primID, rh.hit.u, rh.hit.v,
                           rng, c);
        return seg;
    }

    // First segments of up to 16 coherent camera rays with packet queries (rtcIntersect16): a Gaussian's data
    // is fetched once for every ray of the packet that reaches it. Sorted rays whose buffer overflows, or whose
    // speculative end came too early, go on together in the next packet query, from where each stopped.
    // Random numbers are drawn in the same order as on the single-ray path, so the image does not change.
    // `ends` (sorted mode): speculative segment ends (RenderSettings::speculative_ends), +inf for none. The first
    // query traverses only up to them; the segments are the same as without them (the same hits composited in the
    // same order).
    void trace_packet(const Ray* rays, const bool* active, const float* ends, Sampler* rngs, Segment* segs,
                      Counters& c) const {
        LaneState lanes[16];
        RTCRayHit16 rh;
        alignas(64) int valid[16];
        float end[16];  // where the first query stops
        const bool sorted = st_.compositing == Compositing::Sorted;
        for (int l = 0; l < 16; ++l) {
            valid[l] = active[l] ? -1 : 0;
            segs[l] = Segment{};
            const Ray& r = rays[l];
            init_lane(lanes[l]);
            if (active[l] && !sorted) lanes[l].seed = rngs[l].next_u32();
            rh.ray.org_x[l] = r.o.x;
            rh.ray.org_y[l] = r.o.y;
            rh.ray.org_z[l] = r.o.z;
            rh.ray.dir_x[l] = r.d.x;
            rh.ray.dir_y[l] = r.d.y;
            rh.ray.dir_z[l] = r.d.z;
            rh.ray.tnear[l] = r.tmin;
            end[l] = std::min(r.tmax, ends[l]);
            rh.ray.tfar[l] = end[l];
            rh.ray.time[l] = 0.0f;
            rh.ray.mask[l] = 0xffffffffu;
            rh.ray.id[l] = unsigned(l);
            rh.ray.flags[l] = 0;
            rh.hit.geomID[l] = RTC_INVALID_GEOMETRY_ID;
            rh.hit.instID[0][l] = RTC_INVALID_GEOMETRY_ID;
        }
        TraceContext ctx(lanes, sorted ? TraceMode::Gather : TraceMode::Stochastic);
        ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
        rtcIntersect16(valid, s_.scene, &ctx, &rh);
        if (!sorted) {
            for (int l = 0; l < 16; ++l)
                if (active[l])
                    consume_stochastic(segs[l], lanes[l], rays[l], rh.ray.tfar[l], rh.hit.geomID[l],
                                       rh.hit.instID[0][l], rh.hit.primID[l], rh.hit.u[l], rh.hit.v[l], rngs[l], c);
            return;
        }
        std::uint32_t pending = 0;  // rays that go on
        for (int l = 0; l < 16; ++l)
            if (active[l] && !consume_gather(segs[l], lanes[l], rays[l], end[l], rh.ray.tfar[l], rh.hit.geomID[l],
                                             rh.hit.instID[0][l], rh.hit.primID[l], rh.hit.u[l], rh.hit.v[l], rngs[l],
                                             c))
                pending |= 1u << l;
        while (pending) {
            for (int l = 0; l < 16; ++l) {
                valid[l] = (pending >> l) & 1u ? -1 : 0;
                if (!valid[l]) continue;
                begin_gather_pass(lanes[l], segs[l]);
                rh.ray.tnear[l] = lanes[l].after_t;
                rh.ray.tfar[l] = rays[l].tmax;
                rh.hit.geomID[l] = RTC_INVALID_GEOMETRY_ID;
                rh.hit.instID[0][l] = RTC_INVALID_GEOMETRY_ID;
            }
            rtcIntersect16(valid, s_.scene, &ctx, &rh);
            std::uint32_t next = 0;
            for (int l = 0; l < 16; ++l)
                if (((pending >> l) & 1u) &&
                    !consume_gather(segs[l], lanes[l], rays[l], rays[l].tmax, rh.ray.tfar[l], rh.hit.geomID[l],
                                    rh.hit.instID[0][l], rh.hit.primID[l], rh.hit.u[l], rh.hit.v[l], rngs[l], c))
                    next |= 1u << l;
            pending = next;
        }
    }

    Segment trace(const Ray& ray, Sampler& rng, Counters& c) const {
        return st_.compositing == Compositing::Sorted ? trace_sorted(ray, rng, c) : trace_stochastic(ray, rng, c);
    }

    // Visibility of a light sample: Gaussian transmittance x mesh occlusion (meshes_only: meshes alone).
    float shadow(const glm::vec3& o, const glm::vec3& d, float dist, bool meshes_only, Counters& c) const {
        LaneState L;
        L.transmittance_threshold = st_.transmittance_threshold;
        TraceContext ctx(&L, meshes_only ? TraceMode::MeshesOnly : TraceMode::Transmittance);
        RTCRay ray;
        ray.org_x = o.x;
        ray.org_y = o.y;
        ray.org_z = o.z;
        ray.dir_x = d.x;
        ray.dir_y = d.y;
        ray.dir_z = d.z;
        ray.tnear = 0.0f;
        ray.tfar = std::isfinite(dist) ? dist * (1.0f - 1e-4f) : kInf;
        ray.time = 0.0f;
        ray.mask = 0xffffffffu;
        ray.id = 0;
        ray.flags = 0;
        rtcOccluded1(s_.scene, &ctx, &ray);
        ++c.traced;
        if (ray.tfar == -kInf) return 0.0f;
        return L.transmittance;
    }

    // Fraction of the lights' unshadowed irradiance that reaches a Gaussian centre past the meshes.
    float gaussian_light_visibility(const glm::vec3& p, Sampler& rng, Counters& c) const {
        if (s_.lights.empty()) return 1.0f;
        float total = 0.0f, visible = 0.0f;
        for (const Light& l : s_.lights) {
            LightSample ls;
            if (!sample_light(l, p, rng, ls)) continue;
            const float e = luminance(ls.value);
            if (!(e > 0.0f)) continue;
            total += e;
            visible += e * shadow(p, ls.wi, ls.distance, true, c);
        }
        return total > 0.0f ? visible / total : 1.0f;
    }

    Surface surface(const Segment& seg, const Ray& ray) const {
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
    int nearest_light_hit(const Ray& ray, LightHit& hit) const {
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
    Segment trace_with_lights(const Ray& ray, const Segment* first, float mis_pdf, const glm::vec3& beta,
                              glm::vec3& radiance, Sampler& rng, Counters& c) const {
        LightHit lh{};  // (set by nearest_light_hit; initialised for GCC's maybe-uninitialized)
        if (s_.lights.empty() || nearest_light_hit(ray, lh) < 0) return first ? *first : trace(ray, rng, c);
        if (first && (first->mesh || first->terminated) && first->t < lh.t) return *first;
        Ray near = ray;
        near.tmax = lh.t;
        Segment s1 = trace(near, rng, c);
        if (s1.mesh || s1.terminated) return s1;
        const float w = mis_pdf > 0.0f ? power_heuristic(mis_pdf, lh.pdf) : 1.0f;
        radiance += beta * s1.transmittance * lh.radiance * w;
        Ray far = ray;
        far.tmin = lh.t;
        const Segment s2 = trace_with_lights(far, nullptr, mis_pdf, beta * s1.transmittance, radiance, rng, c);
        Segment seg = s2;
        seg.radiance = s1.radiance + s1.transmittance * s2.radiance;
        seg.transmittance = s1.transmittance * s2.transmittance;
        if (s1.depth < kInf) {
            seg.depth = s1.depth;
            seg.normal = s1.normal;
        }
        return seg;
    }

    // One path from a camera ray. Returns the radiance; writes coverage, depth and normal of the primary segment.
    // Bounces follow Cycles: NEE at the camera hit and after each of max_bounces bounces, and the ray leaving the
    // last vertex still collects the emitters it sees (world, area lights, mesh emission) without further shading
    // (Cycles' PATH_RAY_TERMINATE_AFTER_TRANSPARENT).
    glm::vec3 path(Ray ray, Sampler& rng, Counters& c, float& alpha, float& depth, glm::vec3& normal,
                   const Segment* first = nullptr) const {
        glm::vec3 radiance(0.0f), beta(1.0f);
        bool camera_segment = true;
        alpha = 0.0f;
        depth = kInf;
        normal = glm::vec3(0.0f);
        int bounce = 0, passes = 0;
        bool after_diffuse = false;  // Cycles PATH_RAY_DIFFUSE: the last bounce was diffuse
        bool last = false;           // the ray leaving the last vertex: emission only
        float mis_pdf = 0.0f;        // pdf of the BSDF sample that made `ray` (0: camera or delta)
        const Material default_material;
        for (;;) {
            Segment seg = trace_with_lights(ray, first, mis_pdf, beta, radiance, rng, c);
            first = nullptr;
            // Splat radiance is baked reflected light: seen from the last vertex it would be one bounce too many
            // (the ray still takes their transmittance).
            if (!last) radiance += beta * seg.radiance;
            if (camera_segment) {
                if (depth == kInf && seg.depth < kInf) {
                    depth = seg.depth;
                    normal = seg.normal;
                }
            }
            if (seg.terminated) {
                if (camera_segment) alpha = 1.0f;
                break;
            }
            if (!seg.mesh) {
                if (camera_segment) {
                    alpha = 1.0f - (1.0f - alpha) * seg.transmittance;
                    if (st_.transparent_background) break;
                }
                radiance += beta * seg.transmittance * world_;
                break;
            }
            beta *= seg.transmittance;
            const Surface sf = surface(seg, ray);
            const Material& mat = s_.materials.empty() ? default_material : s_.materials[sf.material];
            const bool entering = glm::dot(sf.ng, ray.d) < 0.0f;
            const glm::vec3 ng = entering ? sf.ng : -sf.ng;  // facing the incoming ray
            const float eps = 1e-4f * std::max(1.0f, std::max(std::abs(sf.p.x), std::max(std::abs(sf.p.y), std::abs(sf.p.z))));
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
                    const float vis = shadow(p_out, ls.wi, ls.distance, false, c);
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
            if (bounce >= st_.max_bounces) {
                last = true;
            } else {
                ++bounce;
                if (bounce > 3) {
                    // Russian roulette keeps long paths unbiased and cheap.
                    const float q = std::min(0.95f, std::max(beta.x, std::max(beta.y, beta.z)));
                    if (rng.next() >= q) break;
                    beta /= q;
                }
            }
            const bool below = glm::dot(bs.wi, ng) < 0.0f;
            ray = Ray{sf.p + (below ? -ng : ng) * eps, bs.wi, 0.0f, kInf};
        }
        return radiance;
    }

private:
    const Scene::Impl& s_;
    const RenderSettings& st_;
    glm::vec3 world_;
};

// The end of the camera segment a tile already knows near pixel (x, y) (tile coordinates) of the 4 x 4 packet at
// (bx, by): the pixel's own in the previous sample; in the first, the larger of its neighbours' in the packets above
// and to the left; +inf when there is none (the tile's first packet, or a neighbour whose segment escaped).
float known_segment_end(const std::vector<float>& segment_end, int tile_width, int x, int y, int bx, int by,
                        int sample) {
    if (sample > 0) return segment_end[std::size_t(y) * tile_width + x];
    if (by == 0 && bx == 0) return kInf;
    float known = 0.0f;
    if (by > 0) known = std::max(known, segment_end[std::size_t(by - 1) * tile_width + x]);
    if (bx > 0) known = std::max(known, segment_end[std::size_t(y) * tile_width + (bx - 1)]);
    return known;
}

}  // namespace

Film render(Scene& scene, const Camera& camera, const RenderSettings& settings, const ProgressCallback& progress,
            const std::atomic<bool>* cancel) {
    settings.validate();
    camera.validate();
    const auto start = std::chrono::steady_clock::now();
    scene.build(settings.gaussian_mode);
    const Scene::Impl& impl = scene.impl();

    Film film;
    film.allocate(settings.width, settings.height);  // each tile clears its pixels first (parallel first touch)
    const int w = settings.width, h = settings.height, ts = settings.tile_size;
    const int tiles_x = (w + ts - 1) / ts, tiles_y = (h + ts - 1) / ts;
    const int tile_count = tiles_x * tiles_y;
    Integrator integrator(impl, settings);
    const CameraRayGenerator camera_rays(camera, w, h);
    // Not in stochastic mode: a segment ends at a random accepted Gaussian, which its neighbours' do not predict
    // (showroom_1.5M: 10-16 % of the rays had to go on, and the frame was slower at every margin tried).
    const bool speculate = settings.speculative_ends && settings.compositing == Compositing::Sorted;
    std::atomic<int> tiles_done{0};
    std::atomic<bool> cancelled{false};
    std::atomic<std::uint64_t> traced{0}, gaussian_hits{0}, candidates{0}, group_candidates{0};
    std::mutex progress_mutex;
    auto is_cancelled = [&] {
        if (cancelled.load(std::memory_order_relaxed)) return true;
        if (cancel && cancel->load(std::memory_order_relaxed)) {
            cancelled = true;
            return true;
        }
        return false;
    };

    tbb::parallel_for(tbb::blocked_range<int>(0, tile_count, 1), [&](const tbb::blocked_range<int>& range) {
        for (int tile = range.begin(); tile != range.end(); ++tile) {
            const int x0 = (tile % tiles_x) * ts, y0 = (tile / tiles_x) * ts;
            const int x1 = std::min(x0 + ts, w), y1 = std::min(y0 + ts, h);
            film.clear(x0, y0, x1, y1);  // also the tiles a cancel leaves empty
            if (is_cancelled()) continue;
            Counters counters;
            const int tw = x1 - x0;
            std::vector<glm::vec4> accum(std::size_t(tw) * (y1 - y0), glm::vec4(0.0f));
            std::vector<float> coverage(accum.size(), 0.0f);
            // Where each pixel's last camera segment ended (+inf: it escaped or was not traced yet).
            std::vector<float> segment_end(accum.size(), kInf);
            bool stop = false;
            // Samples outermost so that consecutive primary rays are coherent (neighbouring pixels).
            // Camera rays go to Embree as 4 x 4 packets (neighbouring pixels, coherent).
            for (int sample = 0; sample < settings.samples && !stop; ++sample) {
                for (int by = y0; by < y1 && !stop; by += 4) {
                    if (is_cancelled()) {
                        stop = true;
                        break;
                    }
                    for (int bx = x0; bx < x1; bx += 4) {
                        Ray rays[16];
                        bool active[16];
                        Sampler rngs[16];  // seeded below for the packet's pixels (the others are never used)
                        Segment segs[16];
                        bool any = false;
                        for (int l = 0; l < 16; ++l) {
                            const int x = bx + (l & 3), y = by + (l >> 2);
                            active[l] = false;
                            rays[l] = Ray{glm::vec3(0.0f), glm::vec3(0, 0, -1), 0.0f, 0.0f};
                            if (x >= x1 || y >= y1) continue;
                            const std::uint64_t pixel = std::uint64_t(y) * w + x;
                            rngs[l] = Sampler(settings.seed, pixel, std::uint32_t(sample));
                            float jx = 0.5f, jy = 0.5f;
                            if (settings.jitter) {
                                jx = rngs[l].next();
                                jy = rngs[l].next();
                            }
                            const CameraRay cr = camera_rays(x + jx, y + jy);
                            if (!cr.valid) continue;
                            rays[l] = Ray{glm::vec3(cr.origin[0], cr.origin[1], cr.origin[2]),
                                          glm::vec3(cr.direction[0], cr.direction[1], cr.direction[2]), cr.t_min, cr.t_max};
                            active[l] = any = true;
                        }
                        if (!any) continue;
                        float ends[16];
                        for (int l = 0; l < 16; ++l) {
                            const int x = bx + (l & 3), y = by + (l >> 2);
                            ends[l] = kInf;
                            if (!active[l] || !speculate) continue;
                            const float known = known_segment_end(segment_end, tw, x - x0, y - y0, bx - x0, by - y0,
                                                                  sample);
                            // (Not before the ray's own start: neighbours' clip starts differ.)
                            if (known * kSpeculativeMargin > rays[l].tmin) ends[l] = known * kSpeculativeMargin;
                        }
                        integrator.trace_packet(rays, active, ends, rngs, segs, counters);
                        for (int l = 0; l < 16; ++l)
                            if (active[l])
                                segment_end[std::size_t(by + (l >> 2) - y0) * tw + (bx + (l & 3) - x0)] = segs[l].end;
                        for (int l = 0; l < 16; ++l) {
                            if (!active[l]) continue;
                            const int x = bx + (l & 3), y = by + (l >> 2);
                            const std::uint64_t pixel = std::uint64_t(y) * w + x;
                            float a, depth;
                            glm::vec3 n;
                            const glm::vec3 lo = integrator.path(rays[l], rngs[l], counters, a, depth, n, &segs[l]);
                            const std::size_t li = std::size_t(y - y0) * tw + (x - x0);
                            accum[li] += glm::vec4(lo, 0.0f);
                            coverage[li] += a;
                            if (sample == 0) {
                                film.depth[pixel] = depth;
                                for (int k = 0; k < 3; ++k) film.normal[3 * pixel + k] = n[k];
                            }
                        }
                    }
                }
            }
            if (stop) {  // a cancelled tile is left empty rather than half-sampled
                film.clear(x0, y0, x1, y1);
                continue;
            }
            const float inv = 1.0f / float(settings.samples);
            for (int y = y0; y < y1; ++y)
                for (int x = x0; x < x1; ++x) {
                    const std::size_t li = std::size_t(y - y0) * tw + (x - x0);
                    const std::size_t pixel = std::size_t(y) * w + x;
                    const float cov = coverage[li] * inv;
                    for (int k = 0; k < 3; ++k) film.rgba[4 * pixel + k] = accum[li][k] * inv;
                    film.rgba[4 * pixel + 3] = settings.transparent_background ? cov : 1.0f;
                    film.alpha[pixel] = cov;
                }
            traced += counters.traced;
            gaussian_hits += counters.gaussian_hits;
            candidates += counters.candidates;
            group_candidates += counters.group_candidates;
            const int done = ++tiles_done;
            if (progress) {
                std::lock_guard<std::mutex> lock(progress_mutex);
                progress(float(done) / float(tile_count));
            }
        }
    });

    film.stats.cancelled = cancelled.load();
    film.stats.camera_rays = std::uint64_t(w) * h * settings.samples;
    film.stats.traced_rays = traced.load();
    film.stats.gaussian_hits = gaussian_hits.load();
    film.stats.gaussian_candidates = candidates.load();
    film.stats.gaussian_group_candidates = group_candidates.load();
    film.stats.render_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return film;
}

}  // namespace raysplats
