// The renderer (DESIGN §6): tiles in parallel, Gaussians composited in exact depth order (or stochastically),
// meshes path traced with next-event estimation (MIS with BSDF sampling for area lights, which rays see).
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>

#include "raysplats/render/camera.h"
#include "raysplats/render/film.h"
#include "raysplats/render/scene.h"

namespace raysplats {

enum class Compositing {
    Sorted,      // exact front-to-back order: k-nearest buffer per ray, re-traced until the segment is done
    Stochastic,  // one traversal per sample, each candidate accepted with probability alpha, nearest kept
};

struct RenderSettings {
    int width = 640;
    int height = 480;
    int samples = 16;        // per pixel, 1 .. 1 << 20
    int max_bounces = 4;     // 0 = direct light only, up to 1024
    std::uint32_t seed = 0;  // the image is a function of the seed only (not of thread scheduling)
    Compositing compositing = Compositing::Sorted;
    float transmittance_threshold = 1e-3f;  // stop compositing when T drops below this, in [0, 1)
    GaussianMode gaussian_mode = GaussianMode::Flat;
    // Gaussians carry baked radiance; with this their colour is scaled by the lights' visibility from the
    // Gaussian centre (meshes only occlude), so meshes cast shadows on splats.
    bool meshes_shadow_gaussians = false;
    int tile_size = 32;
    // k of the per-ray k-nearest buffer (1 .. 128). Any k gives the same image; it trades re-traces against
    // culling. The buffer is also cut where the transmittance falls below the threshold. 96 covers the ~34
    // Gaussians an indoor ray composites (showroom_1.5M) with room for the out-of-order arrivals of a traversal, so
    // rays are rarely re-traced: bench_render, CPU time per ray k = 16 / 32 / 48 / 64 / 96 / 128:
    // 5.6 / 3.6 / 3.1 / 2.8 / 2.7 / 2.7 us.
    int gather_buffer_size = 96;
    // Box-filtered jitter inside the pixel; when false every sample goes through the pixel centre.
    bool jitter = true;
    // true: camera rays that escape show nothing (rgba is premultiplied by coverage, Blender's Film >
    // Transparent). false: they show the world, and rgba alpha is 1. The alpha buffer is coverage either way.
    bool transparent_background = false;
    // Cycles' "Caustics" (Render > Light Paths > Caustics, defaults on): when off, a path whose last bounce was
    // diffuse gets no glossy/specular reflection (refraction) lobes at its next surface, so it cannot make
    // reflective (refractive) caustics; a surface left without lobes (a mirror, a metal) absorbs such paths.
    bool caustics_reflective = true;
    bool caustics_refractive = true;
    // Sorted mode: camera rays first traverse the scene only up to a little beyond where their neighbours' (or,
    // after the first sample, their own previous) camera segments ended, and go on from there when that was too
    // early: the traversal then skips what lies behind the first opaque layer. The image is the same either way (the
    // same Gaussians composited in the same order); off is for tests and measurements.
    bool speculative_ends = true;

    // Throws InvalidArgument with the offending setting.
    void validate() const;
};

// Called with the fraction done in [0, 1] after each tile, from worker threads, one call at a time.
using ProgressCallback = std::function<void(float fraction_done)>;

// Renders `scene` (building its BVH first if needed). `cancel` is polled per tile row and per sample: once it
// is set, render returns within a fraction of a second with stats.cancelled = true and the tiles done so far.
Film render(Scene& scene, const Camera& camera, const RenderSettings& settings,
            const ProgressCallback& progress = {}, const std::atomic<bool>* cancel = nullptr);

}  // namespace raysplats
