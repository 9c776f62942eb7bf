// The storage of camera-ray splatting's pre-pass (camera_splat_prepass.h has the model): the splats in depth order,
// their tile lists, and the pre-pass's working arrays. A scene that renders frame after frame (Persistent Data) keeps
// it between frames (Scene::set_keep_frame_buffers), so that the next pre-pass writes into pages already mapped
// instead of faulting in and zeroing hundreds of megabytes of fresh ones; every array is rewritten in full each
// frame, so what it held before changes nothing.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include <glm/glm.hpp>

#include "raysplats/default_init_allocator.h"

namespace raysplats {

// An array every element of which the pre-pass writes: resized without a zeroing pass.
template <typename T>
using SplatArray = std::vector<T, DefaultInitAllocator<T>>;

// Sizes an array that is then written in full. Grown, it keeps nothing of what it held (a resize would copy it all to
// the new memory, and a kept scene's next frame has a few more splats or entries than the last as often as not) and
// takes room for 1/16 more, so that the frames after do not grow it again.
template <typename T>
void size_for_overwrite(SplatArray<T>& a, std::size_t n) {
    if (n > a.capacity()) {
        a.clear();
        a.reserve(n + n / 16);
    }
    a.resize(n);
}

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

// One level of tile lists: nx x ny square tiles of `size` pixels from the grids' corner; tile t's splats are
// entries[offsets[t] .. offsets[t + 1]), indices into the splats, ascending (= front to back).
struct SplatTileLists {
    int size = 0, nx = 0, ny = 0;
    std::vector<std::uint64_t> offsets;
    SplatArray<std::uint32_t> entries;
    // The tile holding image position (x, y), clamped to the grid whose corner is (x0, y0).
    std::size_t tile_of(float x, float y, int x0, int y0) const;
};

// The tiles of a splat's square (from column tx0, row ty0, `width` columns wide) that the binning found it reaches, as
// bits row by row; width 0: not kept (a square of more than 64 tiles), the fill pass tests it again.
struct ReachedTiles {
    std::uint64_t bits;
    std::uint16_t tx0, ty0, width;
};

struct CameraSplatBuffers {
    SplatArray<ProjectedSplat> splats;
    SplatArray<SplatSource> sources;
    SplatTileLists coarse, fine;
    // Working arrays: every Gaussian's sort key (and the sort's other buffer) and projection by global index, each
    // splat's level (coarse or fine), the binning's per-chunk counts and each splat's tiles.
    SplatArray<std::uint64_t> keys, sort_scratch;
    SplatArray<ProjectedSplat> projected;
    SplatArray<std::uint8_t> level;
    std::vector<std::uint32_t> starts;
    SplatArray<ReachedTiles> reached;

    // Bytes of what a frame's samples read (the splats and tile lists), and of everything held.
    std::size_t frame_bytes() const;
    std::size_t capacity_bytes() const;
    // Frees the working arrays (what the samples do not read).
    void release_working_arrays();
};

}  // namespace raysplats
