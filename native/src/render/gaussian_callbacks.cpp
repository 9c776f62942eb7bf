#include "gaussian_callbacks.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <string>
#include <type_traits>

#include "render_math.h"
#include "simd.h"

namespace raysplats {
namespace {

// Bounds callback (rtcSetGeometryBoundsFunction): the box of primitive primID, in the geometry's object space, at
// time step timeStep: always 0 without deformation; with it, Embree asks for every step (GaussianSet::
// build_deformation says why those boxes hold the group between the steps too).
void gaussians_bounds(const RTCBoundsFunctionArguments* args) {
    const auto* chunk = static_cast<const GaussianChunk*>(args->geometryUserPtr);
    *args->bounds_o = chunk->deformed.empty()
                          ? chunk->group_bounds[args->primID]
                          : chunk->deformed_bounds[std::size_t(args->timeStep) * chunk->groups.size() + args->primID];
}

// The group a ray of time `time` is tested against: `g` itself, or with deformation (where every group is wide) the
// group where that time puts its Gaussians, made in `moved`.
template <class G>
inline const G& group_at(const GaussianChunk& chunk, unsigned prim, const G& g, float time, G& moved) {
    if constexpr (std::is_same_v<G, GaussianGroup>) {
        if (!chunk.deformed.empty()) {
            chunk.set->deformed_group(chunk, prim, time, moved);
            return moved;
        }
    }
    return g;
}

// Exact ray test against every lane of a group: returns the mask of lanes whose support (GaussianGroup::support)
// the ray reaches at a t in [tnear, tfar], and writes t (any sign) and the squared distance of the
// evaluation point: flat, the ray-plane hit and the distance y0^2 + y1^2 there; volumetric, the maximum response
// along the ray, i.e. the point nearest to the centre in canonical coordinates.
//
// Every function here that holds an S::V is always_inline, down to the callbacks at the end, which carry the
// policy's target: with AVX2 a __m256 then never crosses a call between code built for different instruction sets
// (a call would pass it in a register on one side and in memory on the other). flatten alone does not promise that:
// at -O0 nothing is inlined but always_inline functions. The policy's own members may stay calls: after inlining,
// their callers are the callbacks, of the same target.
template <class S>
__attribute__((always_inline)) inline typename S::V dot3(typename S::V ax, typename S::V ay, typename S::V az,
                                                         typename S::V bx, typename S::V by, typename S::V bz) {
    return S::madd(az, bz, S::madd(ay, by, S::mul(ax, bx)));
}

// Field f of lanes [h, h + S::W) of a group of N lanes (GaussianLanes::fields); N == 1: the one lane's, in every
// SIMD lane.
template <class S, int N>
__attribute__((always_inline)) inline typename S::V load_field(const float* fields, int f, int h) {
    if constexpr (N == 1) return S::set1(fields[f]);
    else return S::load(fields + f * N + h);
}

template <class S, bool Flat, class G>
__attribute__((always_inline)) inline unsigned test_group(const G& g, const glm::vec3& o, const glm::vec3& d,
                                                          float tnear, float tfar, float* t_out, float* dist2_out) {
    using V = typename S::V;
    constexpr int N = int(sizeof(g.opacity) / sizeof(float));
    static_assert(N == 1 || N % S::W == 0, "a group is a whole number of steps");
    const float* f = g.fields();
    const V ox = S::set1(o.x), oy = S::set1(o.y), oz = S::set1(o.z);
    const V dx = S::set1(d.x), dy = S::set1(d.y), dz = S::set1(d.z);
    const V zero = S::set1(0.0f), lo = S::set1(tnear), hi = S::set1(tfar);
    unsigned mask = 0;
    for (int h = 0; h < N; h += S::W) {
        const V px = S::sub(ox, load_field<S, N>(f, 0, h));
        const V py = S::sub(oy, load_field<S, N>(f, 1, h));
        const V pz = S::sub(oz, load_field<S, N>(f, 2, h));
        V r[9];
        for (int k = 0; k < 9; ++k) r[k] = load_field<S, N>(f, 3 + k, h);
        V t, dist2, ok;
        if (Flat) {
            const V denom = dot3<S>(r[6], r[7], r[8], dx, dy, dz);
            t = S::div(S::neg(dot3<S>(r[6], r[7], r[8], px, py, pz)), denom);
            const V qx = S::madd(t, dx, px), qy = S::madd(t, dy, py), qz = S::madd(t, dz, pz);
            const V u = dot3<S>(r[0], r[1], r[2], qx, qy, qz), v = dot3<S>(r[3], r[4], r[5], qx, qy, qz);
            dist2 = S::madd(v, v, S::mul(u, u));
            ok = S::ne(denom, zero);
        } else {
            const V pu = dot3<S>(r[0], r[1], r[2], px, py, pz), pv = dot3<S>(r[3], r[4], r[5], px, py, pz),
                    pw = dot3<S>(r[6], r[7], r[8], px, py, pz);
            const V du = dot3<S>(r[0], r[1], r[2], dx, dy, dz), dv = dot3<S>(r[3], r[4], r[5], dx, dy, dz),
                    dw = dot3<S>(r[6], r[7], r[8], dx, dy, dz);
            const V d2 = dot3<S>(du, dv, dw, du, dv, dw);
            t = S::div(S::neg(dot3<S>(pu, pv, pw, du, dv, dw)), d2);
            const V qu = S::madd(t, du, pu), qv = S::madd(t, dv, pv), qw = S::madd(t, dw, pw);
            dist2 = dot3<S>(qu, qv, qw, qu, qv, qw);
            ok = S::ne(d2, zero);
        }
        ok = S::and_(ok, S::le(dist2, load_field<S, N>(f, 12, h)));
        ok = S::and_(ok, S::and_(S::le(lo, t), S::le(t, hi)));
        S::store(t_out + h, t);
        S::store(dist2_out + h, dist2);
        mask |= S::bits(ok) << h;
    }
    return N == 1 ? mask & 1u : mask;
}

// Intersect callback for rtcIntersect1 and ray packets (any N, any order: each ray's state is ctx->lanes[id]).
// Never reports a hit in Gather mode: it fills the per-ray k-nearest buffer and, once the buffer is full (or
// saturated), shrinks tfar so that traversal culls everything behind it (a mesh hit that lies behind is dropped
// and found again by the next re-trace).
// What it relies on from Embree (rtcSetGeometryIntersectFunction, RTCIntersectFunctionNArguments): `valid[i]` says
// which of the N rays to test; the rays and hits are read and written through the RTCRayN/RTCHitN accessors of
// rtcore_ray.h (SOA of width N); a hit is committed by shrinking tfar and writing the hit's ids; primID is the
// primitive of this geometry; context->instID[0] is the instance being traversed (a chunk's instance in the top
// scene); the ray arrives in that instance's object space (the cloud's frame, where the groups are), with its
// direction transformed but not normalised, so t means the same point as in world space.
template <class S, bool Flat, class G>
__attribute__((always_inline)) inline void intersect_group(const RTCIntersectFunctionNArguments* args,
                                                           TraceContext* ctx, const GaussianChunk* chunk, const G& g) {
    // Hits are identified by (top-level instance = chunk, primID in the chunk); rays arrive in object space.
    const std::uint32_t geom_id = args->context->instID[0];
    const unsigned n = args->N;
    RTCRayN* ray = RTCRayHitN_RayN(args->rayhit, n);
    RTCHitN* hit = RTCRayHitN_HitN(args->rayhit, n);
    // Two passes over the active rays (N <= 16: rtcIntersect1 and rtcIntersect16 only, or the packets of 4 or 8
    // Embree splits them into). First every ray is tested against the group with no data-dependent branch in
    // between, so that the out-of-order core overlaps the rays' tests (each a long dependency chain through a
    // division); then the rays with candidates are visited. Testing and visiting one ray at a time serialised the
    // tests behind the visits' unpredictable branches. A ray's test sees the tfar it had on entry either way (only
    // its own hits shrink it), so the images are the same.
    alignas(32) float ts[16][kGroupWidth], dist2s[16][kGroupWidth];
    unsigned masks[16];
    G moved;  // (deformation: the group at a ray's time)
    std::uint32_t active = 0;
    for (unsigned i = 0; i < n; ++i)
        active |= std::uint32_t(args->valid[i] != 0 && RTCRayN_id(ray, n, i) < ctx->lane_count) << i;
    std::uint32_t with_candidates = 0;
    for (std::uint32_t a = active; a; a &= a - 1) {
        const unsigned i = unsigned(__builtin_ctz(a));
        LaneState& L = ctx->lanes[RTCRayN_id(ray, n, i)];
        L.candidates += g.count;
        ++L.group_candidates;
        const glm::vec3 o(RTCRayN_org_x(ray, n, i), RTCRayN_org_y(ray, n, i), RTCRayN_org_z(ray, n, i));
        const glm::vec3 d(RTCRayN_dir_x(ray, n, i), RTCRayN_dir_y(ray, n, i), RTCRayN_dir_z(ray, n, i));
        masks[i] = test_group<S, Flat>(group_at(*chunk, args->primID, g, RTCRayN_time(ray, n, i), moved), o, d,
                                       RTCRayN_tnear(ray, n, i), RTCRayN_tfar(ray, n, i), ts[i], dist2s[i]);
        with_candidates |= std::uint32_t(masks[i] != 0) << i;
    }
    for (; with_candidates; with_candidates &= with_candidates - 1) {
        const unsigned i = unsigned(__builtin_ctz(with_candidates));
        LaneState& L = ctx->lanes[RTCRayN_id(ray, n, i)];
        float& tfar = RTCRayN_tfar(ray, n, i);
        // Lane by lane: a hit may shrink tfar, which culls the following lanes.
        for (unsigned mask = masks[i]; mask; mask &= mask - 1) {
            const int lane = __builtin_ctz(mask);
            const float t = ts[i][lane];
            if (!(t <= tfar)) continue;
            const float alpha = std::min(kMaxAlpha, g.opacity[lane] * std::exp(-0.5f * dist2s[i][lane]));
            if (alpha < kMinAlpha) continue;
            const std::uint32_t prim = g.first + std::uint32_t(lane);

            if (ctx->mode == TraceMode::Gather) {
                const float far = L.gather.insert(t, alpha, geom_id, prim, L.transmittance_threshold);
                if (far < tfar) {
                    tfar = far;
                    // A mesh hit behind the new far end is dropped; if it matters, the next re-trace finds it again.
                    RTCHitN_geomID(hit, n, i) = RTC_INVALID_GEOMETRY_ID;
                    RTCHitN_instID(hit, n, i, 0) = RTC_INVALID_GEOMETRY_ID;
                }
            } else if (ctx->mode == TraceMode::Stochastic) {
                // The acceptance draw depends on (ray seed, Gaussian) only: never on traversal order, primitive
                // order or chunking, so an edited or differently chunked scene draws the same for every Gaussian.
                const float u = u32_to_unit_float(hash_combine(L.seed, hash_combine(chunk->set->index, g.cloud_index[lane])));
                if (u >= alpha) continue;
                // The renderer needs only which Gaussian (instance = chunk, primID) and t; it computes the normal.
                tfar = t;
                RTCHitN_primID(hit, n, i) = prim;
                RTCHitN_geomID(hit, n, i) = args->geomID;
                RTCHitN_instID(hit, n, i, 0) = args->context->instID[0];
            }
        }
    }
}

// The group of primID in its width, tested with the path's policy S (eight lanes) or its four-lane policy.
template <class S, bool Flat>
__attribute__((always_inline)) inline void intersect_groups(const RTCIntersectFunctionNArguments* args) {
    auto* ctx = static_cast<TraceContext*>(args->context);
    if (ctx->mode == TraceMode::MeshesOnly) return;
    const auto* chunk = static_cast<const GaussianChunk*>(args->geometryUserPtr);
    const GaussianGroups::Location at = chunk->groups.locate(args->primID);
    if (at.width == GaussianGroups::Width::Eight)
        intersect_group<S, Flat>(args, ctx, chunk, chunk->groups.wide[at.index]);
    else if (at.width == GaussianGroups::Width::Four)
        intersect_group<typename Narrow<S>::type, Flat>(args, ctx, chunk, chunk->groups.quads[at.index]);
    else
        intersect_group<typename Narrow<S>::type, Flat>(args, ctx, chunk, chunk->groups.singles[at.index]);
}

// Occlusion callback: the transmittance of a shadow segment is the product of (1 - alpha) over the Gaussians
// on it, in any order, so no sorting is needed. Reports occlusion only when it falls below the threshold, the way
// Embree's occlusion queries report it: tfar set to -inf. Like the intersect callback it takes any N and finds each
// ray's state by the ray's id (only rtcOccluded1 calls it today).
template <class S, bool Flat, class G>
__attribute__((always_inline)) inline void occluded_group(const RTCOccludedFunctionNArguments* args,
                                                          TraceContext* ctx, const GaussianChunk* chunk, const G& g) {
    const unsigned n = args->N;
    RTCRayN* ray = args->ray;
    alignas(32) float ts[kGroupWidth], dist2s[kGroupWidth];
    G moved;  // (deformation: the group at a ray's time)
    for (unsigned i = 0; i < n; ++i) {
        if (!args->valid[i] || RTCRayN_id(ray, n, i) >= ctx->lane_count) continue;
        LaneState& L = ctx->lanes[RTCRayN_id(ray, n, i)];
        float& tfar = RTCRayN_tfar(ray, n, i);
        const glm::vec3 o(RTCRayN_org_x(ray, n, i), RTCRayN_org_y(ray, n, i), RTCRayN_org_z(ray, n, i));
        const glm::vec3 d(RTCRayN_dir_x(ray, n, i), RTCRayN_dir_y(ray, n, i), RTCRayN_dir_z(ray, n, i));
        const G& tested = group_at(*chunk, args->primID, g, RTCRayN_time(ray, n, i), moved);
        for (unsigned mask = test_group<S, Flat>(tested, o, d, RTCRayN_tnear(ray, n, i), tfar, ts, dist2s); mask;
             mask &= mask - 1) {
            const int lane = __builtin_ctz(mask);
            const float alpha = std::min(kMaxAlpha, g.opacity[lane] * std::exp(-0.5f * dist2s[lane]));
            if (alpha < kMinAlpha) continue;
            L.transmittance *= 1.0f - alpha;
            if (L.transmittance <= L.transmittance_threshold) {
                L.transmittance = 0.0f;
                tfar = -std::numeric_limits<float>::infinity();
                break;
            }
        }
    }
}

template <class S, bool Flat>
__attribute__((always_inline)) inline void occluded_groups(const RTCOccludedFunctionNArguments* args) {
    auto* ctx = static_cast<TraceContext*>(args->context);
    if (ctx->mode != TraceMode::Transmittance) return;
    const auto* chunk = static_cast<const GaussianChunk*>(args->geometryUserPtr);
    const GaussianGroups::Location at = chunk->groups.locate(args->primID);
    if (at.width == GaussianGroups::Width::Eight)
        occluded_group<S, Flat>(args, ctx, chunk, chunk->groups.wide[at.index]);
    else if (at.width == GaussianGroups::Width::Four)
        occluded_group<typename Narrow<S>::type, Flat>(args, ctx, chunk, chunk->groups.quads[at.index]);
    else
        occluded_group<typename Narrow<S>::type, Flat>(args, ctx, chunk, chunk->groups.singles[at.index]);
}

// The callbacks Embree calls, per instruction set and mode: everything above is inlined into them (always_inline
// where vectors pass, flatten for the rest) and so built for the function's target.
template <bool Flat>
__attribute__((flatten)) void gaussians_intersect_sse(const RTCIntersectFunctionNArguments* args) {
    intersect_groups<Sse, Flat>(args);
}
template <bool Flat>
__attribute__((flatten)) void gaussians_occluded_sse(const RTCOccludedFunctionNArguments* args) {
    occluded_groups<Sse, Flat>(args);
}
template <bool Flat>
__attribute__((target("avx2,fma"), flatten)) void gaussians_intersect_avx2(const RTCIntersectFunctionNArguments* args) {
    intersect_groups<Avx2, Flat>(args);
}
template <bool Flat>
__attribute__((target("avx2,fma"), flatten)) void gaussians_occluded_avx2(const RTCOccludedFunctionNArguments* args) {
    occluded_groups<Avx2, Flat>(args);
}

bool use_avx2() {
    // RAYSPLATS_SIMD=sse forces the baseline path (the test suite runs the render tests both ways).
    static const bool avx2 = __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma") &&
                             !(std::getenv("RAYSPLATS_SIMD") && std::string(std::getenv("RAYSPLATS_SIMD")) == "sse");
    return avx2;
}

}  // namespace

const char* gaussian_group_test_path() { return use_avx2() ? "avx2" : "sse"; }

RTCGeometry create_gaussian_geometry(RTCDevice device, GaussianChunk& chunk) {
    const bool avx2 = use_avx2();
    const bool flat = chunk.set->flat;
    RTCGeometry geom = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_USER);
    rtcSetGeometryUserData(geom, &chunk);
    rtcSetGeometryBoundsFunction(geom, gaussians_bounds, &chunk);
    if (avx2) {
        rtcSetGeometryIntersectFunction(geom, flat ? gaussians_intersect_avx2<true> : gaussians_intersect_avx2<false>);
        rtcSetGeometryOccludedFunction(geom, flat ? gaussians_occluded_avx2<true> : gaussians_occluded_avx2<false>);
    } else {
        rtcSetGeometryIntersectFunction(geom, flat ? gaussians_intersect_sse<true> : gaussians_intersect_sse<false>);
        rtcSetGeometryOccludedFunction(geom, flat ? gaussians_occluded_sse<true> : gaussians_occluded_sse<false>);
    }
    chunk.geometry = geom;
    chunk.set->update_geometry(chunk);
    return geom;
}

}  // namespace raysplats
