// Gaussian primitives and their grouping into Embree primitives (internal); the callbacks that test rays against
// them are in gaussian_callbacks.h. Each Gaussian is stored as its centre and three world-space
// rows that map a world offset x - m to canonical coordinates:
//   volumetric: y = S^-1 R^T A^-1 (x - m), G = exp(-|y|^2 / 2), the ellipsoid of Mahalanobis radius 3 is |y| <= 3;
//   flat:       rows 0 and 1 as above (the two largest axes), row 2 the plane normal (R's smallest axis pulled
//               back through A^-1, unnormalised): the disk is { x : row2 . (x - m) = 0, y0^2 + y1^2 <= 9 }.
// (A = linear part of the object-to-world matrix, so any affine object transform is exact.)
#pragma once

#include <cstdint>
#include <optional>
#include <vector>

#include <embree3/rtcore.h>
#include <glm/glm.hpp>

#include "motion_vectors.h"
#include "raysplats/default_init_allocator.h"
#include "raysplats/gaussian_cloud.h"
#include "raysplats/render/cryptomatte.h"
#include "raysplats/render/scene.h"
#include "raysplats/render/transform.h"

namespace raysplats {

constexpr float kGaussianSupportSq = 9.0f;          // Mahalanobis radius 3
constexpr float kMinAlpha = 1.0f / 255.0f;          // docs/design.md §6: hits below this are skipped
constexpr float kMaxAlpha = 0.99f;                  // docs/design.md §6: alpha clamp

struct alignas(16) GaussianPrimitive {
    glm::vec3 center;
    float opacity;
    glm::vec3 row0;
    std::uint32_t cloud_index;  // the Gaussian's index in its cloud: keys the stochastic draw (independent of order)
    glm::vec3 row1;
    // The Gaussian's smallest scale, at least 1e-6 of its largest: the length of the axis a flat primitive's row 2
    // leaves out, which camera-ray splatting's footprint puts back (kept here, in the primitives' order, so that the
    // projection does not read the cloud's scales in its own order).
    float thin_scale;
    glm::vec3 row2;
    // Squared Mahalanobis radius within which the Gaussian can reach alpha 1/255 (GaussianGroup::support; not positive
    // when it never does): computed once here, where the box and the group read it.
    float support_sq;
};
static_assert(sizeof(GaussianPrimitive) == 64, "one cache line per Gaussian");

// Embree primitives: groups of up to kGroupWidth Gaussians that are consecutive in the set's (Morton) order, stored
// SoA so that the intersect callback tests a ray against the whole group with SIMD (like Embree's own Triangle4
// leaves). One Embree user primitive per Gaussian made Embree's per-primitive callback overhead and scattered 64-byte
// loads a large part of a frame; a group is one callback and one contiguous block of data. The Embree bound of a
// group is the union of its Gaussians' boxes; GaussianSet::build_groups keeps groups tight (see there). Each
// Gaussian keeps its identity: hits carry its chunk-local index (first + lane) as primID. Lanes >= count are
// padding (zero rows and opacity: never a hit). Derived from GaussianSet::prims, which stays the source of truth.
// Groups make frames and the BVH build faster, with the same images (bench_render; docs/benchmarks.md).
constexpr int kGroupWidth = 8;
// The fields the ray test reads are the first 13 rows of N floats, field f of lane h at [f * N + h]: the centre's
// axes (0-2), the rows (3-11), the support (12).
template <int N>
struct alignas(32) GaussianLanes {
    float center[3][N];  // [axis][lane]
    float row[9][N];     // [3 * row + axis][lane]: rows 0..2 of GaussianPrimitive
    // Squared Mahalanobis radius within which the Gaussian can reach alpha 1/255 (at most 9): lanes beyond it are
    // rejected by the SIMD test, before any exp (0 for padding lanes).
    float support[N];
    float opacity[N];
    std::uint32_t cloud_index[N];  // GaussianPrimitive::cloud_index (the stochastic draw's key)
    // (No default member initialisers: the groups are allocated without being written, so that build_groups' parallel
    // fill is the first touch of their pages; a value-initialised group is still all zeros.)
    std::uint32_t first;           // chunk-local index of lane 0
    std::uint32_t count;           // Gaussians in the group, lanes [0, count)
    const float* fields() const { return &center[0][0]; }
};
using GaussianGroup = GaussianLanes<kGroupWidth>;
using GaussianQuad = GaussianLanes<4>;
// A group of one Gaussian: the same fields, one lane, in one cache line (no room for the count, which is 1).
template <>
struct alignas(64) GaussianLanes<1> {
    float center[3][1];
    float row[9][1];
    float support[1];
    float opacity[1];
    std::uint32_t cloud_index[1];
    std::uint32_t first;
    static constexpr std::uint32_t count = 1;
    const float* fields() const { return &center[0][0]; }
};
using GaussianSingle = GaussianLanes<1>;
static_assert(sizeof(GaussianSingle) == 64, "one cache line");

// A chunk's groups, each stored in the narrowest of three widths that holds it: most groups of a real scene hold one
// Gaussian or a few, and eight lanes for each made the groups a scene's largest array (docs/benchmarks.md has the
// figures). The primIDs stay the groups' order (the BVH and the order in which a ray meets the Gaussians do not depend
// on the widths); a primID is found in its width's array by rank: per 64 primIDs, the masks of the wide and the
// four-lane groups among them and the number of each before them.
class GaussianGroups {
public:
    enum class Width : std::uint8_t { One, Four, Eight };
    struct Location {
        Width width;
        std::uint32_t index;  // in singles, quads or wide
    };
    std::size_t size() const { return size_; }
    Location locate(std::uint32_t prim) const {
        const Block& b = blocks_[prim >> 6];
        const unsigned bit = prim & 63u;
        const std::uint64_t below = (std::uint64_t(1) << bit) - 1;
        const auto wide_below = std::uint32_t(__builtin_popcountll(b.wide & below));
        const auto quads_below = std::uint32_t(__builtin_popcountll(b.quads & below));
        if (b.wide >> bit & 1u) return {Width::Eight, b.wide_before + wide_below};
        if (b.quads >> bit & 1u) return {Width::Four, b.quads_before + quads_below};
        return {Width::One, prim - b.wide_before - b.quads_before - wide_below - quads_below};
    }
    // Makes room for groups of the given widths, in primID order (the arrays allocated unwritten; fill them after).
    void assign(const std::vector<Width>& widths);

    std::vector<GaussianSingle, DefaultInitAllocator<GaussianSingle>> singles;
    std::vector<GaussianQuad, DefaultInitAllocator<GaussianQuad>> quads;
    std::vector<GaussianGroup, DefaultInitAllocator<GaussianGroup>> wide;

private:
    struct Block {
        std::uint64_t wide = 0, quads = 0;  // bit i: primID 64 k + i is of that width
        std::uint32_t wide_before = 0, quads_before = 0;  // of that width in the blocks before
    };
    std::vector<Block> blocks_;
    std::size_t size_ = 0;
};

// Deformation blur (Scene::set_gaussians_deformation): a group's lanes (the same Gaussians as its GaussianGroup) at
// one time step, from which GaussianSet::deformed_group makes the group a ray of some time is tested against. Lanes
// >= the group's count are zero.
struct alignas(32) DeformedLanes {
    float center[3][kGroupWidth];       // [axis][lane]
    float rotation[4][kGroupWidth];     // unit quaternion (w, x, y, z), sign-aligned with the previous step's
    float scale[3][kGroupWidth];        // the standard deviation along the axis of row r of the primitive
    std::uint8_t axis[3][kGroupWidth];  // which column of the rotation row r takes (the first step's order of scales)
};

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
    GaussianGroups groups;                 // the geometry's primitives (build_groups)
    std::vector<RTCBounds> group_bounds;   // their Embree bounds
    // With the set's deformation (GaussianSet::deformation): the groups' lanes and their Embree bounds at each time
    // step, [step * groups.size() + group]; empty without.
    std::vector<DeformedLanes> deformed;
    std::vector<RTCBounds> deformed_bounds;
    unsigned instance_id = RTC_INVALID_GEOMETRY_ID;  // geomID of the instance in the top-level scene
};

struct GaussianSet {
    std::uint32_t index = 0;  // in the scene
    const GaussianCloud* cloud = nullptr;
    Matrix4 object_to_world;
    std::vector<Matrix4> motion;          // Scene::set_gaussians_motion's matrices (empty: none)
    // Scene::set_gaussians_deformation's Gaussians (in cloud order) at `steps` equally spaced times across the
    // shutter, step after step: centres, unit quaternions and scales, each step's axes in the order and signs nearest
    // the previous step's (one Gaussian may be given with its axes named differently at two steps).
    struct Deformation {
        std::size_t steps = 0;  // 0: none
        std::vector<float> positions, rotations, scales;
    } deformation;
    FrameMotion frame_motion;             // Scene::set_gaussians_frame_motion's (the Vector pass)
    glm::mat3 linear{1.0f};               // A
    glm::vec3 translation{0.0f};          // b
    glm::mat3 world_to_object_dir{1.0f};  // A^-1: world points and view directions into the cloud's frame
    glm::mat3 normal_matrix{1.0f};        // A^-T: object-space plane normals to world
    bool flat = true;
    std::optional<GaussianShading> shading;  // Scene::set_gaussian_shading: none follows the render settings
    std::uint32_t object_pass_index = 0, material_pass_index = 0;  // Scene::set_gaussian_pass_indices
    CryptomatteIds cryptomatte_ids{};  // Scene::set_gaussian_cryptomatte_names
    bool holdout = false;                                           // Scene::set_gaussian_holdout
    // Primitives are stored in Morton order of their centres (primID = position in this order), so that
    // Gaussians that are close in space, and therefore visited together by a traversal, share cache lines and
    // chunks are compact in space.
    std::vector<GaussianPrimitive, DefaultInitAllocator<GaussianPrimitive>> prims;  // (written by prepare, in parallel)
    std::vector<std::uint32_t> cloud_index;  // primID -> index in the cloud
    std::vector<std::uint32_t> prim_index;   // index in the cloud -> primID (the inverse permutation)
    std::vector<float> linear_rgb;        // degree 0: colour (linear) precomputed per primitive
    std::vector<float> display_rgb;       // degree 0: its display value (0.5 + SH_C0 f_dc, clamped at 0)
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
    // linear_rgb and display_rgb of primitive j from the degree-0 SH of its Gaussian, cloud index i.
    void store_linear_rgb(std::uint32_t j, std::size_t i);
    glm::vec3 world_center(std::uint32_t i) const { return linear * prims[i].center + translation; }
    // Linear colour of primitive i seen from `origin` (world).
    glm::vec3 color(std::uint32_t i, const glm::vec3& origin) const;
    // Its display (sRGB) colour, as SH give it (clamped at 0, not above 1): what BlendSpace::Display composites.
    glm::vec3 display_color(std::uint32_t i, const glm::vec3& origin) const;
    // World-space unit normal of a flat primitive.
    glm::vec3 world_normal(std::uint32_t i) const { return glm::normalize(normal_matrix * prims[i].row2); }
    // After prepare() changed the chunk's primitives: regroups them and commits the geometry (its BVH is rebuilt
    // when the chunk's scene is committed).
    void update_geometry(GaussianChunk& chunk) const;
    // Groups the chunk's primitives (GaussianGroups: each group in the fewest lanes that hold it, all eight with
    // deformation) and computes their bounds.
    void build_groups(GaussianChunk& chunk) const;
    // After build_groups: the chunk's DeformedLanes and bounds at each step of `deformation` (cleared without).
    void build_deformation(GaussianChunk& chunk) const;
    // Group `group` of a chunk with deformation as a ray of shutter time `time` sees it (its Gaussians interpolated
    // between the two steps around `time`), written to `out`.
    void deformed_group(const GaussianChunk& chunk, std::uint32_t group, float time, GaussianGroup& out) const;
};

}  // namespace raysplats
