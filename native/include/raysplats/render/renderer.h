// The renderer (docs/design.md §6): tiles in parallel, Gaussians composited in exact depth order (or stochastically),
// meshes path traced with next-event estimation (MIS with BSDF sampling for area lights, which rays see).
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>

#include "raysplats/render/camera.h"
#include "raysplats/render/film.h"
#include "raysplats/render/render_settings.h"
#include "raysplats/render/scene.h"

namespace raysplats {

// Called with the fraction done in [0, 1] after each tile's sample pass, from worker threads, one call at a time.
using ProgressCallback = std::function<void(float fraction_done)>;

// Called after each sample pass but the last (the last one's film is render()'s result) with the film of the
// passes done (stats.samples of them, every pixel the mean of that many samples), on the rendering thread while no
// tile renders: the film is valid only during the call (copy what you keep).
using SamplePassCallback = std::function<void(const Film& film_so_far)>;

// Renders `scene` (building its BVH first if needed) in sample passes: every tile renders sample k before any
// renders k + 1. The image does not depend on that order (nor on threads): each pixel sample has its own seed.
// Only the render region's tiles are rendered (RenderSettings::region_*). With adaptive sampling, pixels whose
// noise estimate fell below the threshold take no further samples (checked between passes, so the image is still
// independent of threads), and the render ends early once no pixel samples on.
// `cancel` is polled per tile and pass (at most tile_size^2 samples): once it is set, render returns within a
// fraction of a second with stats.cancelled = true and every tile holding the mean of the passes it completed (the
// tiles the interrupted pass reached have one sample more; tiles without any are empty; stats.samples is the passes
// that every tile completed).
Film render(Scene& scene, const Camera& camera, const RenderSettings& settings,
            const ProgressCallback& progress = {}, const std::atomic<bool>* cancel = nullptr,
            const SamplePassCallback& pass_done = {});

}  // namespace raysplats
