// Camera-ray splatting's pre-pass (internal; camera_splatting.h has the model), as the 3DGS tile rasterizer: every
// Gaussian projected in parallel, the visible ones sorted by depth, binned into screen tiles (a tile's list is the
// ranks, in that sort, of the Gaussians that can reach alpha 1/255 in it: the square, intersected with the ellipse
// where a exp(-q / 2) >= 1/255; 4 bytes an entry), each list in depth order. Unlike the rasterizer's one level of
// 16 x 16 px tiles, there are two: splats whose square's half side is at most 4 px go into 4 x 4 px tiles, the bigger
// ones into 16 x 16 px tiles (the reason and figures at CameraSplatPrepass::bin's call). Memory: 56 bytes a Gaussian
// in view and 4 a tile entry, for the render's duration. A tile's lists hold every splat that a sample of its pixels
// can see wherever the pixel filter's jitter puts it (the tile widened by the filter's reach), so a 4 x 4 packet of
// camera rays (the grids are aligned to the packets) reads the lists of its own fine tile and of the coarse tile
// holding it once, for all 16 samples, merged by rank. The grids cover the render region widened by the filter's
// reach.
#pragma once

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

#include <glm/glm.hpp>

#include "camera_splat_buffers.h"
#include "raysplats/render/camera.h"
#include "raysplats/render/render_settings.h"
#include "scene_impl.h"

namespace raysplats {

// The ellipse d^T C d <= r of a splat's offsets d from its centre (C its conic, [[a, b], [b, c]], positive definite),
// and its extent within a horizontal band of offsets: a row of tiles meets the ellipse exactly where its columns meet
// that extent, so the binning finds a row's tiles from at most two square roots instead of testing each tile.
class SplatEllipse {
public:
    SplatEllipse(double a, double b, double c, double r);
    // The x extent [x0, x1] of the ellipse within y0 <= y <= y1; false when the band misses it. A conic that is not
    // positive definite (float rounding of a needle-thin splat) reaches the whole band.
    bool row_extent(double y0, double y1, double& x0, double& x1) const;

private:
    double b_, det_, inv_a_ = 0.0, ar_ = 0.0;
    double x_half_ = 0.0, y_half_ = 0.0;  // the ellipse's extent, |x| <= x_half_, |y| <= y_half_
    double y_at_right_ = 0.0;             // y of its rightmost point (its leftmost is (-x_half_, -y_at_right_))
    bool definite_ = false;
};

// (Defined here, inline: the binning calls them for every splat and row.)
inline SplatEllipse::SplatEllipse(double a, double b, double c, double r) : b_(b), det_(a * c - b * b) {
    definite_ = a > 0.0 && c > 0.0 && det_ > 0.0 && r >= 0.0 && std::isfinite(det_) && std::isfinite(r);
    if (!definite_) return;
    // At the extreme points the gradient 2 (C d) is along an axis: the rightmost point has b x + c y = 0, and
    // q = r there gives x = sqrt(r c / det); likewise |y| <= sqrt(r a / det).
    inv_a_ = 1.0 / a;
    ar_ = a * r;
    y_half_ = std::sqrt(r * a / det_);
    x_half_ = std::sqrt(r * c / det_);
    y_at_right_ = -b * x_half_ / c;
}

inline bool SplatEllipse::row_extent(double y0, double y1, double& x0, double& x1) const {
    if (!definite_) {
        x0 = -std::numeric_limits<double>::infinity();
        x1 = std::numeric_limits<double>::infinity();
        return y0 <= y1;
    }
    if (y0 > y1 || y0 > y_half_ || y1 < -y_half_) return false;
    // For a given y the ellipse spans x = (-b y -+ s(y)) / a, s(y) = sqrt(a r - det y^2). The right end is concave in
    // y and greatest at the rightmost point, the left end convex and least at the leftmost, so over the band each is
    // extreme at that point's y clamped into the band (the band holds both points of a small splat's row: no root).
    const double yr = std::clamp(y_at_right_, y0, y1), yl = std::clamp(-y_at_right_, y0, y1);
    const auto s = [&](double y) { return std::sqrt(std::max(0.0, ar_ - det_ * y * y)); };
    x1 = yr == y_at_right_ ? x_half_ : (-b_ * yr + s(yr)) * inv_a_;
    x0 = yl == -y_at_right_ ? -x_half_ : (-b_ * yl - s(yl)) * inv_a_;
    return true;
}

class CameraSplatPrepass {
public:
    // The pre-pass. Returns early, incomplete, once `cancel` is set (the render loop then renders nothing).
    CameraSplatPrepass(const Scene::Impl& scene, const RenderSettings& settings, const Camera& camera,
                       const std::atomic<bool>* cancel);

    static constexpr int kTileSize = 16;      // pixels, as the 3DGS rasterizer's BLOCK_X x BLOCK_Y
    static constexpr int kFineTileSize = 4;   // pixels: one 4 x 4 packet of camera rays
    // Splats whose square's half side is at most this (pixels) go into the fine lists, the others into the coarse.
    // (examples/benchmark_camera_splatting.py: 4 and 8 render as fast, 4 with fewer entries; 16 is slower.)
    static constexpr float kFineSplatMaxHalfExtent = 4.0f;

    // Gives the storage back to the scene when it keeps it for the next frame (Scene::set_keep_frame_buffers).
    ~CameraSplatPrepass();
    CameraSplatPrepass(const CameraSplatPrepass&) = delete;
    CameraSplatPrepass& operator=(const CameraSplatPrepass&) = delete;

    // The visible Gaussians in (depth, set, prim) order, and their sources in the same order.
    const SplatArray<ProjectedSplat>& splats() const { return b_.splats; }
    const SplatArray<SplatSource>& sources() const { return b_.sources; }
    // kTileSize tiles: the splats wider than kFineSplatMaxHalfExtent; kFineTileSize tiles, the packets' own: the
    // smaller ones.
    const SplatTileLists& coarse() const { return b_.coarse; }
    const SplatTileLists& fine() const { return b_.fine; }
    int grid_x0() const { return grid_x0_; }  // the tile grids' common corner, pixels
    int grid_y0() const { return grid_y0_; }
    // The view depth of a world point (along the camera's -Z axis).
    float view_depth(const glm::vec3& world_point) const;
    // Bytes held by the splats and tile lists.
    std::size_t memory_bytes() const { return b_.frame_bytes(); }

private:
    // The projection and the tile grids of the render region.
    void set_up_grids(const RenderSettings& settings);
    // Projects Gaussian `prim` of `set`, whose (W A)^T is `wa_t` (W: world to camera, A: the set's linear part): false
    // when it is culled (near, far, faint, degenerate, off the grid).
    bool project(const GaussianSet& set, const glm::mat3& wa_t, std::uint32_t prim, ProjectedSplat& out) const;
    // project() of primitives prim .. prim + 3 at once, bit for bit: returns the mask of the visible ones (out[lane]
    // written for those).
    unsigned project4(const GaussianSet& set, const glm::mat3& wa_t, std::uint32_t prim, ProjectedSplat* out) const;
    // Every Gaussian projected once, by global index (set_base[k] + j: primitive j of set k; the culled ones' entries
    // unwritten), the visible ones with their colours (`display`: in display values), and the visible Gaussians'
    // keys, depth above global index, sorted; false when cancelled.
    bool sorted_keys(const std::vector<std::size_t>& set_base, bool display, const std::atomic<bool>* cancel);
    // The splats and their sources in the keys' order; frees the keys and the projections unless the scene keeps
    // the storage.
    void gather(const std::vector<std::size_t>& set_base, const std::atomic<bool>* cancel);
    // The tiles of `lists` a splat's square, widened by the samples' pad, covers: columns tx0..tx1, rows ty0..ty1.
    struct TileSquare {
        int tx0, ty0, tx1, ty1;
        int width() const { return tx1 - tx0 + 1; }
        int count() const { return tx1 < tx0 || ty1 < ty0 ? 0 : width() * (ty1 - ty0 + 1); }
    };
    TileSquare tile_square(const SplatTileLists& lists, const ProjectedSplat& ps) const;
    // Calls visit(t, bit) for every tile t of `lists` where the splat can reach alpha 1/255; bit is the tile's place
    // in its square `sq` (tile_square), row by row ((ty - ty0) * width + tx - tx0).
    template <typename Visit>
    void for_each_tile(const SplatTileLists& lists, const ProjectedSplat& ps, const TileSquare& sq,
                       Visit&& visit) const;
    // Bins the splats of `level` into `lists` (sized already): only tiles the splat can reach alpha 1/255 in.
    void bin(SplatTileLists& lists, std::uint8_t which, const std::atomic<bool>* cancel);

    const Scene::Impl& s_;
    // World to camera space (the camera's inverse matrix: camera looks down -Z) and the projection to pixels:
    // x = cx + fx X / z, y = cy - fy Y / z, z = -Z.
    glm::mat3 world_to_camera_{1.0f};
    glm::vec3 camera_origin_{0.0f};
    CameraRayGenerator::PinholeProjection proj_{};
    float near_ = 0.0f, far_ = 0.0f;        // the camera's clip range, view depth
    float lim_x_ = 0.0f, lim_y_ = 0.0f;     // the Jacobian's clamp about the frustum's centre, in X / z and Y / z
    int grid_x0_ = 0, grid_y0_ = 0;         // the tile grids' common corner, pixels
    float grid_x1_ = 0.0f, grid_y1_ = 0.0f; // and their far corner
    float sample_pad_ = 0.0f;               // how far outside its pixel's square a sample can fall, pixels
    CameraSplatBuffers b_;  // taken from the scene when it keeps them, else empty
};

}  // namespace raysplats
