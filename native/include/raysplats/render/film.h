// The renderer's output: float buffers a binding can expose to numpy without copies (std::vector::data()).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "raysplats/default_init_allocator.h"

namespace raysplats {

// The renderer writes every pixel of the film from its tiles, in parallel (DefaultInitAllocator): a 1920 x 1080
// film (75 MB) no longer costs about 40 ms of serial zeroing and page faults before the first ray.
using FloatBuffer = std::vector<float, DefaultInitAllocator<float>>;

struct RenderStats {
    double render_seconds = 0.0;
    std::uint64_t camera_rays = 0;       // primary rays (one per pixel sample)
    std::uint64_t traced_rays = 0;       // every rtcIntersect1/rtcOccluded1 call, including re-traces
    std::uint64_t gaussian_hits = 0;     // Gaussians composited (sorted) or accepted candidates (stochastic)
    std::uint64_t gaussian_candidates = 0;  // Gaussian intersection tests run by the traversals
    std::uint64_t gaussian_group_candidates = 0;  // the groups of Gaussians (Embree primitives) they belong to
    bool cancelled = false;
};

// Rows are stored top to bottom (row 0 is the top of the image), pixels left to right.
struct Film {
    int width = 0;
    int height = 0;
    FloatBuffer rgba;    // width * height * 4, linear, premultiplied (see RenderSettings::transparent_background)
    FloatBuffer depth;   // distance from the camera along the ray to the first surface where the
                                // accumulated opacity reaches 0.5; +inf where there is none
    FloatBuffer normal;  // width * height * 3, world-space normal at that surface, 0 where none
    FloatBuffer alpha;   // width * height: 1 - final transmittance (1 where an opaque surface was hit)
    RenderStats stats;

    // An empty film: rgba, normal and alpha 0, depth +inf.
    void resize(int width, int height);
    // Sizes the buffers without writing them (their contents are unspecified until written): for writers that
    // write every pixel, such as the renderer.
    void allocate(int width, int height);
    // Writes the empty-film values into pixels [x0, x1) x [y0, y1).
    void clear(int x0, int y0, int x1, int y1);
    std::size_t pixel_count() const { return std::size_t(width) * std::size_t(height); }
    const float* pixel(int x, int y) const { return &rgba[4 * (std::size_t(y) * width + x)]; }

    // Writers: PNG is 8-bit sRGB (the linear buffer clamped and encoded), PFM is the float RGB buffer.
    // Both write atomically (temporary file, then rename); failures throw raysplats::Error.
    void write_png(const std::string& path) const;
    void write_pfm(const std::string& path) const;
};

}  // namespace raysplats
