#include "gaussian_geometry.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <string>

#include <immintrin.h>

#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include "raysplats/spherical_harmonics.h"
#include "render_math.h"

namespace raysplats {
namespace {

bool hit_before(float t, std::uint64_t key, const GatherHit& h) {
    return t < h.t || (t == h.t && key < gather_key(h.geom, h.prim));
}

// Squared Mahalanobis radius of a Gaussian's support: 3, tightened to where a * G reaches 1/255 (hits below are
// skipped anyway): a exp(-r^2 / 2) = 1/255  <=>  r^2 = 2 ln(255 a). Not positive when it never reaches 1/255.
float support_sq(float opacity) { return std::min(kGaussianSupportSq, 2.0f * std::log(255.0f * opacity)); }

// Axis-aligned box of a Gaussian's support; false when it can never reach kMinAlpha.
bool gaussian_box(const GaussianPrimitive& g, bool flat, glm::vec3& lower, glm::vec3& upper) {
    // Columns of M^-1 (M = rows 0..2) are the world-space axes scaled by the standard deviations; for flat
    // Gaussians columns 0 and 1 span the disk (row 2 is orthogonal to both by construction).
    glm::mat3 m;
    m[0] = glm::vec3(g.row0.x, g.row1.x, g.row2.x);
    m[1] = glm::vec3(g.row0.y, g.row1.y, g.row2.y);
    m[2] = glm::vec3(g.row0.z, g.row1.z, g.row2.z);  // glm is column-major: m[c][r] = row r, column c
    const glm::mat3 l = glm::inverse(m);
    // Gaussians that never reach 1/255 get no box and are left out of every group.
    const float r2 = support_sq(g.opacity);
    if (!(r2 > 0.0f)) return false;
    const float radius = std::sqrt(r2);
    glm::vec3 half;
    for (int j = 0; j < 3; ++j) {
        float s = l[0][j] * l[0][j] + l[1][j] * l[1][j];
        if (!flat) s += l[2][j] * l[2][j];
        half[j] = radius * std::sqrt(s);
    }
    if (!std::isfinite(half.x + half.y + half.z)) half = glm::vec3(0.0f);  // degenerate: never hit anyway
    lower = g.center - half;
    upper = g.center + half;
    return true;
}

float half_area(const glm::vec3& lower, const glm::vec3& upper) {
    const glm::vec3 e = upper - lower;
    return e.x * e.y + e.y * e.z + e.z * e.x;
}

void gaussians_bounds(const RTCBoundsFunctionArguments* args) {
    const auto* chunk = static_cast<const GaussianChunk*>(args->geometryUserPtr);
    *args->bounds_o = chunk->group_bounds[args->primID];
}

// SIMD policies for the group test: 4 lanes with SSE (the x86-64 baseline; two steps per group) or 8 with AVX2 and
// FMA, chosen at run time. madd(a, b, c) = a b + c is one fused operation (one rounding) with FMA and a mul and an
// add with SSE, so the two paths differ in the last bits of t and of the distance (each is deterministic on its
// machine). FMA made the frames of showroom_1.5M (bench_render, 3 interleaved rounds) 2-4 % faster: stochastic
// 0.494-0.497 -> 0.480-0.499 s, sorted 1.77-1.79 -> 1.69-1.74 s. (Functions with a target attribute can only be
// inlined into callers with that target: see the callbacks at the end.)
struct Sse {
    using V = __m128;
    static constexpr int W = 4;
    static V load(const float* p) { return _mm_load_ps(p); }
    static V set1(float s) { return _mm_set1_ps(s); }
    static V add(V a, V b) { return _mm_add_ps(a, b); }
    static V sub(V a, V b) { return _mm_sub_ps(a, b); }
    static V mul(V a, V b) { return _mm_mul_ps(a, b); }
    static V div(V a, V b) { return _mm_div_ps(a, b); }
    static V le(V a, V b) { return _mm_cmple_ps(a, b); }
    static V ne(V a, V b) { return _mm_cmpneq_ps(a, b); }
    static V and_(V a, V b) { return _mm_and_ps(a, b); }
    static V neg(V a) { return _mm_xor_ps(a, _mm_set1_ps(-0.0f)); }
    static V madd(V a, V b, V c) { return _mm_add_ps(_mm_mul_ps(a, b), c); }  // a b + c
    static unsigned bits(V m) { return unsigned(_mm_movemask_ps(m)); }
    static void store(float* p, V a) { _mm_store_ps(p, a); }
};

// __m256 passes between these functions by value; all of them are inlined into the AVX2 callbacks, so the ABI
// note GCC gives (at the end of the file, hence not scoped) concerns no real call.
#pragma GCC diagnostic ignored "-Wpsabi"
struct Avx2 {
    using V = __m256;
    static constexpr int W = 8;
    __attribute__((target("avx2,fma"))) static V load(const float* p) { return _mm256_load_ps(p); }
    __attribute__((target("avx2,fma"))) static V set1(float s) { return _mm256_set1_ps(s); }
    __attribute__((target("avx2,fma"))) static V add(V a, V b) { return _mm256_add_ps(a, b); }
    __attribute__((target("avx2,fma"))) static V sub(V a, V b) { return _mm256_sub_ps(a, b); }
    __attribute__((target("avx2,fma"))) static V mul(V a, V b) { return _mm256_mul_ps(a, b); }
    __attribute__((target("avx2,fma"))) static V div(V a, V b) { return _mm256_div_ps(a, b); }
    __attribute__((target("avx2,fma"))) static V le(V a, V b) { return _mm256_cmp_ps(a, b, _CMP_LE_OQ); }
    __attribute__((target("avx2,fma"))) static V ne(V a, V b) { return _mm256_cmp_ps(a, b, _CMP_NEQ_UQ); }
    __attribute__((target("avx2,fma"))) static V and_(V a, V b) { return _mm256_and_ps(a, b); }
    __attribute__((target("avx2,fma"))) static V neg(V a) { return _mm256_xor_ps(a, _mm256_set1_ps(-0.0f)); }
    __attribute__((target("avx2,fma"))) static V madd(V a, V b, V c) { return _mm256_fmadd_ps(a, b, c); }
    __attribute__((target("avx2,fma"))) static unsigned bits(V m) { return unsigned(_mm256_movemask_ps(m)); }
    __attribute__((target("avx2,fma"))) static void store(float* p, V a) { _mm256_store_ps(p, a); }
};

// Exact ray test against every lane of a group: returns the mask of lanes whose support (GaussianGroup::support)
// the ray reaches at a t in [tnear, tfar], and writes t (any sign) and the squared distance of the
// evaluation point: flat, the ray-plane hit and the distance y0^2 + y1^2 there; volumetric, the maximum response
// along the ray, i.e. the point nearest to the centre in canonical coordinates.
template <class S, bool Flat>
inline unsigned test_group(const GaussianGroup& g, const glm::vec3& o, const glm::vec3& d, float tnear, float tfar,
                           float* t_out, float* dist2_out) {
    using V = typename S::V;
    const V ox = S::set1(o.x), oy = S::set1(o.y), oz = S::set1(o.z);
    const V dx = S::set1(d.x), dy = S::set1(d.y), dz = S::set1(d.z);
    const V zero = S::set1(0.0f), lo = S::set1(tnear), hi = S::set1(tfar);
    auto dot = [](V ax, V ay, V az, V bx, V by, V bz) {
        return S::madd(az, bz, S::madd(ay, by, S::mul(ax, bx)));
    };
    unsigned mask = 0;
    for (int h = 0; h < kGroupWidth; h += S::W) {
        const V px = S::sub(ox, S::load(&g.center[0][h]));
        const V py = S::sub(oy, S::load(&g.center[1][h]));
        const V pz = S::sub(oz, S::load(&g.center[2][h]));
        V r[9];
        for (int k = 0; k < 9; ++k) r[k] = S::load(&g.row[k][h]);
        V t, dist2, ok;
        if (Flat) {
            const V denom = dot(r[6], r[7], r[8], dx, dy, dz);
            t = S::div(S::neg(dot(r[6], r[7], r[8], px, py, pz)), denom);
            const V qx = S::madd(t, dx, px), qy = S::madd(t, dy, py), qz = S::madd(t, dz, pz);
            const V u = dot(r[0], r[1], r[2], qx, qy, qz), v = dot(r[3], r[4], r[5], qx, qy, qz);
            dist2 = S::madd(v, v, S::mul(u, u));
            ok = S::ne(denom, zero);
        } else {
            const V pu = dot(r[0], r[1], r[2], px, py, pz), pv = dot(r[3], r[4], r[5], px, py, pz),
                    pw = dot(r[6], r[7], r[8], px, py, pz);
            const V du = dot(r[0], r[1], r[2], dx, dy, dz), dv = dot(r[3], r[4], r[5], dx, dy, dz),
                    dw = dot(r[6], r[7], r[8], dx, dy, dz);
            const V d2 = dot(du, dv, dw, du, dv, dw);
            t = S::div(S::neg(dot(pu, pv, pw, du, dv, dw)), d2);
            const V qu = S::madd(t, du, pu), qv = S::madd(t, dv, pv), qw = S::madd(t, dw, pw);
            dist2 = dot(qu, qv, qw, qu, qv, qw);
            ok = S::ne(d2, zero);
        }
        ok = S::and_(ok, S::le(dist2, S::load(&g.support[h])));
        ok = S::and_(ok, S::and_(S::le(lo, t), S::le(t, hi)));
        S::store(t_out + h, t);
        S::store(dist2_out + h, dist2);
        mask |= S::bits(ok) << h;
    }
    return mask;
}

// Intersect callback for rtcIntersect1 and ray packets (any N; the accessors of rtcore_ray.h address lane i).
// Never reports a hit in Gather mode: it fills the per-ray k-nearest buffer and, once the buffer is full (or
// saturated), shrinks tfar so that traversal culls everything behind it (a mesh hit that lies behind is dropped
// and found again by the next re-trace).
template <class S, bool Flat>
inline void intersect_groups(const RTCIntersectFunctionNArguments* args) {
    auto* ctx = static_cast<TraceContext*>(args->context);
    if (ctx->mode == TraceMode::MeshesOnly) return;
    const auto* chunk = static_cast<const GaussianChunk*>(args->geometryUserPtr);
    const GaussianGroup& g = chunk->groups[args->primID];
    // Hits are identified by (top-level instance = chunk, primID in the chunk); rays arrive in object space.
    const std::uint32_t geom_id = args->context->instID[0];
    const unsigned n = args->N;
    RTCRayN* ray = RTCRayHitN_RayN(args->rayhit, n);
    RTCHitN* hit = RTCRayHitN_HitN(args->rayhit, n);
    // Two passes over the active rays (N <= 16: rtcIntersect1 and rtcIntersect16 only). First every ray is tested
    // against the group with no data-dependent branch in between, so that the out-of-order core overlaps the rays'
    // tests (each a long dependency chain through a division); then the rays with candidates are visited. Testing
    // and visiting one ray at a time serialised the tests behind the visits' unpredictable branches (a packet
    // callback has 7.3 active rays on average, a ray test 0.53 candidates, stochastic mode). A ray's test
    // sees the tfar it had on entry either way (only its own hits shrink it): the images are bit-identical.
    // showroom_1.5M (bench_render, 3 interleaved rounds): stochastic frame 0.541-0.566 -> 0.495-0.496 s
    // (0.52 -> 0.48 us CPU/ray), sorted 1.947-1.968 -> 1.755-1.766 s (1.88 -> 1.69 us CPU/ray).
    alignas(32) float ts[16][kGroupWidth], dist2s[16][kGroupWidth];
    unsigned masks[16];
    std::uint32_t active = 0;
    for (unsigned i = 0; i < n; ++i) active |= std::uint32_t(args->valid[i] != 0) << i;
    std::uint32_t with_candidates = 0;
    for (std::uint32_t a = active; a; a &= a - 1) {
        const unsigned i = unsigned(__builtin_ctz(a));
        LaneState& L = ctx->lanes[i];
        L.candidates += g.count;
        ++L.group_candidates;
        const glm::vec3 o(RTCRayN_org_x(ray, n, i), RTCRayN_org_y(ray, n, i), RTCRayN_org_z(ray, n, i));
        const glm::vec3 d(RTCRayN_dir_x(ray, n, i), RTCRayN_dir_y(ray, n, i), RTCRayN_dir_z(ray, n, i));
        masks[i] = test_group<S, Flat>(g, o, d, RTCRayN_tnear(ray, n, i), RTCRayN_tfar(ray, n, i), ts[i], dist2s[i]);
        with_candidates |= std::uint32_t(masks[i] != 0) << i;
    }
    for (; with_candidates; with_candidates &= with_candidates - 1) {
        const unsigned i = unsigned(__builtin_ctz(with_candidates));
        LaneState& L = ctx->lanes[i];
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
                const std::uint64_t key = gather_key(geom_id, prim);
                if (L.has_after && (t < L.after_t || (t == L.after_t && key <= L.after_key))) continue;
                const int k = L.capacity;
                int last = L.count;  // index of the buffer's last hit after the insertion
                if (L.count == k) {
                    if (!hit_before(t, key, L.hits[k - 1])) continue;
                    last = k - 1;  // the last hit is dropped
                }
                // Insertion from the back: each shifted hit now lies behind the new one.
                const float keep = 1.0f - alpha;
                int pos = last;
                while (pos > 0 && hit_before(t, key, L.hits[pos - 1])) {
                    L.hits[pos] = L.hits[pos - 1];
                    L.prefix[pos] = L.prefix[pos - 1] * keep;
                    --pos;
                }
                L.hits[pos] = GatherHit{t, alpha, geom_id, prim};
                L.prefix[pos] = (pos > 0 ? L.prefix[pos - 1] : L.base_transmittance) * keep;
                L.count = last + 1;
                float far = tfar;
                L.saturated = L.prefix[last] < L.transmittance_threshold;
                if (L.saturated) {
                    // Entries before pos - 1 are unchanged and were above the threshold (the buffer ends at the
                    // first one below); the new hit may lie behind the cut (equal t, larger key).
                    int cut = pos > 0 ? pos - 1 : 0;
                    while (!(L.prefix[cut] < L.transmittance_threshold)) ++cut;
                    L.count = cut + 1;
                    far = L.hits[cut].t;
                } else if (L.count == k) {
                    far = L.hits[k - 1].t;
                }
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

// Occlusion callback: the transmittance of a shadow segment is the product of (1 - alpha) over the Gaussians
// on it, in any order, so no sorting is needed. Reports occlusion only when it falls below the threshold.
template <class S, bool Flat>
inline void occluded_groups(const RTCOccludedFunctionNArguments* args) {
    auto* ctx = static_cast<TraceContext*>(args->context);
    if (args->N != 1 || !args->valid[0] || ctx->mode != TraceMode::Transmittance) return;
    LaneState& L = ctx->lanes[0];
    const auto* chunk = static_cast<const GaussianChunk*>(args->geometryUserPtr);
    const GaussianGroup& g = chunk->groups[args->primID];
    RTCRay* ray = reinterpret_cast<RTCRay*>(args->ray);
    const glm::vec3 o(ray->org_x, ray->org_y, ray->org_z);
    const glm::vec3 d(ray->dir_x, ray->dir_y, ray->dir_z);
    alignas(32) float ts[kGroupWidth], dist2s[kGroupWidth];
    for (unsigned mask = test_group<S, Flat>(g, o, d, ray->tnear, ray->tfar, ts, dist2s); mask; mask &= mask - 1) {
        const int lane = __builtin_ctz(mask);
        const float alpha = std::min(kMaxAlpha, g.opacity[lane] * std::exp(-0.5f * dist2s[lane]));
        if (alpha < kMinAlpha) continue;
        L.transmittance *= 1.0f - alpha;
        if (L.transmittance <= L.transmittance_threshold) {
            L.transmittance = 0.0f;
            ray->tfar = -std::numeric_limits<float>::infinity();
            return;
        }
    }
}

// The callbacks Embree calls, per instruction set and mode (flatten: everything above is inlined with the
// function's target).
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

// Indices of the cloud's Gaussians in Morton order (10 bits per axis) of their centres.
std::vector<std::uint32_t> morton_order(const GaussianCloud& c) {
    const std::size_t n = c.size();
    glm::vec3 lo(std::numeric_limits<float>::max()), hi(-std::numeric_limits<float>::max());
    for (std::size_t i = 0; i < n; ++i) {
        const glm::vec3 p(c.positions[3 * i], c.positions[3 * i + 1], c.positions[3 * i + 2]);
        lo = glm::min(lo, p);
        hi = glm::max(hi, p);
    }
    const glm::vec3 extent = glm::max(hi - lo, glm::vec3(1e-30f));
    auto spread = [](std::uint64_t v) {  // 10 bits -> every third bit
        v &= 0x3ff;
        v = (v | (v << 16)) & 0x30000ff;
        v = (v | (v << 8)) & 0x300f00f;
        v = (v | (v << 4)) & 0x30c30c3;
        v = (v | (v << 2)) & 0x9249249;
        return v;
    };
    std::vector<std::uint64_t> keyed(n);
    tbb::parallel_for(std::size_t(0), n, [&](std::size_t i) {
        const glm::vec3 p(c.positions[3 * i], c.positions[3 * i + 1], c.positions[3 * i + 2]);
        const glm::vec3 q = glm::clamp((p - lo) / extent, 0.0f, 1.0f) * 1023.0f;
        const std::uint64_t code = spread(std::uint64_t(q.x)) | (spread(std::uint64_t(q.y)) << 1) | (spread(std::uint64_t(q.z)) << 2);
        keyed[i] = (code << 32) | std::uint64_t(i);
    });
    tbb::parallel_sort(keyed.begin(), keyed.end());
    std::vector<std::uint32_t> order(n);
    for (std::size_t j = 0; j < n; ++j) order[j] = std::uint32_t(keyed[j] & 0xffffffffu);
    return order;
}

}  // namespace

void GaussianSet::set_transform(const Matrix4& m) {
    object_to_world = m;
    linear = linear_part(m);
    translation = translation_part(m);
    world_to_object_dir = glm::inverse(linear);
    normal_matrix = glm::transpose(world_to_object_dir);
}

namespace {

// The primitive of Gaussian i of a cloud (see GaussianPrimitive).
GaussianPrimitive make_primitive(const GaussianCloud& c, std::size_t i, bool flat) {
    const float* q = &c.rotations[4 * i];
    glm::vec4 qq(q[0], q[1], q[2], q[3]);
    const float qn = glm::length(qq);
    qq = qn > 0.0f ? qq / qn : glm::vec4(1, 0, 0, 0);
    const float w = qq[0], x = qq[1], y = qq[2], z = qq[3];
    // Columns of R: the Gaussian's axes (reference 3DGS build_rotation).
    const glm::vec3 axis[3] = {
        {1 - 2 * (y * y + z * z), 2 * (x * y + w * z), 2 * (x * z - w * y)},
        {2 * (x * y - w * z), 1 - 2 * (x * x + z * z), 2 * (y * z + w * x)},
        {2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)},
    };
    const float* s = &c.scales[3 * i];
    int order[3] = {0, 1, 2};
    std::sort(order, order + 3, [&](int l, int r2) { return s[l] > s[r2]; });
    const float smax = std::max(s[order[0]], 1e-30f);
    auto inv_scale = [&](int k) { return 1.0f / std::max(s[k], 1e-6f * smax); };
    GaussianPrimitive g;
    g.center = glm::vec3(c.positions[3 * i], c.positions[3 * i + 1], c.positions[3 * i + 2]);
    g.opacity = std::min(std::max(c.opacities[i], 0.0f), 1.0f);
    g.row0 = axis[order[0]] * inv_scale(order[0]);
    g.row1 = axis[order[1]] * inv_scale(order[1]);
    g.row2 = flat ? axis[order[2]] : axis[order[2]] * inv_scale(order[2]);
    g.cloud_index = std::uint32_t(i);
    g.pad1 = g.pad2 = 0.0f;
    return g;
}

}  // namespace

std::vector<char> GaussianSet::prepare(GaussianMode mode, bool keep_order) {
    const bool was_flat = flat;
    flat = mode == GaussianMode::Flat;
    const GaussianCloud& c = *cloud;
    const std::size_t n = c.size();
    keep_order = keep_order && cloud_index.size() == n && was_flat == flat;
    const std::size_t chunk_count = (n + std::size_t(chunk_size) - 1) / std::size_t(chunk_size);
    std::vector<std::atomic<bool>> chunk_changed(chunk_count);
    for (auto& f : chunk_changed) f = !keep_order;
    prims.resize(n);
    const bool deg0 = c.sh_degree == 0;
    if (deg0) linear_rgb.resize(3 * n);
    else linear_rgb.clear();
    if (!keep_order) {
        cloud_index = morton_order(c);
        prim_index.resize(n);
        for (std::size_t j = 0; j < n; ++j) prim_index[cloud_index[j]] = std::uint32_t(j);
    }

    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 4096), [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t j = r.begin(); j != r.end(); ++j) {
            const std::size_t i = cloud_index[j];
            const GaussianPrimitive g = make_primitive(c, i, flat);
            if (keep_order && std::memcmp(&g, &prims[j], sizeof(g)) != 0)
                chunk_changed[j / std::size_t(chunk_size)].store(true, std::memory_order_relaxed);
            prims[j] = g;
            if (deg0) store_linear_rgb(j);
        }
    });
    std::vector<char> changed(chunk_count);
    for (std::size_t k = 0; k < chunk_count; ++k) changed[k] = chunk_changed[k].load();
    return changed;
}

std::vector<char> GaussianSet::prepare_rows(const std::vector<std::uint32_t>& rows) {
    const GaussianCloud& c = *cloud;
    std::vector<char> changed((c.size() + std::size_t(chunk_size) - 1) / std::size_t(chunk_size), 0);
    for (const std::uint32_t i : rows) {
        const std::uint32_t j = prim_index[i];
        const GaussianPrimitive g = make_primitive(c, i, flat);
        if (std::memcmp(&g, &prims[j], sizeof(g)) != 0) changed[j / chunk_size] = 1;
        prims[j] = g;
        if (!linear_rgb.empty()) store_linear_rgb(j);
    }
    return changed;
}

void GaussianSet::store_linear_rgb(std::uint32_t j) {
    const float* dc = &cloud->sh[3 * std::size_t(cloud_index[j])];
    for (int ch = 0; ch < 3; ++ch) linear_rgb[3 * j + ch] = srgb_to_linear(std::max(0.0f, 0.5f + float(kShC0) * dc[ch]));
}

glm::vec3 GaussianSet::color(std::uint32_t i, const glm::vec3& origin) const {
    if (!linear_rgb.empty()) return {linear_rgb[3 * i], linear_rgb[3 * i + 1], linear_rgb[3 * i + 2]};
    // Reference 3DGS: the SH are evaluated in the direction from the camera (ray origin) to the centre, here in
    // the cloud's frame: A^-1 (A c + b - o) = c - A^-1 (o - b).
    glm::vec3 dir = prims[i].center - world_to_object_dir * (origin - translation);
    const float len = glm::length(dir);
    dir = len > 0.0f ? dir / len : glm::vec3(0, 0, 1);
    const int k = cloud->coeffs_per_channel();
    const auto rgb = evaluate_sh(cloud->sh_degree, &cloud->sh[std::size_t(cloud_index[i]) * k * 3], dir.x, dir.y, dir.z);
    return {srgb_to_linear(rgb[0]), srgb_to_linear(rgb[1]), srgb_to_linear(rgb[2])};
}

// Greedy over the chunk's Gaussians in Morton order, in independent blocks of 4096 (parallel, deterministic): a
// group takes the next Gaussian while it has fewer than kGroupWidth and the surface area of the union box stays
// at most the sum of its members' box areas (a ray that reaches the union box would have reached about as many
// member boxes: what grouping saves is the per-primitive overhead, not Gaussian tests). A Gaussian without a box
// ends the group and is left out. On showroom_1.5M (bench_render) this gives about 5.6 Gaussians per group
// reached; allowing 1.5x or 2x the area made groups fuller but every ray test more Gaussians (slower), 0.8x or
// 0.9x made more groups (slower sorted); groups of 4 gained about half as much, groups of 16 nothing.
void GaussianSet::build_groups(GaussianChunk& chunk) const {
    struct Spec {
        std::uint32_t first, count;
        glm::vec3 lower, upper;
    };
    constexpr std::uint32_t kBlock = 4096;
    const std::uint32_t blocks = (chunk.count + kBlock - 1) / kBlock;
    std::vector<std::vector<Spec>> specs(blocks);
    tbb::parallel_for(std::uint32_t(0), blocks, [&](std::uint32_t b) {
        const std::uint32_t begin = b * kBlock, end = std::min(chunk.count, begin + kBlock);
        std::vector<Spec>& out = specs[b];
        out.reserve((end - begin) / 2);
        bool open = false;
        float area_sum = 0.0f;
        for (std::uint32_t j = begin; j < end; ++j) {
            glm::vec3 lo, hi;
            if (!gaussian_box(prims[chunk.offset + j], flat, lo, hi)) {
                open = false;
                continue;
            }
            const float area = half_area(lo, hi);
            if (open) {
                Spec& s = out.back();
                const glm::vec3 ulo = glm::min(s.lower, lo), uhi = glm::max(s.upper, hi);
                const float ua = half_area(ulo, uhi);
                if (s.count < std::uint32_t(kGroupWidth) && ua <= area_sum + area) {
                    s.lower = ulo;
                    s.upper = uhi;
                    ++s.count;
                    area_sum += area;
                    continue;
                }
            }
            out.push_back(Spec{j, 1, lo, hi});
            area_sum = area;
            open = true;
        }
    });
    std::vector<std::size_t> base(blocks + 1, 0);
    for (std::uint32_t b = 0; b < blocks; ++b) base[b + 1] = base[b] + specs[b].size();
    chunk.groups.assign(base[blocks], GaussianGroup{});
    chunk.group_bounds.resize(base[blocks]);
    tbb::parallel_for(std::uint32_t(0), blocks, [&](std::uint32_t b) {
        for (std::size_t k = 0; k < specs[b].size(); ++k) {
            const Spec& s = specs[b][k];
            GaussianGroup& g = chunk.groups[base[b] + k];
            g.first = s.first;
            g.count = s.count;
            for (int lane = 0; lane < kGroupWidth; ++lane) {
                GaussianPrimitive p;
                if (std::uint32_t(lane) < s.count) p = prims[chunk.offset + s.first + lane];
                else std::memset(&p, 0, sizeof(p));  // padding: zero rows fail the ray test (denominator 0)
                const glm::vec3 rows[3] = {p.row0, p.row1, p.row2};
                for (int a = 0; a < 3; ++a) {
                    g.center[a][lane] = p.center[a];
                    for (int r = 0; r < 3; ++r) g.row[3 * r + a][lane] = rows[r][a];
                }
                g.opacity[lane] = p.opacity;
                g.cloud_index[lane] = p.cloud_index;
                g.support[lane] = std::uint32_t(lane) < s.count ? support_sq(p.opacity) : 0.0f;
            }
            RTCBounds& bb = chunk.group_bounds[base[b] + k];
            bb = RTCBounds{};
            bb.lower_x = s.lower.x;
            bb.lower_y = s.lower.y;
            bb.lower_z = s.lower.z;
            bb.upper_x = s.upper.x;
            bb.upper_y = s.upper.y;
            bb.upper_z = s.upper.z;
        }
    });
}

void GaussianSet::update_geometry(GaussianChunk& chunk) const {
    build_groups(chunk);
    rtcSetGeometryUserPrimitiveCount(chunk.geometry, unsigned(chunk.groups.size()));
    rtcCommitGeometry(chunk.geometry);
}

RTCGeometry GaussianSet::create_geometry(RTCDevice device, GaussianChunk& chunk) const {
    // RAYSPLATS_SIMD=sse forces the baseline path (the test suite runs the render tests both ways).
    static const bool avx2 = __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma") &&
                             !(std::getenv("RAYSPLATS_SIMD") && std::string(std::getenv("RAYSPLATS_SIMD")) == "sse");
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
    update_geometry(chunk);
    return geom;
}

}  // namespace raysplats
