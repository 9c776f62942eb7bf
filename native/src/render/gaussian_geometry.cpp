#include "gaussian_geometry.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>
#include <limits>

#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include "raysplats/spherical_harmonics.h"
#include "render_math.h"

namespace raysplats {
namespace {

bool hit_before(float t, std::uint64_t key, const GatherHit& h) {
    return t < h.t || (t == h.t && key < gather_key(h.geom, h.prim));
}

void gaussians_bounds(const RTCBoundsFunctionArguments* args) {
    const auto* chunk = static_cast<const GaussianChunk*>(args->geometryUserPtr);
    const GaussianSet* set = chunk->set;
    const GaussianPrimitive& g = set->prims[chunk->offset + args->primID];
    // Columns of M^-1 (M = rows 0..2) are the world-space axes scaled by the standard deviations; for flat
    // Gaussians columns 0 and 1 span the disk (row 2 is orthogonal to both by construction).
    glm::mat3 m;
    m[0] = glm::vec3(g.row0.x, g.row1.x, g.row2.x);
    m[1] = glm::vec3(g.row0.y, g.row1.y, g.row2.y);
    m[2] = glm::vec3(g.row0.z, g.row1.z, g.row2.z);  // glm is column-major: m[c][r] = row r, column c
    const glm::mat3 l = glm::inverse(m);
    // Support: Mahalanobis radius 3, tightened to where a * G reaches 1/255 (hits below are skipped anyway):
    // a exp(-r^2 / 2) = 1/255  <=>  r^2 = 2 ln(255 a). Gaussians that never reach 1/255 get an invalid box, which
    // Embree leaves out of the BVH.
    const float r2 = std::min(kGaussianSupportSq, 2.0f * std::log(255.0f * g.opacity));
    RTCBounds* b = args->bounds_o;
    if (!(r2 > 0.0f)) {
        b->lower_x = b->lower_y = b->lower_z = std::numeric_limits<float>::infinity();
        b->upper_x = b->upper_y = b->upper_z = -std::numeric_limits<float>::infinity();
        return;
    }
    const float radius = std::sqrt(r2);
    glm::vec3 half;
    for (int j = 0; j < 3; ++j) {
        float s = l[0][j] * l[0][j] + l[1][j] * l[1][j];
        if (!set->flat) s += l[2][j] * l[2][j];
        half[j] = radius * std::sqrt(s);
    }
    if (!std::isfinite(half.x + half.y + half.z)) half = glm::vec3(0.0f);  // degenerate: never hit anyway
    b->lower_x = g.center.x - half.x;
    b->lower_y = g.center.y - half.y;
    b->lower_z = g.center.z - half.z;
    b->upper_x = g.center.x + half.x;
    b->upper_y = g.center.y + half.y;
    b->upper_z = g.center.z + half.z;
}

// Intersect callback for rtcIntersect1 and ray packets (any N; the accessors of rtcore_ray.h address lane i).
// Never reports a hit in Gather mode: it fills the per-ray k-nearest buffer and, once the buffer is full (or
// saturated), shrinks tfar so that traversal culls everything behind it (a mesh hit that lies behind is dropped
// and found again by the next re-trace).
void gaussians_intersect(const RTCIntersectFunctionNArguments* args) {
    auto* ctx = static_cast<TraceContext*>(args->context);
    if (ctx->mode == TraceMode::MeshesOnly) return;
    const auto* chunk = static_cast<const GaussianChunk*>(args->geometryUserPtr);
    const GaussianSet* set = chunk->set;
    const GaussianPrimitive& g = set->prims[chunk->offset + args->primID];
    // Hits are identified by (top-level instance = chunk, primID in the chunk); rays arrive in object space.
    const std::uint32_t geom_id = args->context->instID[0];
    const unsigned n = args->N;
    RTCRayN* ray = RTCRayHitN_RayN(args->rayhit, n);
    RTCHitN* hit = RTCRayHitN_HitN(args->rayhit, n);
    for (unsigned i = 0; i < n; ++i) {
        if (!args->valid[i]) continue;
        LaneState& L = ctx->lanes[i];
        ++L.candidates;
        const glm::vec3 o(RTCRayN_org_x(ray, n, i), RTCRayN_org_y(ray, n, i), RTCRayN_org_z(ray, n, i));
        const glm::vec3 d(RTCRayN_dir_x(ray, n, i), RTCRayN_dir_y(ray, n, i), RTCRayN_dir_z(ray, n, i));
        float t, dist2;
        if (!intersect_gaussian(g, set->flat, o, d, t, dist2)) continue;
        float& tfar = RTCRayN_tfar(ray, n, i);
        if (!(t >= RTCRayN_tnear(ray, n, i) && t <= tfar)) continue;
        const float alpha = std::min(kMaxAlpha, g.opacity * std::exp(-0.5f * dist2));
        if (alpha < kMinAlpha) continue;

        if (ctx->mode == TraceMode::Gather) {
            const std::uint64_t key = gather_key(geom_id, args->primID);
            if (L.has_after && (t < L.after_t || (t == L.after_t && key <= L.after_key))) continue;
            int pos;
            const int k = L.capacity;
            if (L.count < k) {
                pos = L.count++;
            } else {
                if (!hit_before(t, key, L.hits[k - 1])) continue;
                L.product /= 1.0f - L.hits[k - 1].alpha;  // evicted
                pos = k - 1;
            }
            while (pos > 0 && hit_before(t, key, L.hits[pos - 1])) {
                L.hits[pos] = L.hits[pos - 1];
                --pos;
            }
            L.hits[pos] = GatherHit{t, alpha, geom_id, args->primID};
            L.product *= 1.0f - alpha;
            int cut = -1;
            if (L.base_transmittance * L.product < L.transmittance_threshold) {
                // Exact scan for the first index where the transmittance falls below the threshold.
                float T = L.base_transmittance, P = 1.0f;
                for (int j = 0; j < L.count; ++j) {
                    P *= 1.0f - L.hits[j].alpha;
                    T *= 1.0f - L.hits[j].alpha;
                    if (T < L.transmittance_threshold) {
                        cut = j;
                        L.product = P;
                        break;
                    }
                }
            }
            float far = tfar;
            if (cut >= 0) {
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
            // The acceptance draw depends on (ray seed, Gaussian) only: never on traversal order, primitive order
            // or chunking, so an edited or differently chunked scene draws the same for every Gaussian.
            const float u = u32_to_unit_float(hash_combine(L.seed, hash_combine(set->index, g.cloud_index)));
            if (u >= alpha) continue;
            // The renderer needs only which Gaussian (instance = chunk, primID) and t; it computes the normal.
            tfar = t;
            RTCHitN_primID(hit, n, i) = args->primID;
            RTCHitN_geomID(hit, n, i) = args->geomID;
            RTCHitN_instID(hit, n, i, 0) = args->context->instID[0];
        }
    }
}

// Occlusion callback: the transmittance of a shadow segment is the product of (1 - alpha) over the Gaussians
// on it, in any order, so no sorting is needed. Reports occlusion only when it falls below the threshold.
void gaussians_occluded(const RTCOccludedFunctionNArguments* args) {
    auto* ctx = static_cast<TraceContext*>(args->context);
    if (args->N != 1 || !args->valid[0] || ctx->mode != TraceMode::Transmittance) return;
    LaneState& L = ctx->lanes[0];
    const auto* chunk = static_cast<const GaussianChunk*>(args->geometryUserPtr);
    const GaussianSet* set = chunk->set;
    RTCRay* ray = reinterpret_cast<RTCRay*>(args->ray);
    const GaussianPrimitive& g = set->prims[chunk->offset + args->primID];
    const glm::vec3 o(ray->org_x, ray->org_y, ray->org_z);
    const glm::vec3 d(ray->dir_x, ray->dir_y, ray->dir_z);
    float t, dist2;
    if (!intersect_gaussian(g, set->flat, o, d, t, dist2)) return;
    if (!(t >= ray->tnear && t <= ray->tfar)) return;
    const float alpha = std::min(kMaxAlpha, g.opacity * std::exp(-0.5f * dist2));
    if (alpha < kMinAlpha) return;
    L.transmittance *= 1.0f - alpha;
    if (L.transmittance <= L.transmittance_threshold) {
        L.transmittance = 0.0f;
        ray->tfar = -std::numeric_limits<float>::infinity();
    }
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

RTCGeometry GaussianSet::create_geometry(RTCDevice device, GaussianChunk& chunk) const {
    RTCGeometry geom = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_USER);
    rtcSetGeometryUserPrimitiveCount(geom, chunk.count);
    rtcSetGeometryUserData(geom, &chunk);
    rtcSetGeometryBoundsFunction(geom, gaussians_bounds, &chunk);
    rtcSetGeometryIntersectFunction(geom, gaussians_intersect);
    rtcSetGeometryOccludedFunction(geom, gaussians_occluded);
    rtcCommitGeometry(geom);
    return geom;
}

}  // namespace raysplats
