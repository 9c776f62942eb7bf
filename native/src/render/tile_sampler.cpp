#include "tile_sampler.h"

#include <algorithm>

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

}  // namespace

// The camera rays of the 4 x 4 pixels from (bx, by), lane l at pixel (bx + l % 4, by + l / 4), and their first
// segments. Lanes outside the tile, or whose pixel takes no sample or has no valid camera ray, are inactive.
struct TileSampler::Packet {
    int bx, by;
    Ray rays[16];
    bool active[16];
    Sampler rngs[16];  // seeded for the active lanes (the others are never used)
    Segment segs[16];
    int lane_sample[16];
    float sample_x[16], sample_y[16];  // the samples' image positions (camera-ray splatting)
    bool any = false;                  // whether any lane is active
};

TileSampler::TileSampler(const RenderSettings& settings, const CameraRayGenerator& camera_rays,
                         const PixelFilterSampler& pixel_filter, const GaussianSegmentTracer& tracer,
                         const CameraSplatting* splatting, const PathIntegrator& integrator,
                         const std::vector<std::uint8_t>& sampling, bool object_motion)
    : st_(settings), camera_rays_(camera_rays), pixel_filter_(pixel_filter), tracer_(tracer), splatting_(splatting),
      integrator_(integrator), sampling_(sampling),
      speculate_(settings.speculative_ends && settings.compositing == Compositing::Sorted),
      motion_(object_motion || camera_rays.motion()) {}

bool TileSampler::samples(const TileState& tile) const {
    if (sampling_.empty()) return true;
    for (int y = tile.samples.y0(); y < tile.samples.y1(); ++y)
        for (int x = tile.samples.x0(); x < tile.samples.x1(); ++x)
            if (sampling_[std::size_t(y) * st_.width + x]) return true;
    return false;
}

std::uint64_t TileSampler::sample(TileState& tile, Counters& counters) const {
    std::uint64_t taken = 0;
    for (int by = tile.samples.y0(); by < tile.samples.y1(); by += 4)
        for (int bx = tile.samples.x0(); bx < tile.samples.x1(); bx += 4) taken += sample_packet(tile, bx, by, counters);
    return taken;
}

std::uint64_t TileSampler::start_packet(TileState& tile, Packet& packet) const {
    const int x1 = tile.samples.x1(), y1 = tile.samples.y1();
    std::uint64_t empty = 0;
    for (int l = 0; l < 16; ++l) {
        const int x = packet.bx + (l & 3), y = packet.by + (l >> 2);
        packet.active[l] = false;
        packet.rays[l] = Ray{glm::vec3(0.0f), glm::vec3(0, 0, -1), 0.0f, 0.0f};
        if (x >= x1 || y >= y1) continue;
        const std::uint64_t pixel = std::uint64_t(y) * st_.width + x;
        if (!sampling_.empty() && !sampling_[pixel]) continue;
        const int sample = packet.lane_sample[l] = tile.samples.sample_count(x, y);
        Sampler& rng = packet.rngs[l] = Sampler(st_.seed, pixel, std::uint32_t(sample));
        float jx = 0.5f, jy = 0.5f;
        if (st_.jitter) {
            jx = pixel_filter_.position(rng.next());
            jy = pixel_filter_.position(rng.next());
        }
        packet.sample_x[l] = float(x) + jx;
        packet.sample_y[l] = float(y) + jy;
        // Depth of field: the lens position is the stream's next two numbers (none are drawn without it, so a
        // pinhole camera's samples keep their numbers).
        CameraRay cr;
        if (camera_rays_.depth_of_field()) {
            const float lens_u = rng.next();
            const float lens_v = rng.next();
            cr = camera_rays_(x + jx, y + jy, lens_u, lens_v);
        } else {
            cr = camera_rays_(x + jx, y + jy);
        }
        // Motion blur: the ray's shutter time is the stream's next number, through the shutter curve (none is drawn
        // in a still scene, so its samples keep their numbers).
        float time = 0.0f;
        if (motion_) {
            time = camera_rays_.shutter_time(rng.next());
            cr = camera_rays_.at_time(cr, time);
        }
        if (!cr.valid) {
            tile.samples.add_empty_sample(x, y);
            ++empty;
            continue;
        }
        packet.rays[l] = Ray{glm::vec3(cr.origin[0], cr.origin[1], cr.origin[2]),
                             glm::vec3(cr.direction[0], cr.direction[1], cr.direction[2]), cr.t_min, cr.t_max,
                             // Every camera model starts its rays at the camera (an orthographic camera's on its
                             // plane) with unit directions: t is the distance Cycles' camera_distance() gives.
                             0.0f, time};
        packet.active[l] = packet.any = true;
    }
    return empty;
}

void TileSampler::speculative_ends(const TileState& tile, const Packet& packet, float* ends) const {
    const int x0 = tile.samples.x0(), y0 = tile.samples.y0(), tw = tile.samples.x1() - x0;
    for (int l = 0; l < 16; ++l) {
        const int x = packet.bx + (l & 3), y = packet.by + (l >> 2);
        ends[l] = kInf;
        if (!packet.active[l] || !speculate_) continue;
        const float known = known_segment_end(tile.segment_end, tw, x - x0, y - y0, packet.bx - x0, packet.by - y0,
                                              packet.lane_sample[l]);
        // (Not before the ray's own start: neighbours' clip starts differ.)
        if (known * kSpeculativeMargin > packet.rays[l].tmin) ends[l] = known * kSpeculativeMargin;
    }
}

std::uint64_t TileSampler::sample_packet(TileState& tile, int bx, int by, Counters& counters) const {
    Packet p;
    p.bx = bx;
    p.by = by;
    std::uint64_t taken = start_packet(tile, p);
    if (!p.any) return taken;
    float ends[16];
    speculative_ends(tile, p, ends);
    if (splatting_) splatting_->trace_packet(bx, by, p.rays, p.active, p.sample_x, p.sample_y, p.rngs, p.segs, counters);
    else tracer_.trace_packet(p.rays, p.active, ends, p.rngs, p.segs, counters);
    const int x0 = tile.samples.x0(), y0 = tile.samples.y0(), tw = tile.samples.x1() - x0;
    for (int l = 0; l < 16; ++l)
        if (p.active[l]) tile.segment_end[std::size_t(by + (l >> 2) - y0) * tw + (bx + (l & 3) - x0)] = p.segs[l].end;
    for (int l = 0; l < 16; ++l)
        if (p.active[l]) {
            tile.samples.add_sample(bx + (l & 3), by + (l >> 2), p.lane_sample[l],
                                    integrator_.path(p.rays[l], p.rngs[l], counters, &p.segs[l]));
            ++taken;
        }
    return taken;
}

}  // namespace raysplats
