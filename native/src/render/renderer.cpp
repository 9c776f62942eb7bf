// render() (docs/design.md §6): sample passes over the render region's tiles, the tiles of a pass in parallel, each
// rendering its next sample with the tile sampler (tile_sampler.h); adaptive sampling's checks between passes,
// progress and cancel per tile and pass.
#include "raysplats/render/renderer.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <memory>
#include <mutex>
#include <vector>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "camera_splatting.h"
#include "core/process_clock.h"
#include "gaussian_segment_tracer.h"
#include "path_integrator.h"
#include "pixel_filter.h"
#include "ray.h"
#include "scene_impl.h"
#include "shadow_visibility.h"
#include "tile_sampler.h"

namespace raysplats {

namespace {

// The render region's tiles: squares of `size` pixels from its corner (the whole image without a region), those of
// the last row and column cut at its edges, numbered row by row.
struct TileGrid {
    TileGrid(const PixelRect& r, int ts)
        : region(r), size(ts), nx((r.width() + ts - 1) / ts), count(nx * ((r.height() + ts - 1) / ts)) {}
    PixelRect rect(int t) const {
        const int x0 = region.x0 + (t % nx) * size, y0 = region.y0 + (t / nx) * size;
        return PixelRect{x0, y0, std::min(x0 + size, region.x1), std::min(y0 + size, region.y1)};
    }
    PixelRect region;
    int size, nx, count;
};

// The film outside the region stays empty.
void clear_outside_region(Film& film, const PixelRect& region, int w, int h) {
    if (region.width() < w || region.height() < h) {
        film.clear(0, 0, w, region.y0);
        film.clear(0, region.y1, w, h);
        film.clear(0, region.y0, region.x0, region.y1);
        film.clear(region.x1, region.y0, w, region.y1);
    }
}

// Camera-ray splatting's pre-pass, once per render (per camera), before any tile; its figures go to `stats`. Null
// when camera rays are traced.
std::unique_ptr<const CameraSplatting> prepare_splatting(const Scene::Impl& impl, const RenderSettings& settings,
                                                         const Camera& camera, const GaussianSegmentTracer& tracer,
                                                         const ShadowVisibility& shadow,
                                                         const std::atomic<bool>* cancel, RenderStats& stats) {
    std::unique_ptr<const CameraSplatting> splatting;
    if (const char* reason = CameraSplatting::traced_reason(impl, settings, camera, tracer.shader())) {
        stats.camera_rays_traced_reason = reason;
        return splatting;
    }
    if (!settings.camera_ray_splatting) return splatting;
    PhaseClock clock(stats.splat_prepass_seconds, stats.splat_prepass_cpu_seconds);
    splatting = std::make_unique<const CameraSplatting>(impl, settings, camera, shadow, cancel);
    clock.stop();
    stats.camera_ray_splatting = true;
    stats.splats = splatting->splat_count();
    stats.splat_tile_entries = splatting->tile_entry_count();
    stats.splat_bytes = splatting->memory_bytes();
    return splatting;
}

// Adaptive sampling's decision after a check (Cycles' film_adaptive_sampling_convergence_check, then its
// filter_x / filter_y): a pixel still sampling is noisy while its noise estimate is at or above the threshold;
// converged pixels stay converged. Then every pixel within one pixel (3 x 3) of a noisy one samples on, so that
// the edges of noisy areas are not left splotchy. Returns whether any pixel samples on.
bool update_sampling_mask(const PixelRect& region, int image_width, const float threshold,
                          const std::vector<std::unique_ptr<TileState>>& tiles, std::vector<std::uint8_t>& sampling,
                          std::vector<std::uint8_t>& noisy) {
    const std::size_t w = std::size_t(image_width);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, tiles.size(), 1), [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t t = r.begin(); t != r.end(); ++t) {
            const FilmTile& tile = tiles[t]->samples;
            for (int y = tile.y0(); y < tile.y1(); ++y)
                for (int x = tile.x0(); x < tile.x1(); ++x) {
                    const std::size_t p = std::size_t(y) * w + std::size_t(x);
                    noisy[p] = sampling[p] && !(tile.noise_estimate(x, y) < threshold);
                }
        }
    });
    // The 3 x 3 box as two passes, along rows into `sampling`, then along columns back into `noisy`.
    tbb::parallel_for(tbb::blocked_range<int>(region.y0, region.y1), [&](const tbb::blocked_range<int>& r) {
        for (int y = r.begin(); y != r.end(); ++y)
            for (int x = region.x0; x < region.x1; ++x) {
                const std::size_t p = std::size_t(y) * w + std::size_t(x);
                sampling[p] = noisy[p] || (x > region.x0 && noisy[p - 1]) || (x + 1 < region.x1 && noisy[p + 1]);
            }
    });
    std::atomic<bool> any{false};
    tbb::parallel_for(tbb::blocked_range<int>(region.y0, region.y1), [&](const tbb::blocked_range<int>& r) {
        bool found = false;
        for (int y = r.begin(); y != r.end(); ++y)
            for (int x = region.x0; x < region.x1; ++x) {
                const std::size_t p = std::size_t(y) * w + std::size_t(x);
                noisy[p] = sampling[p] || (y > region.y0 && sampling[p - w]) || (y + 1 < region.y1 && sampling[p + w]);
                found |= noisy[p] != 0;
            }
        if (found) any = true;
    });
    sampling.swap(noisy);
    return any.load();
}

// The traversal counters and camera samples of every tile pass, summed for the film's stats.
struct RenderCounters {
    void add(const Counters& c) {
        traced += c.traced;
        gaussian_hits += c.gaussian_hits;
        candidates += c.candidates;
        group_candidates += c.group_candidates;
    }
    void write_to(RenderStats& stats) const {
        stats.camera_rays = camera_samples.load();
        stats.traced_rays = traced.load();
        stats.gaussian_hits = gaussian_hits.load();
        stats.gaussian_candidates = candidates.load();
        stats.gaussian_group_candidates = group_candidates.load();
    }
    std::atomic<std::uint64_t> traced{0}, gaussian_hits{0}, candidates{0}, group_candidates{0}, camera_samples{0};
};

// The tile passes done, reported to the progress callback, and the cancel flag polled per tile and pass.
class PassProgress {
public:
    PassProgress(const ProgressCallback& progress, const std::atomic<bool>* cancel, double tile_passes)
        : progress_(progress), cancel_(cancel), tile_passes_(tile_passes) {}
    bool cancelled() {
        if (cancelled_.load(std::memory_order_relaxed)) return true;
        if (cancel_ && cancel_->load(std::memory_order_relaxed)) {
            cancelled_ = true;
            return true;
        }
        return false;
    }
    bool was_cancelled() const { return cancelled_.load(); }
    void tile_pass_done() {
        if (progress_) {
            // Counted under the lock, so that the values reported never go backwards.
            std::lock_guard<std::mutex> lock(mutex_);
            progress_(float(double(++done_) / tile_passes_));
        } else {
            ++done_;
        }
    }
    long long tile_passes_done() const { return done_.load(); }

private:
    const ProgressCallback& progress_;
    const std::atomic<bool>* cancel_;
    const double tile_passes_;
    std::atomic<long long> done_{0};
    std::atomic<bool> cancelled_{false};
    std::mutex mutex_;
};

// Sample pass `sample`: every tile renders its next sample, the tiles in parallel. A tile's state is created by the
// thread that renders its first pass (parallel first touch of its sums), or is the last render's tile `kept[t]`
// restarted when it was made for the same pixels and passes.
void render_pass(int sample, const TileGrid& grid, const TileSampler& sampler, bool noise_estimates,
                 const CryptomatteLayout& cryptomatte, const FilmChannelSet& channels,
                 std::vector<std::unique_ptr<TileState>>& tiles, std::vector<std::unique_ptr<TileState>>& kept,
                 PassProgress& progress, RenderCounters& counters) {
    tbb::parallel_for(tbb::blocked_range<int>(0, grid.count, 1), [&](const tbb::blocked_range<int>& range) {
        for (int t = range.begin(); t != range.end(); ++t) {
            // Polled per tile and pass (at most 32 x 32 samples): a cancelled tile keeps its completed passes.
            if (progress.cancelled()) continue;
            std::unique_ptr<TileState>& tile = tiles[std::size_t(t)];
            if (!tile) {
                std::unique_ptr<TileState>& last = t < int(kept.size()) ? kept[std::size_t(t)] : tile;
                if (last && last->made_for(grid.rect(t), noise_estimates, cryptomatte, channels)) {
                    last->restart();
                    tile = std::move(last);
                } else {
                    tile = std::make_unique<TileState>(grid.rect(t), noise_estimates, cryptomatte, channels);
                }
            }
            Counters tile_counters;
            if (sampler.samples(*tile)) counters.camera_samples += sampler.sample(*tile, tile_counters);
            tile->samples_done = sample + 1;
            counters.add(tile_counters);
            progress.tile_pass_done();
        }
    });
}

// Every tile as the mean of the passes it completed; tiles a cancel left without any stay empty.
void write_film(Film& film, const std::vector<std::unique_ptr<TileState>>& tiles, const TileGrid& grid,
                bool transparent_background) {
    tbb::parallel_for(tbb::blocked_range<int>(0, grid.count, 1), [&](const tbb::blocked_range<int>& range) {
        for (int t = range.begin(); t != range.end(); ++t) {
            const TileState* tile = tiles[std::size_t(t)].get();
            if (tile && tile->samples_done > 0) {
                tile->samples.write_to(film, transparent_background);
            } else {
                const PixelRect r = grid.rect(t);
                film.clear(r.x0, r.y0, r.x1, r.y1);
            }
        }
    });
}

}  // namespace

Film render(Scene& scene, const Camera& camera, const RenderSettings& settings, const ProgressCallback& progress,
            const std::atomic<bool>* cancel, const SamplePassCallback& pass_done) {
    settings.validate();
    camera.validate();
    const auto start = std::chrono::steady_clock::now();
    Film film;
    PhaseClock build_clock(film.stats.build_seconds, film.stats.build_cpu_seconds);
    scene.build(settings.gaussian_mode);
    build_clock.stop();
    const Scene::Impl& impl = scene.impl();

    const FilmChannelSet channels = computed_film_channels(settings);
    film.allocate(settings.width, settings.height, channels);  // every pixel is written at the end (or by a snapshot)
    const CryptomatteLayout cryptomatte = cryptomatte_layout_of(settings);
    film.allocate_cryptomatte(cryptomatte);
    const int w = settings.width, h = settings.height;
    const TileGrid grid(render_region_of(settings), settings.tile_size);
    clear_outside_region(film, grid.region, w, h);
    // Adaptive sampling: which pixels still take samples (1), over the whole image's pixels; Cycles' threshold
    // factor 5 ("makes the threshold more similar to what it was before", integrator.cpp) keeps its settings' scale.
    const AdaptiveSampling adaptive = adaptive_sampling_of(settings);
    const float noise_threshold = 5.0f * adaptive.threshold;
    std::vector<std::uint8_t> sampling, noisy;
    if (adaptive.on()) {
        sampling.assign(std::size_t(w) * std::size_t(h), 1);
        noisy.assign(sampling.size(), 0);
    }
    const ShadowVisibility shadow(impl, settings);
    const GaussianSegmentTracer tracer(impl, settings, shadow);
    const MotionVectorProjector vectors(camera, w, h);
    const PathIntegrator integrator(impl, settings, tracer, shadow, vectors);
    const CameraRayGenerator camera_rays(camera, w, h);
    const PixelFilterSampler pixel_filter(settings.pixel_filter, settings.filter_width);
    const std::unique_ptr<const CameraSplatting> splatting =
        prepare_splatting(impl, settings, camera, tracer, shadow, cancel, film.stats);
    const TileSampler sampler(settings, camera_rays, pixel_filter, tracer, splatting.get(), integrator, sampling,
                              impl.has_motion());
    PassProgress pass_progress(progress, cancel, double(grid.count) * double(settings.samples));
    RenderCounters counters;
    std::vector<std::unique_ptr<TileState>> tiles(static_cast<std::size_t>(grid.count)), kept;
    if (impl.keep_frame_buffers) {  // the last render's tiles: restarted, their sums are in the pages they had
        const std::lock_guard<std::mutex> lock(impl.frame_buffers_mutex);
        kept = std::move(impl.frame_tiles);
        impl.frame_tiles.clear();
    }

    // Sample passes: every tile renders sample k before any renders k + 1, so that after each pass the film is a
    // whole image (progressive display; a cancelled render keeps the passes done). A pixel's samples, their seeds and
    // the order of its sums are those of a tile-by-tile loop, so the image is the same bit for bit.
    // With adaptive sampling, pixels drop out at the checks; once none samples on, the render ends early.
    int samples_done = 0;
    RenderStats& stats = film.stats;
    for (int sample = 0; sample < settings.samples; ++sample) {
        PhaseClock sample_clock(stats.sample_seconds, stats.sample_cpu_seconds);
        render_pass(sample, grid, sampler, adaptive.on(), cryptomatte, channels, tiles, kept, pass_progress, counters);
        // A pass counts when every tile finished it, even if a cancel came after the last one did.
        const bool complete = pass_progress.tile_passes_done() >= (long long)(sample + 1) * grid.count;
        if (complete) samples_done = sample + 1;
        // Cycles checks after every kAdaptiveStep samples once the minimum is reached (AdaptiveSampling::need_filter).
        // Once no pixel samples on, the render has converged.
        const bool converged = complete && adaptive.on() && samples_done % kAdaptiveStep == 0 &&
                               samples_done >= adaptive.min_samples && samples_done < settings.samples &&
                               !update_sampling_mask(grid.region, w, noise_threshold, tiles, sampling, noisy);
        sample_clock.stop();
        if (!complete || converged) break;
        if (pass_done && samples_done < settings.samples) {
            PhaseClock film_clock(stats.film_seconds, stats.film_cpu_seconds);
            write_film(film, tiles, grid, settings.transparent_background);
            film_clock.stop();
            film.stats.samples = samples_done;
            pass_done(film);
        }
    }
    PhaseClock film_clock(stats.film_seconds, stats.film_cpu_seconds);
    write_film(film, tiles, grid, settings.transparent_background);
    film_clock.stop();

    film.stats.cancelled = pass_progress.was_cancelled();
    film.stats.samples = samples_done;
    counters.write_to(film.stats);
    if (impl.keep_frame_buffers) {
        // (Of two renders of one scene at once, the tiles of the one that ends last are kept.)
        const std::lock_guard<std::mutex> lock(impl.frame_buffers_mutex);
        impl.frame_tiles = std::move(tiles);
    }
    film.stats.render_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return film;
}

}  // namespace raysplats
