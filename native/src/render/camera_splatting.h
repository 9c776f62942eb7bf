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
// binned into screen tiles (a tile's list is the ranks, in that sort, of the Gaussians that can reach alpha 1/255 in
// it: the square, intersected with the ellipse where a exp(-q / 2) >= 1/255; 4 bytes an entry), each list in depth
// order. Unlike the rasterizer's one level of 16 x 16 px tiles, there are two: splats whose square's half side is at
// most 4 px go into 4 x 4 px tiles, the bigger ones into 16 x 16 px tiles (the reason and figures at
// CameraSplatting::bin's call). Memory: 56 bytes a Gaussian in view and 4 a tile entry, for the render's duration. A
// tile's lists hold every splat that a sample of its pixels can see wherever the pixel filter's jitter puts it (the
// tile widened by the filter's reach), so a 4 x 4 packet of camera rays (the grids are aligned to the packets) reads
// the lists of its own fine tile and of the coarse tile holding it once, for all 16 samples, merged by rank. The grids
// cover the render region widened by the filter's reach.
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

// One Gaussian as the camera sees it, in depth order: what every camera sample reads (48 bytes; the colour is here,
// not with the rest of what only the samples it covers read, because a second array meant a second cache miss)...
struct alignas(16) ProjectedSplat {
    float u, v;            // image position of the centre, pixels (x right, y down from the top-left corner)
    float conic[3];        // Sigma'^-1 = [[conic0, conic1], [conic1, conic2]], 1 / px^2
    float opacity;
    float depth;           // view depth of the centre (along the camera's -Z axis, camera-space units)
    float half_extent;     // half side of its square, pixels: 3 sqrt(lambda_max(Sigma'))
    glm::vec3 color;       // in the render's blend space
    // Below this exponent alpha is under 1/255: ln(1/255 / opacity), less a margin, so that the test skips the exp of
    // most samples it misses and never one whose alpha reaches 1/255 (which is then tested exactly).
    float least_power;
};
// ... and what only a sample it stops or makes opaque, or meshes_shadow_gaussians, reads.
struct SplatSource {
    std::uint32_t set, prim;  // its GaussianSet and primitive (normal, centre)
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

    // First segments of up to 16 camera rays (lanes where `active` is set) of the 4 x 4 pixels from (packet_x,
    // packet_y), lane l at pixel (packet_x + l % 4, packet_y + l / 4), whose samples lie at image positions (xs, ys):
    // the splats in front of each ray's first mesh hit, then that hit (as GaussianSegmentTracer's).
    void trace_packet(int packet_x, int packet_y, const Ray* rays, const bool* active, const float* xs,
                      const float* ys, Sampler* rngs, Segment* segs, Counters& c) const;

    std::size_t splat_count() const { return splats_.size(); }
    std::size_t tile_entry_count() const { return coarse_.entries.size() + fine_.entries.size(); }
    // Bytes held by the splats and tile lists.
    std::size_t memory_bytes() const;

    static constexpr int kTileSize = 16;      // pixels, as the 3DGS rasterizer's BLOCK_X x BLOCK_Y
    static constexpr int kFineTileSize = 4;   // pixels: one 4 x 4 packet of camera rays
    // Splats whose square's half side is at most this (pixels) go into the fine lists, the others into the coarse.
    // (examples/benchmark_camera_splatting.py: 4 and 8 render as fast, 4 with fewer entries; 16 is slower.)
    static constexpr float kFineSplatMaxHalfExtent = 4.0f;

private:
    // One level of tile lists: nx x ny square tiles of `size` pixels from the grid's corner (grid_x0_, grid_y0_);
    // tile t's splats are entries[offsets[t] .. offsets[t + 1]), indices into splats_, ascending (= front to back).
    struct TileLists {
        int size = 0, nx = 0, ny = 0;
        std::vector<std::uint64_t> offsets;
        std::vector<std::uint32_t> entries;
        std::size_t tile_of(float x, float y, int x0, int y0) const;
    };
    // Bins the splats of `level` into `lists` (sized already): only tiles the splat can reach alpha 1/255 in.
    void bin(TileLists& lists, const std::vector<std::uint8_t>& level, std::uint8_t which,
             const std::atomic<bool>* cancel);
    // Composites onto the segments of the lanes in `lanes` (a mask), whose samples all lie in fine tile `fine_tile`,
    // the splats of that fine tile's list and of its coarse tile's list, merged in depth order, in front of each
    // lane's `mesh_depth` (view depth): the lists are read once for all of them.
    void composite(std::size_t fine_tile, std::uint32_t lanes, const Ray* rays, const float* xs, const float* ys,
                   const float* mesh_depth, Sampler* rngs, Segment* segs, Counters& c) const;
    float view_depth(const glm::vec3& world_point) const;

    const Scene::Impl& s_;
    const RenderSettings& st_;
    const ShadowVisibility& shadow_;
    // World to camera space (the camera's inverse matrix: camera looks down -Z) and the projection to pixels:
    // x = cx + fx X / z, y = cy - fy Y / z, z = -Z.
    glm::mat3 world_to_camera_{1.0f};
    glm::vec3 camera_origin_{0.0f};
    float fx_ = 1.0f, fy_ = 1.0f, cx_ = 0.0f, cy_ = 0.0f;
    int grid_x0_ = 0, grid_y0_ = 0;         // the tile grids' common corner, pixels
    float sample_pad_ = 0.0f;               // how far outside its pixel's square a sample can fall, pixels
    std::vector<ProjectedSplat> splats_;    // visible Gaussians in (depth, set, prim) order
    std::vector<SplatSource> sources_;      // theirs, in the same order
    TileLists coarse_;                      // kTileSize tiles: splats wider than kFineSplatMaxHalfExtent
    TileLists fine_;                        // kFineTileSize tiles, the packets' own: the smaller splats
};

}  // namespace raysplats
