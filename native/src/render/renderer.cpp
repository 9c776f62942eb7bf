// The tile loop of render() (docs/design.md §6): sample passes over the image, tiles in parallel within each, camera
// rays as 4 x 4 packets whose first segments the Gaussian segment tracer traces together (gaussian_segment_tracer.h)
// and whose paths the path integrator follows one by one (path_integrator.h).
#include "raysplats/render/renderer.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "camera_splatting.h"
#include "gaussian_segment_tracer.h"
#include "path_integrator.h"
#include "pixel_filter.h"
#include "ray.h"
#include "raysplats/errors.h"
#include "render_math.h"
#include "scene_impl.h"
#include "shadow_visibility.h"

namespace raysplats {

namespace {

// RenderSettings::speculative_ends: a camera ray first traverses up to this factor times the end of its
// neighbours' (previous sample's) segments. 1.01 gave the least CPU per ray of the margins measured (bench_render,
// showroom_1.5M sorted; docs/benchmarks.md): at 1.0 many more rays must go on, from 1.05 more Gaussians are tested.
constexpr float kSpeculativeMargin = 1.01f;

// The end of the camera segment a tile already knows near pixel (x, y) (tile coordinates) of the 4 x 4 packet at
// (bx, by): the pixel's own in the previous sample; in the first, the larger of its neighbours' in the packets above
// and to the left; +inf when there is none (the tile's first packet, or a neighbour whose segment escaped).
float known_segment_end(const std::vector<float>& segment_end, int tile_width, int x, int y, int bx, int by,
                        int sample) {
    if (sample > 0) return segment_end[std::size_t(y) * tile_width + x];
    if (by == 0 && bx == 0) return kInf;
    float known = 0.0f;
    if (by > 0) known = std::max(known, segment_end[std::size_t(by - 1) * tile_width + x]);
    if (bx > 0) known = std::max(known, segment_end[std::size_t(y) * tile_width + (bx - 1)]);
    return known;
}

// What one tile keeps between sample passes: its sums, where its pixels' last camera segments ended (+inf: escaped
// or not traced yet) and how many passes it has completed.
struct TileState {
    TileState(const PixelRect& r, bool noise_estimates)
        : samples(r.x0, r.y0, r.x1, r.y1, noise_estimates),
          segment_end(std::size_t(r.width()) * std::size_t(r.height()), kInf) {}
    FilmTile samples;
    std::vector<float> segment_end;
    int samples_done = 0;
};

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

}  // namespace

Film render(Scene& scene, const Camera& camera, const RenderSettings& settings, const ProgressCallback& progress,
            const std::atomic<bool>* cancel, const SamplePassCallback& pass_done) {
    settings.validate();
    camera.validate();
    const auto start = std::chrono::steady_clock::now();
    scene.build(settings.gaussian_mode);
    const Scene::Impl& impl = scene.impl();

    Film film;
    film.allocate(settings.width, settings.height);  // every pixel is written at the end (or by a snapshot)
    const int w = settings.width, h = settings.height, ts = settings.tile_size;
    // Tiles cover the region (the whole image without one) from its corner; the rest of the film stays empty.
    const PixelRect region = render_region_of(settings);
    const int tiles_x = (region.width() + ts - 1) / ts, tiles_y = (region.height() + ts - 1) / ts;
    const int tile_count = tiles_x * tiles_y;
    auto tile_rect = [&](int t) {
        const int x0 = region.x0 + (t % tiles_x) * ts, y0 = region.y0 + (t / tiles_x) * ts;
        return PixelRect{x0, y0, std::min(x0 + ts, region.x1), std::min(y0 + ts, region.y1)};
    };
    if (region.width() < w || region.height() < h) {
        film.clear(0, 0, w, region.y0);
        film.clear(0, region.y1, w, h);
        film.clear(0, region.y0, region.x0, region.y1);
        film.clear(region.x1, region.y0, w, region.y1);
    }
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
    const PathIntegrator integrator(impl, settings, tracer, shadow);
    const CameraRayGenerator camera_rays(camera, w, h);
    const PixelFilterSampler pixel_filter(settings.pixel_filter, settings.filter_width);
    // Camera-ray splatting: its pre-pass once per render (per camera), before any tile.
    std::unique_ptr<const CameraSplatting> splatting;
    if (CameraSplatting::applies(impl, settings, camera, tracer.shader())) {
        const auto prepass_start = std::chrono::steady_clock::now();
        splatting = std::make_unique<const CameraSplatting>(impl, settings, camera, shadow, cancel);
        film.stats.splat_prepass_seconds =
            std::chrono::duration<double>(std::chrono::steady_clock::now() - prepass_start).count();
        film.stats.camera_ray_splatting = true;
        film.stats.splats = splatting->splat_count();
        film.stats.splat_tile_entries = splatting->tile_entry_count();
        film.stats.splat_bytes = splatting->memory_bytes();
    }
    // Not in stochastic mode: a segment ends at a random accepted Gaussian, which its neighbours' do not predict
    // (on showroom_1.5M the frame was slower at every margin tried).
    const bool speculate = settings.speculative_ends && settings.compositing == Compositing::Sorted;
    std::atomic<long long> tile_passes_done{0};
    const double tile_passes = double(tile_count) * double(settings.samples);
    std::atomic<bool> cancelled{false};
    std::atomic<std::uint64_t> traced{0}, gaussian_hits{0}, candidates{0}, group_candidates{0}, camera_samples{0};
    std::mutex progress_mutex;
    auto is_cancelled = [&] {
        if (cancelled.load(std::memory_order_relaxed)) return true;
        if (cancel && cancel->load(std::memory_order_relaxed)) {
            cancelled = true;
            return true;
        }
        return false;
    };
    // Created by the thread that renders the tile's first pass (parallel first touch of its sums).
    std::vector<std::unique_ptr<TileState>> tiles(static_cast<std::size_t>(tile_count));

    // The next sample of every pixel of a tile that still takes samples (each pixel's own next: its sample count,
    // which is the pass without adaptive sampling). Camera rays go to Embree as 4 x 4 packets (neighbouring pixels,
    // coherent). Returns the samples taken.
    auto render_tile_sample = [&](TileState& tile, Counters& counters) {
        const int x0 = tile.samples.x0(), y0 = tile.samples.y0(), x1 = tile.samples.x1(), y1 = tile.samples.y1();
        const int tw = x1 - x0;
        std::uint64_t taken = 0;
        for (int by = y0; by < y1; by += 4) {
            for (int bx = x0; bx < x1; bx += 4) {
                Ray rays[16];
                bool active[16];
                Sampler rngs[16];  // seeded below for the packet's pixels (the others are never used)
                Segment segs[16];
                int lane_sample[16];
                float sample_x[16], sample_y[16];  // the samples' image positions (camera-ray splatting)
                bool any = false;
                for (int l = 0; l < 16; ++l) {
                    const int x = bx + (l & 3), y = by + (l >> 2);
                    active[l] = false;
                    rays[l] = Ray{glm::vec3(0.0f), glm::vec3(0, 0, -1), 0.0f, 0.0f};
                    if (x >= x1 || y >= y1) continue;
                    const std::uint64_t pixel = std::uint64_t(y) * w + x;
                    if (!sampling.empty() && !sampling[pixel]) continue;
                    const int sample = lane_sample[l] = tile.samples.sample_count(x, y);
                    rngs[l] = Sampler(settings.seed, pixel, std::uint32_t(sample));
                    float jx = 0.5f, jy = 0.5f;
                    if (settings.jitter) {
                        jx = pixel_filter.position(rngs[l].next());
                        jy = pixel_filter.position(rngs[l].next());
                    }
                    sample_x[l] = float(x) + jx;
                    sample_y[l] = float(y) + jy;
                    const CameraRay cr = camera_rays(x + jx, y + jy);
                    if (!cr.valid) {
                        tile.samples.add_empty_sample(x, y);
                        ++taken;
                        continue;
                    }
                    rays[l] = Ray{glm::vec3(cr.origin[0], cr.origin[1], cr.origin[2]),
                                  glm::vec3(cr.direction[0], cr.direction[1], cr.direction[2]), cr.t_min, cr.t_max};
                    active[l] = any = true;
                }
                if (!any) continue;
                float ends[16];
                for (int l = 0; l < 16; ++l) {
                    const int x = bx + (l & 3), y = by + (l >> 2);
                    ends[l] = kInf;
                    if (!active[l] || !speculate) continue;
                    const float known =
                        known_segment_end(tile.segment_end, tw, x - x0, y - y0, bx - x0, by - y0, lane_sample[l]);
                    // (Not before the ray's own start: neighbours' clip starts differ.)
                    if (known * kSpeculativeMargin > rays[l].tmin) ends[l] = known * kSpeculativeMargin;
                }
                if (splatting) splatting->trace_packet(bx, by, rays, active, sample_x, sample_y, rngs, segs, counters);
                else tracer.trace_packet(rays, active, ends, rngs, segs, counters);
                for (int l = 0; l < 16; ++l)
                    if (active[l])
                        tile.segment_end[std::size_t(by + (l >> 2) - y0) * tw + (bx + (l & 3) - x0)] = segs[l].end;
                for (int l = 0; l < 16; ++l)
                    if (active[l]) {
                        tile.samples.add_sample(bx + (l & 3), by + (l >> 2), lane_sample[l],
                                                integrator.path(rays[l], rngs[l], counters, &segs[l]));
                        ++taken;
                    }
            }
        }
        return taken;
    };

    // Whether any pixel of the tile still takes samples.
    auto tile_samples = [&](const TileState& tile) {
        if (sampling.empty()) return true;
        for (int y = tile.samples.y0(); y < tile.samples.y1(); ++y)
            for (int x = tile.samples.x0(); x < tile.samples.x1(); ++x)
                if (sampling[std::size_t(y) * w + x]) return true;
        return false;
    };

    // Every tile as the mean of the passes it completed; tiles a cancel left without any stay empty.
    auto write_film = [&] {
        tbb::parallel_for(tbb::blocked_range<int>(0, tile_count, 1), [&](const tbb::blocked_range<int>& range) {
            for (int t = range.begin(); t != range.end(); ++t) {
                const TileState* tile = tiles[std::size_t(t)].get();
                if (tile && tile->samples_done > 0) {
                    tile->samples.write_to(film, settings.transparent_background);
                } else {
                    const PixelRect r = tile_rect(t);
                    film.clear(r.x0, r.y0, r.x1, r.y1);
                }
            }
        });
    };

    // Sample passes: every tile renders sample k before any renders k + 1, so that after each pass the film is a
    // whole image (progressive display; a cancelled render keeps the passes done). A pixel's samples, their seeds and
    // the order of its sums are those of a tile-by-tile loop, so the image is the same bit for bit.
    // With adaptive sampling, pixels drop out at the checks; once none samples on, the render ends early.
    int samples_done = 0;
    for (int sample = 0; sample < settings.samples; ++sample) {
        tbb::parallel_for(tbb::blocked_range<int>(0, tile_count, 1), [&](const tbb::blocked_range<int>& range) {
            for (int t = range.begin(); t != range.end(); ++t) {
                // Polled per tile and pass (at most 32 x 32 samples): a cancelled tile keeps its completed passes.
                if (is_cancelled()) continue;
                std::unique_ptr<TileState>& tile = tiles[std::size_t(t)];
                if (!tile) tile = std::make_unique<TileState>(tile_rect(t), adaptive.on());
                Counters counters;
                if (tile_samples(*tile)) camera_samples += render_tile_sample(*tile, counters);
                tile->samples_done = sample + 1;
                traced += counters.traced;
                gaussian_hits += counters.gaussian_hits;
                candidates += counters.candidates;
                group_candidates += counters.group_candidates;
                if (progress) {
                    // Counted under the lock, so that the values reported never go backwards.
                    std::lock_guard<std::mutex> lock(progress_mutex);
                    progress(float(double(++tile_passes_done) / tile_passes));
                } else {
                    ++tile_passes_done;
                }
            }
        });
        // A pass counts when every tile finished it, even if a cancel came after the last one did.
        if (tile_passes_done.load() < (long long)(sample + 1) * tile_count) break;
        samples_done = sample + 1;
        // Cycles checks after every kAdaptiveStep samples once the minimum is reached (AdaptiveSampling::need_filter).
        bool converged = false;
        if (adaptive.on() && samples_done % kAdaptiveStep == 0 && samples_done >= adaptive.min_samples &&
            samples_done < settings.samples)
            converged = !update_sampling_mask(region, w, noise_threshold, tiles, sampling, noisy);
        if (converged) break;
        if (pass_done && samples_done < settings.samples) {
            write_film();
            film.stats.samples = samples_done;
            pass_done(film);
        }
    }
    write_film();

    film.stats.cancelled = cancelled.load();
    film.stats.samples = samples_done;
    film.stats.camera_rays = camera_samples.load();
    film.stats.traced_rays = traced.load();
    film.stats.gaussian_hits = gaussian_hits.load();
    film.stats.gaussian_candidates = candidates.load();
    film.stats.gaussian_group_candidates = group_candidates.load();
    film.stats.render_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return film;
}

}  // namespace raysplats
