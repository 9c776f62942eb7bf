#include "gaussian_segment_tracer.h"

#include <algorithm>

#include "core/color_math.h"
#include "mist.h"

namespace raysplats {

// The helpers are inline, as they were when the tracer was one class body with the path integrator: GCC inlines
// them into the tracing loops below.
inline void GaussianSegmentTracer::init_rayhit(RTCRayHit& rh, const Ray& ray, float tnear) const {
    rh.ray.org_x = ray.o.x;
    rh.ray.org_y = ray.o.y;
    rh.ray.org_z = ray.o.z;
    rh.ray.dir_x = ray.d.x;
    rh.ray.dir_y = ray.d.y;
    rh.ray.dir_z = ray.d.z;
    rh.ray.tnear = tnear;
    rh.ray.tfar = ray.tmax;
    rh.ray.time = ray.time;
    rh.ray.mask = 0xffffffffu;
    rh.ray.id = 0;  // a single-ray query's state is lanes[0] of its TraceContext
    rh.ray.flags = 0;
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
}

inline void GaussianSegmentTracer::record_mesh(Segment& seg, float t, unsigned geom, unsigned inst, unsigned prim,
                                               float u, float v) const {
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
inline const GaussianSet& GaussianSegmentTracer::gaussian_of(unsigned geom, std::uint32_t& prim) const {
    const TopGeometry& tg = s_.top[geom];
    prim += tg.offset;
    return *s_.gaussians[tg.index];
}

// A LIT or BAKED_SHADOWED Gaussian of compositing weight `weight` (T_i a_i) joins the segment's shading point
// (gaussian_shading.h); its colour is produced when the path integrator shades the segment.
inline void GaussianSegmentTracer::add_shaded(Segment& seg, const GaussianSet& set, std::uint32_t prim,
                                              GaussianShading shading, const Ray& ray, float t, float weight,
                                              Sampler& rng) const {
    GaussianShadingPoint& sp = seg.shading;
    if (shading == GaussianShading::Lit) sp.albedo_sum += weight * shader_.albedo(set, prim);
    else sp.shadowed_sum += weight * set.color(prim, ray.o);
    glm::vec3 n = set.world_normal(prim);
    if (glm::dot(n, ray.d) > 0.0f) n = -n;  // two-sided: the side the ray comes from
    sp.add(weight, ray.o + t * ray.d, n, GaussianShader::shadow_bias(set, prim), rng);
    sp.time = ray.time;
}

// The colour Gaussian `prim` of `set` is composited with, in the settings' blend space (Segment::radiance): linear,
// or display as its SH give it. With meshes_shadow_gaussians the lights' visibility v from its centre scales its
// radiance, which is linear light: a display colour c becomes srgb(v * linear(c)), so both spaces darken a shadowed
// Gaussian alike.
inline glm::vec3 GaussianSegmentTracer::gaussian_color(const GaussianSet& set, std::uint32_t prim, const Ray& ray,
                                                       Sampler& rng, Counters& c) const {
    if (st_.blend_space == BlendSpace::Linear) {
        glm::vec3 color = set.color(prim, ray.o);
        if (st_.meshes_shadow_gaussians)
            color *= shadow_.gaussian_light_visibility(set.world_center(prim), ray.time, rng, c);
        return color;
    }
    glm::vec3 color = set.display_color(prim, ray.o);
    if (st_.meshes_shadow_gaussians) {
        const float v = shadow_.gaussian_light_visibility(set.world_center(prim), ray.time, rng, c);
        if (v < 1.0f)
            for (int ch = 0; ch < 3; ++ch) color[ch] = linear_to_srgb(v * srgb_to_linear(color[ch]));
    }
    return color;
}

// A Gaussian at `t` along a camera ray, of weight `weight` in the pixel, joins the Mist pass's sum (when the render
// has it, RenderSettings::mist_pass).
inline void GaussianSegmentTracer::add_mist(Segment& seg, const Ray& ray, float t, float weight) const {
    if (st_.mist_pass && ray.camera_distance >= 0.0f)
        seg.mist_clearance += weight * mist_clearance(s_.world, ray.camera_distance + t);
}

// A Gaussian of `set` of weight `weight` in a camera ray's pixel joins the Cryptomatte passes' coverage (when the
// render has them) under its cloud's ids.
inline void GaussianSegmentTracer::add_cryptomatte(Segment& seg, const GaussianSet& set, const Ray& ray,
                                                   float weight) const {
    if (cryptomatte_ && ray.camera_distance >= 0.0f) seg.cryptomatte.add(set.cryptomatte_ids, weight);
}

// A Gaussian of weight `weight` in a camera ray's pixel joins the denoiser's guides (Segment::guide_albedo): its
// linear colour clamped to [0, 1] (a LIT one's albedo) and its normal facing the ray (as the Normal pass's).
inline void GaussianSegmentTracer::add_guides(Segment& seg, const GaussianSet& set, std::uint32_t prim,
                                              const Ray& ray, float weight) const {
    if (!st_.denoising_data || ray.camera_distance < 0.0f) return;
    const glm::vec3 albedo = shader_.shading(set.index) == GaussianShading::Lit
                                 ? shader_.albedo(set, prim)
                                 : glm::clamp(set.color(prim, ray.o), glm::vec3(0.0f), glm::vec3(1.0f));
    const glm::vec3 n = set.flat ? set.world_normal(prim) : -ray.d;
    seg.guide_albedo += weight * albedo;
    seg.guide_normal += weight * (glm::dot(n, ray.d) > 0.0f ? -n : n);
}

// Composites one Gaussian onto the segment (front to back).
inline void GaussianSegmentTracer::composite(Segment& seg, const Ray& ray, std::uint32_t geom, std::uint32_t prim,
                                             float t, float alpha, Sampler& rng, Counters& c) const {
    const GaussianSet& set = gaussian_of(geom, prim);
    const float t_before = seg.transmittance;
    const GaussianShading shading = shader_.shading(set.index);
    if (set.holdout && ray.camera_distance >= 0.0f) {
        seg.holdout += t_before * alpha;  // held out: its coverage leaves Combined's alpha, it adds no colour
    } else if (shading == GaussianShading::Baked) {
        seg.radiance += t_before * alpha * gaussian_color(set, prim, ray, rng, c);
    } else {
        add_shaded(seg, set, prim, shading, ray, t, t_before * alpha, rng);
    }
    seg.transmittance = t_before * (1.0f - alpha);
    add_mist(seg, ray, t, t_before * alpha);
    add_guides(seg, set, prim, ray, t_before * alpha);
    add_cryptomatte(seg, set, ray, t_before * alpha);
    if (t_before > 0.5f && seg.transmittance <= 0.5f) {
        seg.depth = t;
        seg.depth_set = &set;
        glm::vec3 n = set.flat ? set.world_normal(prim) : -ray.d;
        seg.normal = glm::dot(n, ray.d) > 0.0f ? -n : n;
    }
    ++seg.gaussians;
    ++c.gaussian_hits;
}

inline void GaussianSegmentTracer::init_lane(LaneState& L) const {
    L.gather.set_capacity(st_.gather_buffer_size);
    L.transmittance_threshold = st_.transmittance_threshold;
}

// Moves one traversal's statistics from the lane to the counters.
inline void GaussianSegmentTracer::count_traversal(LaneState& L, Counters& c) {
    ++c.traced;
    c.candidates += L.candidates;
    c.group_candidates += L.group_candidates;
    L.candidates = 0;
    L.group_candidates = 0;
}

// Consumes one sorted gathering pass of a ray that ended at `end` (the ray's tmax or a speculative end):
// composites the buffer; true when the segment is complete, false when the ray must be re-traced from its last
// hit (the buffer overflowed) or from `end` (the speculative end came too early).
inline bool GaussianSegmentTracer::consume_gather(Segment& seg, LaneState& L, const Ray& ray, float end, float tfar,
                                                  unsigned geom, unsigned inst, unsigned prim, float u, float v,
                                                  Sampler& rng, Counters& c) const {
    count_traversal(L, c);
    for (int i = 0; i < L.gather.size(); ++i) {
        const GatherHit& h = L.gather[i];
        if (h.t > tfar) break;  // behind the mesh hit found later in the traversal
        composite(seg, ray, h.geom, h.prim, h.t, h.alpha, rng, c);
        if (seg.transmittance < st_.transmittance_threshold) {
            seg.terminated = true;
            seg.end = h.t;
            add_mist(seg, ray, h.t, seg.transmittance);
            std::uint32_t prim_in_set = h.prim;
            const GaussianSet& set = gaussian_of(h.geom, prim_in_set);
            add_guides(seg, set, prim_in_set, ray, seg.transmittance);
            add_cryptomatte(seg, set, ray, seg.transmittance);
            if (set.holdout && ray.camera_distance >= 0.0f) seg.holdout += seg.transmittance;
            return true;
        }
    }
    if (geom != RTC_INVALID_GEOMETRY_ID) {
        record_mesh(seg, tfar, geom, inst, prim, u, v);
        if (seg.transmittance > 0.5f) {
            seg.depth = seg.t;
            seg.depth_at_mesh = true;
        }
        return true;
    }
    // Every Gaussian up to `end` was gathered unless the buffer overflowed or was cut (and compositing did not
    // terminate within it: the cut came early by a rounding of GatherBuffer::prefix_).
    if (L.gather.truncated()) {
        L.gather.continue_behind_last();
        return false;
    }
    if (!(end < ray.tmax)) return true;
    // The speculative end came too early: go on behind everything this pass could see.
    L.gather.continue_behind(end);
    return false;
}

// Sorted gathering of a ray with single-ray queries, from the state left by earlier passes.
inline void GaussianSegmentTracer::trace_sorted_from(Segment& seg, LaneState& L, const Ray& ray, Sampler& rng,
                                                     Counters& c) const {
    TraceContext ctx(&L, 1, TraceMode::Gather);
    for (;;) {
        RTCRayHit rh;
        init_rayhit(rh, ray, L.gather.continues() ? L.gather.continuation_t() : ray.tmin);
        L.gather.begin_pass(seg.transmittance);
        // rtcIntersect1: the callbacks get this one ray (N = 1); tfar and the hit come back in rh.
        rtcIntersect1(s_.scene, &ctx, &rh);
        if (consume_gather(seg, L, ray, ray.tmax, rh.ray.tfar, rh.hit.geomID, rh.hit.instID[0], rh.hit.primID, rh.hit.u,
                           rh.hit.v, rng, c))
            return;
    }
}

inline Segment GaussianSegmentTracer::trace_sorted(const Ray& ray, Sampler& rng, Counters& c) const {
    Segment seg;
    LaneState L;
    init_lane(L);
    trace_sorted_from(seg, L, ray, rng, c);
    return seg;
}

inline void GaussianSegmentTracer::consume_stochastic(Segment& seg, LaneState& L, const Ray& ray, float tfar,
                                                      unsigned geom, unsigned inst, unsigned prim, float u, float v,
                                                      Sampler& rng, Counters& c) const {
    count_traversal(L, c);
    if (geom == RTC_INVALID_GEOMETRY_ID) return;
    // Every top-level geometry is an instance (a mesh or a chunk of Gaussians).
    if (s_.top[inst].kind == TopGeometry::Gaussians) {
        // Accepted with probability alpha: the estimator of sum T_i a_i c_i is c of the nearest accepted.
        // In display space too: the expectation of this estimator is the display composite sum T_i a_i c_i, and
        // the film takes the camera segment's display values to linear only after averaging them (SampleRecord).
        const GaussianSet& set = gaussian_of(inst, prim);
        const GaussianShading shading = shader_.shading(set.index);
        if (set.holdout && ray.camera_distance >= 0.0f) seg.holdout = 1.0f;
        else if (shading == GaussianShading::Baked) seg.radiance = gaussian_color(set, prim, ray, rng, c);
        else add_shaded(seg, set, prim, shading, ray, tfar, 1.0f, rng);
        seg.transmittance = 0.0f;
        seg.terminated = true;
        seg.depth = tfar;
        seg.depth_set = &set;
        add_mist(seg, ray, tfar, 1.0f);
        add_guides(seg, set, prim, ray, 1.0f);
        add_cryptomatte(seg, set, ray, 1.0f);
        const glm::vec3 n = set.flat ? set.world_normal(prim) : -ray.d;
        seg.normal = glm::dot(n, ray.d) > 0.0f ? -n : n;
        ++seg.gaussians;
        ++c.gaussian_hits;
        return;
    }
    record_mesh(seg, tfar, geom, inst, prim, u, v);
    seg.depth = seg.t;
    seg.depth_at_mesh = true;
}

inline Segment GaussianSegmentTracer::trace_stochastic(const Ray& ray, Sampler& rng, Counters& c) const {
    Segment seg;
    LaneState L;
    L.seed = rng.next_u32();
    TraceContext ctx(&L, 1, TraceMode::Stochastic);
    RTCRayHit rh;
    init_rayhit(rh, ray, ray.tmin);
    // rtcIntersect1: one ray, id 0; the nearest accepted Gaussian or mesh comes back as the hit.
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
void GaussianSegmentTracer::trace_packet(const Ray* rays, const bool* active, const float* ends, Sampler* rngs,
                                         Segment* segs, Counters& c) const {
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
        end[l] = std::min(r.tmax, ends[l]);
        if (active[l]) set_packet_lane(rh, l, r, end[l]);
        else set_packet_lane_inactive(rh, l);
    }
    TraceContext ctx(lanes, 16, sorted ? TraceMode::Gather : TraceMode::Stochastic);
    ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
    // rtcIntersect16 (any CPU): the rays come back in the packet's order, but the callbacks may see them split into
    // packets of 4 or 8 and reordered (TraceContext says how they find their state). Inactive lanes are inactive
    // both in `valid` and as empty segments (set_packet_lane_inactive).
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
            if (!valid[l]) {
                // Finished (or never active): not traced again, whatever the path Embree takes.
                set_packet_lane_inactive(rh, l);
                continue;
            }
            lanes[l].gather.begin_pass(segs[l].transmittance);
            rh.ray.tnear[l] = lanes[l].gather.continuation_t();
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

Segment GaussianSegmentTracer::trace(const Ray& ray, Sampler& rng, Counters& c) const {
    return st_.compositing == Compositing::Sorted ? trace_sorted(ray, rng, c) : trace_stochastic(ray, rng, c);
}

}  // namespace raysplats
