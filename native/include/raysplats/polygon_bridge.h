// The editing bridge of DESIGN §5: every Gaussian becomes one flat K-gon in a Blender mesh, and any polygon
// the user leaves behind becomes a Gaussian again, by moments.
//
//   v_k = m + rho (s1 cos θ_k a1 + s2 sin θ_k a2),  θ_k = 2πk/K             (import)
//   m = (1/K) Σ v_k,  C = (1/K) Σ (v_k - m)(v_k - m)^T = (rho²/2)(s1² a1a1^T + s2² a2a2^T)
//   eigen(C): λ1 >= λ2 >= λ3  ->  s1 = sqrt(2 λ1)/rho, s2 = sqrt(2 λ2)/rho      (recovery)
//
// The recovery is exact under any affine map of the polygon, so object transforms, modifiers, lattices and
// armatures all move Gaussians correctly. Colour SH are kept in each face's local frame F = [e1, e2, n]
// (e1: centre -> vertex 0, n: the face normal by winding): SH_local = D(F^T) SH_world on import,
// SH_world = D(F_now) SH_local on recovery, so view-dependent colour follows the edit.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "raysplats/gaussian_cloud.h"

namespace raysplats {

constexpr int kMinPolygonVertices = 3;
constexpr int kMaxPolygonVertices = 64;
// Defaults for faces the user adds (no imported Gaussian behind them): an opaque grey flat splat.
constexpr float kNewFaceOpacity = 1.0f;
// Smallest scale a recovered Gaussian gets, relative to its largest and in absolute scene units.
constexpr double kMinRelativeScale = 1e-4;
constexpr double kMinAbsoluteScale = 1e-9;

struct PolygonSettings {
    int vertices_per_polygon = 8;  // K
    float radius = 3.0f;           // rho, Mahalanobis radius of the polygon's ellipse
    void validate() const;         // throws InvalidArgument
};

// A mesh of independent K-gons, in the array layout Blender's foreach_set takes.
struct SplatPolygons {
    std::vector<float> vertex_positions;      // 3 per vertex, K vertices per Gaussian
    std::vector<std::int32_t> corner_vertices;  // one per corner (= per vertex here)
    std::vector<std::int32_t> face_corner_start;  // per face
    std::vector<std::int32_t> face_corner_count;  // per face (= K)
    std::vector<std::int32_t> edge_vertices;   // 2 per edge, K edges per face
    std::vector<std::int32_t> corner_edges;    // one per corner: edge from this corner to the next
    std::vector<float> thickness;              // per face: s3 / sqrt(s1 s2), s sorted descending
    std::vector<float> sh_local;               // per face, [k][rgb], SH in the face's local frame
    std::vector<float> corner_colors;          // 4 per corner: linear RGB of the SH DC colour, A = opacity
    std::vector<float> corner_uvs;             // 2 per corner: (rho cos θ_k, rho sin θ_k)
};

SplatPolygons gaussians_to_polygons(const GaussianCloud& cloud, const PolygonSettings& settings);

// The K polygon vertices of one Gaussian (float32, as stored in Blender). Recovery regenerates polygons
// with this very function to recognise unedited faces bit for bit.
void gaussian_polygon(const float center[3], const float rotation_wxyz[4], const float scales[3],
                      const PolygonSettings& settings, float* out_vertices);

// gaussian_polygon() of Gaussians [begin, end) of a cloud (bit-identical results, the angle table computed once):
// the K vertices of Gaussian i go to out + (i - begin) * stride (stride in floats, >= 3K). Single-threaded;
// callers split ranges across threads.
void gaussian_polygons(const GaussianCloud& cloud, std::size_t begin, std::size_t end, const PolygonSettings& settings,
                       float* out, std::size_t stride);

// Blender mesh arrays of any polygon mesh (after modifiers), read with foreach_get.
struct PolygonMeshView {
    const float* vertex_positions = nullptr;  std::size_t vertex_count = 0;
    const std::int32_t* corner_vertices = nullptr;  std::size_t corner_count = 0;
    const std::int32_t* face_corner_start = nullptr;
    const std::int32_t* face_corner_count = nullptr;
    std::size_t face_count = 0;
};

// A view of polygons made by gaussians_to_polygons (for recovering from them without Blender).
PolygonMeshView mesh_view(const SplatPolygons& polygons);

// Per-face attributes stored on import; any pointer may be null (then defaults apply).
struct SplatFaceAttributesView {
    const float* opacity = nullptr;          // F
    const float* thickness = nullptr;        // F
    int sh_degree = 0;
    const float* sh_local = nullptr;         // F * (deg+1)^2 * 3
    // The Gaussian each face was made from (centre, rotation wxyz, scales). When a face's vertices are
    // bit-identical to gaussian_polygon() of these, the face is unedited and this exact Gaussian is used,
    // so an untouched scene exports exactly what it imported despite float32 vertex positions.
    // Zero rest scales (what Blender gives faces the user adds) mark a new face: it gets default attributes.
    const float* rest_centers = nullptr;     // F * 3
    const float* rest_rotations = nullptr;   // F * 4
    const float* rest_scales = nullptr;      // F * 3
};

struct RecoveryOptions {
    PolygonSettings polygon;                // K and rho the object was imported with
    // Affine map from the mesh's coordinates to the output space (row-major 4x4, last row 0 0 0 1),
    // e.g. the object's world matrix followed by the axis conversion back to the file's convention.
    double mesh_to_output[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
};

struct RecoveryStats {
    std::size_t unedited = 0;     // faces that matched their imported Gaussian exactly
    std::size_t recovered = 0;    // faces recovered by moments
    std::size_t added = 0;        // faces without an imported Gaussian (default attributes)
    std::size_t degenerate = 0;   // collinear or coincident vertices: scales clamped
    std::size_t dropped = 0;      // faces with non-finite vertices or fewer than 3 corners: not exported
};

// Recovers one Gaussian per face (in face order, dropped faces left out) in the output space of
// options.mesh_to_output, with world-space SH. Multi-threaded. With `faces`, only those faces are recovered (row o
// of the result is face faces[o], dropped faces again left out): a face's Gaussian depends on nothing but its own
// corners and attributes, so this equals the same rows of a full recovery, bit for bit (the viewport's edits).
GaussianCloud recover_gaussians_from_polygons(const PolygonMeshView& mesh, const SplatFaceAttributesView& attributes,
                                              const RecoveryOptions& options, RecoveryStats* stats = nullptr,
                                              const std::uint32_t* faces = nullptr, std::size_t faces_count = 0);

// The faces (ascending) with a corner on a vertex whose position differs, bit for bit, from previous_positions
// (3 floats per vertex, mesh.vertex_count of them: the same mesh before an edit that kept its topology).
// Multi-threaded.
std::vector<std::uint32_t> faces_with_moved_vertices(const PolygonMeshView& mesh, const float* previous_positions);

// The rows (ascending) in which two row-major float arrays of `rows` x `width` differ bit for bit (a per-face
// attribute before and after an edit). Multi-threaded.
std::vector<std::uint32_t> rows_that_differ(const float* previous, const float* current, std::size_t rows,
                                            std::size_t width);

}  // namespace raysplats
