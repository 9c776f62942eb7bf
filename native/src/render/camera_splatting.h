// Camera-ray splatting (internal; RenderSettings::camera_ray_splatting): the Gaussians a perspective camera's rays
// see in front of their first mesh hit are drawn as splat viewers draw them, not traced. Ray tracing draws each
// Gaussian by its exact 3D response along the ray, in per-ray order; viewers draw the EWA footprint in centre-depth
// order, and on scenes of Gaussians that are large for their distance or thin and seen obliquely the two differ by
// more than the training's noise (native/tests/reference/test_viewer_agreement.py measures it).
//
// The model, that of the 3DGS rasterizer (Kerbl et al. 2023, §4 and §6; its CUDA forward.cu, computeCov2D and
// renderCUDA):
//   centre m (world), view-space p = W (m - o), view depth z;  pixel (u, v) = the camera's projection of p;
//   2D covariance  Sigma' = J W A Sigma A^T W^T J^T + 0.3 I  (px^2), Sigma the Gaussian's 3D covariance in either
//   Gaussian mode (flat mode traces disks, but a viewer draws the whole Gaussian), J the perspective Jacobian at p, its x/z and
//   y/z clamped to 1.3 times the frustum's half extent about its centre (forward.cu: 1.3 tan(fov / 2));
//   alpha(x) = min(0.99, a exp(-1/2 d^T Sigma'^-1 d)), d = x - (u, v), skipped below 1/255, evaluated at each camera
//   sample's own (jittered) position; cut outside the square of half side 3 sqrt(lambda_max(Sigma'));
//   every camera sample composites the same list, sorted by (z, Gaussian) once per frame, front to back, C += T alpha c,
//   T *= 1 - alpha, stopping once T < transmittance_threshold; c is the Gaussian's SH colour in the direction camera
//   -> centre, in the render's blend space (display values by default).
// Gaussians whose centre is nearer than the camera's clip start or beyond its clip end are culled (the rasterizer's
// near cut), as are those whose opacity never reaches 1/255. Behind the splats the camera ray goes on as a traced ray
// does: its first mesh hit (found with a meshes-only traversal) bounds the list by view depth, is shaded by the path
// integrator and weighted by the transmittance left (the world without a mesh hit), exactly as a traced segment's.
//
// The pre-pass, as the 3DGS tile rasterizer: every Gaussian projected in parallel, the visible ones sorted by depth,
// binned into 16 x 16 pixel screen tiles (a tile's list is the ranks, in that sort, of the Gaussians that can reach
// alpha 1/255 in it: the square, intersected with the ellipse where a exp(-q / 2) >= 1/255; 4 bytes an entry), each
// list in depth order. Memory: 52 bytes a Gaussian in view and 4 a tile entry (showroom_1.5M seen whole at
// 1920 x 1080: 1.14 M splats, 4.1 M entries, 76 MB), for the render's duration. A camera sample reads the list of the
// tile under its
// position; the 16 samples of a 4 x 4 packet of camera rays mostly share a tile (the grid is aligned to the packets),
// and read its list once, together. The tile grid covers the render region widened by the pixel filter's reach, so
// jittered samples always find their tile.
//
// Applies when the camera is perspective and every Gaussian cloud is BAKED (effective shading): LIT and
// BAKED_SHADOWED Gaussians are shaded per hit point along the ray and cannot join a screen-space list, so a scene
// holding any keeps every camera ray traced (CameraSplatting::applies). Secondary rays (reflections, refraction,
// shadows, a camera ray continuing through a semi-transparent mesh) are always traced, and so is a camera ray that
// meets an area light in front of its mesh hit (or with none): the path integrator traces the part in front of the
// light again, as it does for a traced first segment (PathIntegrator::trace_with_lights).
#pragma once

#include <atomic>
#include <cstdint>
#include <vector>

#include <glm/glm.hpp>

#include "gaussian_segment_tracer.h"
#include "ray.h"
#include "raysplats/render/camera.h"
#include "raysplats/render/render_settings.h"
#include "render_math.h"
#include "scene_impl.h"
#include "shadow_visibility.h"

namespace raysplats {

// One Gaussian as the camera sees it, in depth order: what every camera sample reads (32 bytes, two to a cache line)...
struct ProjectedSplat {
    float u, v;            // image position of the centre, pixels (x right, y down from the top-left corner)
    float conic[3];        // Sigma'^-1 = [[conic0, conic1], [conic1, conic2]], 1 / px^2
    float opacity;
    float depth;           // view depth of the centre (along the camera's -Z axis, camera-space units)
    float half_extent;     // half side of its square, pixels: 3 sqrt(lambda_max(Sigma'))
};
// ... and what only the samples it covers read.
struct SplatShade {
    glm::vec3 color;          // in the render's blend space
    std::uint32_t set, prim;  // its GaussianSet and primitive (normal, centre, meshes_shadow_gaussians)
};

class CameraSplatting {
public:
    // Whether camera-ray splatting renders this frame's camera rays (the setting on, a perspective camera, every
    // Gaussian cloud BAKED).
    static bool applies(const Scene::Impl& scene, const RenderSettings& settings, const Camera& camera,
                        const GaussianShader& shader);

    // The pre-pass. Returns early, incomplete, once `cancel` is set (the render loop then renders nothing).
    CameraSplatting(const Scene::Impl& scene, const RenderSettings& settings, const Camera& camera,
                    const ShadowVisibility& shadow, const std::atomic<bool>* cancel);

    // First segments of up to 16 camera rays (lanes where `active` is set) whose samples lie at image positions
    // (xs, ys): the splats in front of each ray's first mesh hit, then that hit (as GaussianSegmentTracer's).
    void trace_packet(const Ray* rays, const bool* active, const float* xs, const float* ys, Sampler* rngs,
                      Segment* segs, Counters& c) const;

    std::size_t splat_count() const { return splats_.size(); }
    std::size_t tile_entry_count() const { return entries_.size(); }
    // Bytes held by the splats and tile lists.
    std::size_t memory_bytes() const;

    static constexpr int kTileSize = 16;  // pixels, as the 3DGS rasterizer's BLOCK_X x BLOCK_Y

private:
    // Composites onto the segments of the lanes in `lanes` (a mask), whose samples all lie in tile `tile`, the
    // tile's splats in front of each lane's `mesh_depth` (view depth): the list is read once for all of them.
    void composite(std::size_t tile, std::uint32_t lanes, const Ray* rays, const float* xs, const float* ys,
                   const float* mesh_depth, Sampler* rngs, Segment* segs, Counters& c) const;
    std::size_t tile_of(float x, float y) const;
    float view_depth(const glm::vec3& world_point) const;

    const Scene::Impl& s_;
    const RenderSettings& st_;
    const ShadowVisibility& shadow_;
    // World to camera space (the camera's inverse matrix: camera looks down -Z) and the projection to pixels:
    // x = cx + fx X / z, y = cy - fy Y / z, z = -Z.
    glm::mat3 world_to_camera_{1.0f};
    glm::vec3 camera_origin_{0.0f};
    float fx_ = 1.0f, fy_ = 1.0f, cx_ = 0.0f, cy_ = 0.0f;
    // The tile grid: tiles_x_ x tiles_y_ tiles of kTileSize pixels from (grid_x0_, grid_y0_).
    int grid_x0_ = 0, grid_y0_ = 0, tiles_x_ = 0, tiles_y_ = 0;
    std::vector<ProjectedSplat> splats_;    // visible Gaussians in (depth, set, prim) order
    std::vector<SplatShade> shades_;        // theirs, in the same order
    std::vector<std::uint64_t> offsets_;    // tile t's entries are entries_[offsets_[t] .. offsets_[t + 1])
    std::vector<std::uint32_t> entries_;    // indices into splats_, ascending (= front to back) within a tile
};

}  // namespace raysplats
