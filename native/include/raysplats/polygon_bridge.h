// The editing bridge of docs/design.md §5: every Gaussian becomes one flat K-gon in a Blender mesh, and any polygon
// the user leaves behind becomes a Gaussian again, by moments.
//
//   v_k = m + rho_i (s1 cos θ_k a1 + s2 sin θ_k a2),  θ_k = 2πk/K             (import)
//   m = (1/K) Σ v_k,  C = (1/K) Σ (v_k - m)(v_k - m)^T = (rho_i²/2)(s1² a1a1^T + s2² a2a2^T)
//   eigen(C): λ1 >= λ2 >= λ3  ->  s1 = sqrt(2 λ1)/rho_i, s2 = sqrt(2 λ2)/rho_i      (recovery)
//
// rho_i is the face's own radius (docs/design.md §5, "Opacity-aware radius"): the polygon spans only where the Gaussian
// is visible, rho_i = min(rho, sqrt(2 ln(255 a_i))), stored per face; Gaussians with a_i < 1/255 get no face.
// The recovery is exact under any affine map of the polygon (for every rho_i), so object transforms, modifiers,
// lattices and armatures all move Gaussians correctly. Colour SH are kept in each face's local frame F = [e1, e2, n]
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
    float radius = 3.0f;           // rho, Mahalanobis radius of the polygon's ellipse (the largest rho_i)
    void validate() const;         // throws InvalidArgument
};

// The least opacity that shows on an 8-bit display: the cut-off of REdiSplats' opacity-aware radius, and the alpha
// below which the reference 3DGS rasteriser skips a Gaussian.
constexpr double kVisibleOpacity = 1.0 / 255.0;

// rho_i of docs/design.md §5: how far (in Mahalanobis radius) a Gaussian of opacity a is visible, at most rho:
//   a·exp(-r²/2) >= 1/255  <=>  r <= sqrt(2 ln(255 a)),    rho_i = min(rho, sqrt(2 ln(255 a)))
// computed in double and rounded once to float, so rho_i == rho bit for bit when the cap applies (a >= 0.353 at
// rho = 3). 0 when nothing is visible: a < 1/255 (no float equals 1/255 exactly), a NaN.
float visible_polygon_radius(float opacity, float rho);

// A mesh of independent K-gons, in the array layout Blender's foreach_set takes: one face per visible Gaussian
// (visible_polygon_radius > 0), in the order of the cloud.
struct SplatPolygons {
    std::vector<float> vertex_positions;      // 3 per vertex, K vertices per Gaussian
    std::vector<std::int32_t> corner_vertices;  // one per corner (= per vertex here)
    std::vector<std::int32_t> face_corner_start;  // per face
    std::vector<std::int32_t> face_corner_count;  // per face (= K)
    std::vector<std::int32_t> edge_vertices;   // 2 per edge, K edges per face
    std::vector<std::int32_t> corner_edges;    // one per corner: edge from this corner to the next
    std::vector<float> thickness;              // per face: gaussian_thickness of its scales
    int sh_degree = 0;                         // of sh_local (the cloud's)
    std::vector<float> sh_local;               // per face, [k][rgb], SH in the face's local frame
    // 4 bytes per corner, a byte colour attribute: the SH DC colour's sRGB bytes (linear RGB to 8 bits where read as
    // Blender does), A = opacity x 255 rounded.
    std::vector<std::uint8_t> corner_colors;
    std::vector<float> corner_uvs;             // 2 per corner: (rho_i cos θ_k, rho_i sin θ_k)
    // The face's own Gaussian, as SplatFaceAttributesView reads it back (the cloud's rows of the faces' Gaussians).
    std::vector<float> polygon_radius;         // per face: rho_i = visible_polygon_radius(opacity, rho)
    std::vector<float> opacity;                // per face
    std::vector<float> rest_centers;           // 3 per face
    std::vector<float> rest_rotations;         // 4 per face, w x y z
    std::vector<float> rest_scales;            // 3 per face
    std::size_t invisible_skipped = 0;         // Gaussians with opacity below 1/255: no face
};

SplatPolygons gaussians_to_polygons(const GaussianCloud& cloud, const PolygonSettings& settings);

// The thickness a face keeps of its Gaussian (which its flat polygon drops): s3 / sqrt(s1 s2) of the scales sorted
// descending, 0 for a degenerate plane.
float gaussian_thickness(const float scales[3]);

// The K polygon vertices of one Gaussian (float32, as stored in Blender) at radius settings.radius (pass rho_i).
// Recovery regenerates polygons the same way to recognise unedited faces bit for bit.
void gaussian_polygon(const float center[3], const float rotation_wxyz[4], const float scales[3],
                      const PolygonSettings& settings, float* out_vertices);

// gaussian_polygon() of Gaussians [begin, end) of a cloud (bit-identical results, the angle table computed once):
// the K vertices of Gaussian i go to out + (i - begin) * stride (stride in floats, >= 3K), at radius
// polygon_radius[i] (finite, >= 0; 0 puts all K vertices on the centre) or, without polygon_radius,
// settings.radius. Single-threaded; callers split ranges across threads.
void gaussian_polygons(const GaussianCloud& cloud, std::size_t begin, std::size_t end, const PolygonSettings& settings,
                       float* out, std::size_t stride, const float* polygon_radius = nullptr);

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

// Per-face attributes stored on import; any pointer may be null (then defaults apply). attributes_view() gives those
// of polygons made by gaussians_to_polygons.
struct SplatFaceAttributesView {
    const float* opacity = nullptr;          // F
    // Null: each face's gaussian_thickness(rest_scales) (0 without rest scales): Blender imports store no
    // thickness, since it follows from the rest scales every imported face carries.
    const float* thickness = nullptr;        // F
    // rho_i of each face: recovery divides by it. A value that is not a positive finite number (0 is what Blender
    // gives faces the user adds), or no array (files from before per-face radii), means RecoveryOptions' rho.
    const float* polygon_radius = nullptr;   // F
    int sh_degree = 0;
    const float* sh_local = nullptr;         // F * (deg+1)^2 * 3
    // The Gaussian each face was made from (centre, rotation wxyz, scales). When a face's vertices are
    // bit-identical to gaussian_polygon() of these, the face is unedited and this exact Gaussian is used,
    // so an untouched scene exports exactly what it imported despite float32 vertex positions.
    // Zero rest scales (what Blender gives faces the user adds) mark a new face: it gets default attributes.
    const float* rest_centers = nullptr;     // F * 3
    const float* rest_rotations = nullptr;   // F * 4
    const float* rest_scales = nullptr;      // F * 3
    // Non-zero for faces whose corners a reflection reversed (faces_with_reversed_uvs() of the polygon UVs: Blender
    // flips a mirrored face by keeping its first corner and reversing the rest, so its UVs run clockwise). Their
    // local SH are reflected across the local y axis before they are rotated to the face, and across the local
    // normal when mesh_to_output reflects too; null: no face is reflected.
    const float* reflected = nullptr;        // F
};

// The face attributes of polygons made by gaussians_to_polygons, as an import stores them (for recovering from them
// without Blender, with mesh_view()). Valid while `polygons` lives.
SplatFaceAttributesView attributes_view(const SplatPolygons& polygons);

struct RecoveryOptions {
    PolygonSettings polygon;                // K and rho the object was imported with (rho: faces without rho_i)
    // Affine map from the mesh's coordinates to the output space (row-major 4x4, last row 0 0 0 1),
    // e.g. the object's world matrix followed by the axis conversion back to the file's convention.
    double mesh_to_output[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
};

struct RecoveryStats {
    std::size_t unedited = 0;     // faces that matched their imported Gaussian exactly
    std::size_t recovered = 0;    // faces recovered by moments
    std::size_t added = 0;        // faces without an imported Gaussian (default attributes)
    std::size_t degenerate = 0;   // collinear or coincident vertices: scales clamped
    std::size_t dropped = 0;      // faces with non-finite vertices or fewer than 3 corners, or whose Gaussian does
                                  // not fit float32 (corners far out, a tiny polygon radius): not exported
    // faces whose stored rest rotation is not a rotation (NaN, Inf or zero, e.g. written by a script): their
    // Gaussian is recovered from the polygon instead (also counted in `recovered`)
    std::size_t invalid_rest_rotation = 0;
    // faces whose stored rest scales are not scales (negative, NaN or Inf): recovered from the polygon likewise
    std::size_t invalid_rest_scale = 0;
};

// Recovers one Gaussian per face (in face order, dropped faces left out) in the output space of
// options.mesh_to_output, with world-space SH. Multi-threaded. With `faces`, only those faces are recovered (row o
// of the result is face faces[o], dropped faces again left out): a face's Gaussian depends on nothing but its own
// corners and attributes, so this equals the same rows of a full recovery, bit for bit (the viewport's edits).
GaussianCloud recover_gaussians_from_polygons(const PolygonMeshView& mesh, const SplatFaceAttributesView& attributes,
                                              const RecoveryOptions& options, RecoveryStats* stats = nullptr,
                                              const std::uint32_t* faces = nullptr, std::size_t faces_count = 0);

// 1 for faces whose polygon UVs (2 floats per corner, the corner UVs gaussians_to_polygons made, which run
// counter-clockwise) wind clockwise, i.e. whose corners a reflection reversed; else 0. Faces with fewer than 3
// corners or corners outside `corner_count` get 0. Multi-threaded.
std::vector<float> faces_with_reversed_uvs(const PolygonMeshView& mesh, const float* corner_uvs);

// rho_i of each face read back from its polygon UVs: gaussians_to_polygons puts the corner at angle 0 at exactly
// (rho_i, 0), so it is the u of the face's corner whose v is 0 and u positive (bit for bit what was stored); 0, which
// means RecoveryOptions' rho, where no corner is. Blender imports keep no per-face radius attribute: the
// UV map, which the material needs anyway, holds it. Multi-threaded.
std::vector<float> polygon_radius_from_uvs(const PolygonMeshView& mesh, const float* corner_uvs);

// The faces (ascending) with a corner on a vertex whose position differs, bit for bit, from previous_positions
// (3 floats per vertex, mesh.vertex_count of them: the same mesh before an edit that kept its topology).
// Multi-threaded.
std::vector<std::uint32_t> faces_with_moved_vertices(const PolygonMeshView& mesh, const float* previous_positions);

// The rows (ascending) in which two row-major float arrays of `rows` x `width` differ bit for bit (a per-face
// attribute before and after an edit). Multi-threaded.
std::vector<std::uint32_t> rows_that_differ(const float* previous, const float* current, std::size_t rows,
                                            std::size_t width);

}  // namespace raysplats
