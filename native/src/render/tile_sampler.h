// The tile sampler (internal; docs/design.md §6): one sample pass over one tile for render()'s pass loop. Camera
// rays go out as 4 x 4 packets of neighbouring pixels (coherent) whose first segments the Gaussian segment tracer
// traces together (gaussian_segment_tracer.h), or camera-ray splatting draws (camera_splatting.h), and whose paths
// the path integrator follows one by one (path_integrator.h).
#pragma once

#include <algorithm>
#include <cstdint>
#include <vector>

#include "camera_splatting.h"
#include "gaussian_segment_tracer.h"
#include "path_integrator.h"
#include "pixel_filter.h"
#include "ray.h"
#include "raysplats/render/camera.h"
#include "raysplats/render/film.h"
#include "raysplats/render/render_settings.h"

namespace raysplats {

// What one tile keeps between sample passes: its sums, where its pixels' last camera segments ended (+inf: escaped
// or not traced yet) and how many passes it has completed.
struct TileState {
    TileState(const PixelRect& r, bool noise_estimates, const CryptomatteLayout& cryptomatte = {},
              const FilmChannelSet& channels = all_film_channels())
        : samples(r.x0, r.y0, r.x1, r.y1, noise_estimates, cryptomatte, channels),
          segment_end(std::size_t(r.width()) * std::size_t(r.height()), kInf) {}
    // Whether it was made with these arguments, and back to what they made, in the memory it has.
    bool made_for(const PixelRect& r, bool noise_estimates, const CryptomatteLayout& cryptomatte,
                  const FilmChannelSet& channels) const {
        return samples.made_for(r.x0, r.y0, r.x1, r.y1, noise_estimates, cryptomatte, channels);
    }
    std::size_t capacity_bytes() const { return samples.capacity_bytes() + sizeof(float) * segment_end.capacity(); }
    void restart() {
        samples.restart();
        std::fill(segment_end.begin(), segment_end.end(), kInf);
        samples_done = 0;
    }
    FilmTile samples;
    std::vector<float> segment_end;
    int samples_done = 0;
};

class TileSampler {
public:
    // `splatting`: camera-ray splatting's pre-pass when it draws the camera rays' first segments, else null.
    // `sampling`: adaptive sampling's mask over the image's pixels (1: the pixel still takes samples; empty without
    // adaptive sampling), which render() updates between passes. `object_motion`: some object of the scene moves
    // during the shutter (Scene::has_motion); then, or when the camera moves, each camera ray draws its time.
    TileSampler(const RenderSettings& settings, const CameraRayGenerator& camera_rays,
                const PixelFilterSampler& pixel_filter, const GaussianSegmentTracer& tracer,
                const CameraSplatting* splatting, const PathIntegrator& integrator,
                const std::vector<std::uint8_t>& sampling, bool object_motion);

    // Whether any pixel of the tile still takes samples.
    bool samples(const TileState& tile) const;

    // The next sample of every pixel of the tile that still takes samples (each pixel's own next: its sample count,
    // which is the pass without adaptive sampling). Returns the samples taken.
    std::uint64_t sample(TileState& tile, Counters& counters) const;

private:
    struct Packet;
    // The samples of the 4 x 4 pixels from (bx, by) (image coordinates) that the tile holds.
    std::uint64_t sample_packet(TileState& tile, int bx, int by, Counters& counters) const;
    // The packet's camera rays; a pixel whose camera ray is invalid takes an empty sample. Returns the empty samples
    // taken.
    std::uint64_t start_packet(TileState& tile, Packet& packet) const;
    // Where each active lane's camera segment may end (RenderSettings::speculative_ends; +inf: unknown).
    void speculative_ends(const TileState& tile, const Packet& packet, float* ends) const;

    const RenderSettings& st_;
    const CameraRayGenerator& camera_rays_;
    const PixelFilterSampler& pixel_filter_;
    const GaussianSegmentTracer& tracer_;
    const CameraSplatting* splatting_;
    const PathIntegrator& integrator_;
    const std::vector<std::uint8_t>& sampling_;
    // Not in stochastic mode: a segment ends at a random accepted Gaussian, which its neighbours' do not predict
    // (on showroom_1.5M the frame was slower at every margin tried).
    bool speculate_;
    bool motion_;  // camera rays draw a shutter time
};

}  // namespace raysplats
