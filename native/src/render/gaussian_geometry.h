// Gaussians as Embree user geometry (internal). Each Gaussian is stored as its centre and three world-space
// rows that map a world offset x - m to canonical coordinates:
//   volumetric: y = S^-1 R^T A^-1 (x - m), G = exp(-|y|^2 / 2), the ellipsoid of Mahalanobis radius 3 is |y| <= 3;
//   flat:       rows 0 and 1 as above (the two largest axes), row 2 the plane normal (R's smallest axis pulled
//               back through A^-1, unnormalised): the disk is { x : row2 . (x - m) = 0, y0^2 + y1^2 <= 9 }.
// (A = linear part of the object-to-world matrix, so any affine object transform is exact.)
#pragma once

#include <cstdint>
#include <vector>

#include <embree3/rtcore.h>
#include <glm/glm.hpp>

#include "raysplats/gaussian_cloud.h"
#include "raysplats/render/scene.h"
#include "raysplats/render/transform.h"

namespace raysplats {

constexpr float kGaussianSupportSq = 9.0f;          // Mahalanobis radius 3
constexpr float kMinAlpha = 1.0f / 255.0f;          // DESIGN §6: hits below this are skipped
constexpr float kMaxAlpha = 0.99f;                  // DESIGN §6: alpha clamp

struct alignas(16) GaussianPrimitive {
    glm::vec3 center;
    float opacity;
    glm::vec3 row0;
    std::uint32_t cloud_index;  // the Gaussian's index in its cloud: keys the stochastic draw (independent of order)
    glm::vec3 row1;
    float pad1;
    glm::vec3 row2;
    float pad2;
};
static_assert(sizeof(GaussianPrimitive) == 64, "one cache line per Gaussian");

// Exact ray test. On success returns true with the hit distance t (ray parameter, any sign) and the squared
// Mahalanobis distance of the evaluation point (at the plane hit for flat, at the maximum response along the
// ray for volumetric). Written for float, no branches beyond the support test.
inline bool intersect_gaussian(const GaussianPrimitive& g, bool flat, const glm::vec3& o, const glm::vec3& d,
                               float& t, float& dist2) {
    const glm::vec3 p = o - g.center;
    if (flat) {
        const float denom = glm::dot(g.row2, d);
        if (denom == 0.0f) return false;
        t = -glm::dot(g.row2, p) / denom;
        const glm::vec3 q = p + t * d;
        const float u = glm::dot(g.row0, q), v = glm::dot(g.row1, q);
        dist2 = u * u + v * v;
    } else {
        const glm::vec3 po(glm::dot(g.row0, p), glm::dot(g.row1, p), glm::dot(g.row2, p));
        const glm::vec3 dd(glm::dot(g.row0, d), glm::dot(g.row1, d), glm::dot(g.row2, d));
        const float d2 = glm::dot(dd, dd);
        if (d2 == 0.0f) return false;
        t = -glm::dot(po, dd) / d2;
        const glm::vec3 q = po + t * dd;
        dist2 = glm::dot(q, q);
    }
    return dist2 <= kGaussianSupportSq;
}

// One Gaussian cloud in the scene. Primitives are in the cloud's own (object) frame and split into chunks of
// consecutive primitives; each chunk is an Embree sub-scene instanced with the object-to-world matrix. So moving
// the object only changes instance transforms, and an edit rebuilds only the chunks whose Gaussians changed
// (Scene::update_gaussians). Rays reach the callbacks in object space (Embree keeps the ray parameter t).
struct GaussianSet;
struct GaussianChunk {
    const GaussianSet* set = nullptr;
    std::uint32_t offset = 0, count = 0;  // primitives [offset, offset + count) of the set
    RTCScene scene = nullptr;
    RTCGeometry geometry = nullptr;        // the user geometry inside `scene` (owned by it)
    unsigned instance_id = RTC_INVALID_GEOMETRY_ID;  // geomID of the instance in the top-level scene
};

struct GaussianSet {
    std::uint32_t index = 0;  // in the scene
    const GaussianCloud* cloud = nullptr;
    Matrix4 object_to_world;
    glm::mat3 linear{1.0f};               // A
    glm::vec3 translation{0.0f};          // b
    glm::mat3 world_to_object_dir{1.0f};  // A^-1: world points and view directions into the cloud's frame
    glm::mat3 normal_matrix{1.0f};        // A^-T: object-space plane normals to world
    bool flat = true;
    // Primitives are stored in Morton order of their centres (primID = position in this order), so that
    // Gaussians that are close in space, and therefore visited together by a traversal, share cache lines and
    // chunks are compact in space.
    std::vector<GaussianPrimitive> prims;
    std::vector<std::uint32_t> cloud_index;  // primID -> index in the cloud
    std::vector<std::uint32_t> prim_index;   // index in the cloud -> primID (the inverse permutation)
    std::vector<float> linear_rgb;        // degree 0: colour (linear) precomputed per primitive
    std::vector<GaussianChunk> chunks;
    std::uint32_t chunk_size = 0xffffffffu;  // primitives per chunk (the last may have fewer)
    // What changed since the last build: only the transform (instance transforms rewritten), some Gaussians of the
    // cloud (`changed_rows`: only their primitives are recomputed), or new data (every primitive recomputed). In
    // the last two cases the chunks whose primitives changed are rebuilt.
    enum class Dirty { None, Transform, Rows, Data } dirty = Dirty::None;
    std::vector<std::uint32_t> changed_rows;  // cloud indices, when dirty == Rows

    void set_transform(const Matrix4& m);
    // Computes prims (and colours) for the mode, in parallel. `keep_order`: reuse cloud_index (same count as
    // before), so that primitive i is the same Gaussian and unchanged chunks stay valid; returns a flag per chunk
    // (of the current chunking) that is set when one of its primitives changed.
    std::vector<char> prepare(GaussianMode mode, bool keep_order);
    // Recomputes the primitives of the given Gaussians (cloud indices) only, in the current mode and order; returns
    // the chunk flags as prepare() does.
    std::vector<char> prepare_rows(const std::vector<std::uint32_t>& rows);
    // linear_rgb of primitive j from the degree-0 SH of its Gaussian.
    void store_linear_rgb(std::uint32_t j);
    glm::vec3 world_center(std::uint32_t i) const { return linear * prims[i].center + translation; }
    // Linear colour of primitive i seen from `origin` (world).
    glm::vec3 color(std::uint32_t i, const glm::vec3& origin) const;
    // World-space unit normal of a flat primitive.
    glm::vec3 world_normal(std::uint32_t i) const { return glm::normalize(normal_matrix * prims[i].row2); }
    // Creates the Embree user geometry of a chunk (bounds + intersect + occluded callbacks).
    RTCGeometry create_geometry(RTCDevice device, GaussianChunk& chunk) const;
};

// What a traversal collects from Gaussians; the context passed to rtcIntersect1/rtcOccluded1 extends
// RTCIntersectContext (the Embree tutorials' pattern for extra per-ray data).
enum class TraceMode : std::uint32_t {
    Gather,        // sorted: keep the k nearest hits in `gather`
    Stochastic,    // accept each with probability alpha, report the nearest accepted as an Embree hit
    Transmittance, // occlusion query: multiply `transmittance` by (1 - alpha) of every Gaussian on the segment
    MeshesOnly,    // Gaussians are ignored
};

struct GatherHit {
    float t;
    float alpha;
    std::uint32_t geom;
    std::uint32_t prim;
};

constexpr int kGatherCapacity = 128;  // upper bound of RenderSettings::gather_buffer_size

// Per-ray state of a traversal.
struct LaneState {
    // Gather: hits strictly after (after_t, after_key) in (t, key) order, key = geom << 32 | prim.
    float after_t = -1e30f;
    std::uint64_t after_key = 0;
    bool has_after = false;
    int count = 0;
    int capacity = 48;  // k, <= kGatherCapacity
    GatherHit hits[kGatherCapacity];
    // product = prod over the buffer of (1 - alpha), order-independent, kept incrementally. When
    // base_transmittance * product drops below the threshold, the buffer is scanned for the first i where
    // base * prod_{j <= i} (1 - alpha_j) does: the true transmittance there is lower still (unseen hits can only
    // lower it), so everything behind hits[i] is irrelevant: the buffer is cut there and tfar shrinks to hits[i].t.
    // Exact, and it bounds the traversal depth like an opaque hit would.
    float product = 1.0f;
    float base_transmittance = 1.0f;
    // Stochastic: random seed of this ray.
    std::uint32_t seed = 0;
    // Statistics: Gaussian callbacks (bounding-box candidates) during the traversal.
    std::uint64_t candidates = 0;
    // Transmittance (shadow rays) and the compositing threshold.
    float transmittance = 1.0f;
    float transmittance_threshold = 0.0f;
};

// The context handed to rtcIntersect1/16 and rtcOccluded1 (the Embree tutorials' way to carry per-ray data):
// lane i of a ray packet uses lanes[i]; single rays use lanes[0].
struct TraceContext : RTCIntersectContext {
    TraceMode mode = TraceMode::Gather;
    LaneState* lanes;
    TraceContext(LaneState* lane_array, TraceMode m) : mode(m), lanes(lane_array) { rtcInitIntersectContext(this); }
};

inline std::uint64_t gather_key(std::uint32_t geom, std::uint32_t prim) { return (std::uint64_t(geom) << 32) | prim; }

}  // namespace raysplats
