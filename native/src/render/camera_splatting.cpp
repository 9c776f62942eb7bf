#include "camera_splatting.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "gaussian_callbacks.h"
#include "gaussian_primitives.h"
#include "mist.h"
#include "simd.h"

namespace raysplats {

bool CameraSplatting::applies(const Scene::Impl& scene, const RenderSettings& settings, const Camera& camera,
                              const GaussianShader& shader) {
    return settings.camera_ray_splatting && !traced_reason(scene, settings, camera, shader);
}

const char* CameraSplatting::traced_reason(const Scene::Impl& scene, const RenderSettings& settings,
                                           const Camera& camera, const GaussianShader& shader) {
    if (!settings.camera_ray_splatting) return nullptr;
    if (camera.type != CameraType::Perspective) return "needs a perspective camera";
    if (CameraRayGenerator(camera, settings.width, settings.height).depth_of_field())
        return "needs a camera without depth of field";
    // Its splats are projected once per frame: a camera or object moving during the shutter is not there.
    if (camera.motion.size() >= 2 || scene.has_motion()) return "needs a scene without motion blur";
    for (const auto& set : scene.gaussians) {
        if (shader.shading(set->index) != GaussianShading::Baked) return "needs every Gaussian object Baked";
        if (set->holdout) return "needs no Gaussian object held out";
    }
    return nullptr;
}

CameraSplatting::CameraSplatting(const Scene::Impl& scene, const RenderSettings& settings, const Camera& camera,
                                 const ShadowVisibility& shadow, const std::atomic<bool>* cancel)
    : s_(scene), st_(settings), shadow_(shadow), prepass_(scene, settings, camera, cancel),
      cryptomatte_(cryptomatte_layout_of(settings).on()) {}

namespace {

// The samples of a packet's lanes for the branch-free per-splat test: their positions and mesh depths (lanes not
// composited far off the image and in front of everything), and the box of their positions.
struct PacketSamples {
    float x0, y0, x1, y1;
    alignas(16) float px[16], py[16], pz[16];
};

void packet_samples(std::uint32_t lanes, const float* xs, const float* ys, const float* mesh_depth,
                    PacketSamples& s) {
    s.x0 = std::numeric_limits<float>::infinity();
    s.y0 = s.x0;
    s.x1 = -s.x0;
    s.y1 = -s.x0;
    for (int l = 0; l < 16; ++l) {
        s.px[l] = s.py[l] = -1e15f;
        s.pz[l] = -kInf;
    }
    for (std::uint32_t live = lanes; live; live &= live - 1) {
        const int l = __builtin_ctz(live);
        s.x0 = std::min(s.x0, xs[l]);
        s.x1 = std::max(s.x1, xs[l]);
        s.y0 = std::min(s.y0, ys[l]);
        s.y1 = std::max(s.y1, ys[l]);
        s.px[l] = xs[l];
        s.py[l] = ys[l];
        s.pz[l] = mesh_depth[l];
    }
}

}  // namespace

inline bool CameraSplatting::blend(std::uint32_t index, float power, const Ray& ray, float view_rate, Sampler& rng,
                                   Segment& seg, Counters& c) const {
    const ProjectedSplat& ps = prepass_.splats()[index];
    const float alpha = std::min(kMaxAlpha, ps.opacity * std::exp(power));
    if (alpha < kMinAlpha) return false;
    glm::vec3 color = ps.color;
    if (st_.meshes_shadow_gaussians) {
        // As GaussianSegmentTracer::gaussian_color: the lights' visibility v from the centre scales linear light.
        const SplatSource& source = prepass_.sources()[index];
        const float vis =
            shadow_.gaussian_light_visibility(s_.gaussians[source.set]->world_center(source.prim), 0.0f, rng, c);
        if (st_.blend_space != BlendSpace::Display) color *= vis;
        else if (vis < 1.0f)
            for (int ch = 0; ch < 3; ++ch) color[ch] = linear_to_srgb(vis * srgb_to_linear(color[ch]));
    }
    const float t_before = seg.transmittance;
    seg.radiance += t_before * alpha * color;
    seg.transmittance = t_before * (1.0f - alpha);
    ++seg.gaussians;
    ++c.gaussian_hits;
    const bool opaque_here = t_before > 0.5f && seg.transmittance <= 0.5f;
    const bool stop = seg.transmittance < st_.transmittance_threshold;
    // As GaussianSegmentTracer::add_mist: a stopping splat takes the transmittance left too.
    if (st_.mist_pass)
        seg.mist_clearance += (stop ? t_before : t_before * alpha) *
                              mist_clearance(s_.world, ray.camera_distance + ps.depth / view_rate);
    // As GaussianSegmentTracer::add_cryptomatte, with the same weight.
    if (cryptomatte_)
        seg.cryptomatte.add(s_.gaussians[prepass_.sources()[index].set]->cryptomatte_ids,
                            stop ? t_before : t_before * alpha);
    if (st_.denoising_data) {
        // The denoiser's guides as GaussianSegmentTracer::add_guides, with the colour the splat shows (every splat
        // is BAKED here).
        const SplatSource& source = prepass_.sources()[index];
        const GaussianSet& set = *s_.gaussians[source.set];
        glm::vec3 albedo = color;
        if (st_.blend_space == BlendSpace::Display)
            for (int ch = 0; ch < 3; ++ch) albedo[ch] = srgb_to_linear(albedo[ch]);
        const glm::vec3 n = set.flat ? set.world_normal(source.prim) : -ray.d;
        const float weight = stop ? t_before : t_before * alpha;
        seg.guide_albedo += weight * glm::clamp(albedo, glm::vec3(0.0f), glm::vec3(1.0f));
        seg.guide_normal += weight * (glm::dot(n, ray.d) > 0.0f ? -n : n);
    }
    if (opaque_here || stop) {
        // The point of the ray nearest the centre stands for the splat's place along the ray.
        const SplatSource& source = prepass_.sources()[index];
        const GaussianSet& set = *s_.gaussians[source.set];
        const float along = glm::dot(set.world_center(source.prim) - ray.o, ray.d);
        if (opaque_here) {
            seg.depth = along;
            seg.depth_set = &set;
            const glm::vec3 n = set.flat ? set.world_normal(source.prim) : -ray.d;
            seg.normal = glm::dot(n, ray.d) > 0.0f ? -n : n;
        }
        if (stop) {
            seg.terminated = true;
            seg.end = along;
        }
    }
    return stop;
}

inline void CameraSplatting::composite(std::size_t fine_tile, std::uint32_t lanes, const Ray* rays, const float* xs,
                                       const float* ys, const float* mesh_depth, const float* view_rates,
                                       Sampler* rngs, Segment* segs, Counters& c) const {
    const SplatArray<ProjectedSplat>& splats = prepass_.splats();
    const SplatTileLists &coarse_lists = prepass_.coarse(), &fine_lists = prepass_.fine();
    // The box of the packet's sample positions: a splat whose square misses it is skipped with four comparisons
    // instead of one per lane. A 4 x 4 packet covers a sixteenth of a 16 px tile, and a zoomed-out view of a big scene
    // has thousands of small splats per tile list (showroom_1.5M whole at 640 x 360, 128 samples: the F12 took 7.5x
    // the traced render's time before this test).
    PacketSamples samples;
    packet_samples(lanes, xs, ys, mesh_depth, samples);
    const float x0 = samples.x0, y0 = samples.y0, x1 = samples.x1, y1 = samples.y1;
    const float *px = samples.px, *py = samples.py, *pz = samples.pz;
    // The coarse tile holding the fine one, and the two lists' ranges; a splat is in one level, so merging them by
    // rank (= depth order) visits each splat once, front to back.
    constexpr int kPerCoarse = CameraSplatPrepass::kTileSize / CameraSplatPrepass::kFineTileSize;
    const std::size_t fx = fine_tile % std::size_t(fine_lists.nx), fy = fine_tile / std::size_t(fine_lists.nx);
    const std::size_t tile = fy / kPerCoarse * std::size_t(coarse_lists.nx) + fx / kPerCoarse;
    const std::uint32_t* coarse = coarse_lists.entries.data() + coarse_lists.offsets[tile];
    const std::uint32_t* const coarse_end = coarse_lists.entries.data() + coarse_lists.offsets[tile + 1];
    const std::uint32_t* fine = fine_lists.entries.data() + fine_lists.offsets[fine_tile];
    const std::uint32_t* const fine_end = fine_lists.entries.data() + fine_lists.offsets[fine_tile + 1];
    // The splats are in depth order, so a tile's are scattered over the whole array: each read misses the cache. They
    // are fetched kPrefetch entries ahead of their turn in either list.
    constexpr std::ptrdiff_t kPrefetch = 8;
    for (std::ptrdiff_t k = 0; k < kPrefetch; ++k) {
        if (coarse + k < coarse_end) __builtin_prefetch(&splats[coarse[k]]);
        if (fine + k < fine_end) __builtin_prefetch(&splats[fine[k]]);
    }
    while (lanes && (coarse != coarse_end || fine != fine_end)) {
        const bool take_fine = coarse == coarse_end || (fine != fine_end && *fine < *coarse);
        const std::uint32_t index = take_fine ? *fine++ : *coarse++;
        if (take_fine ? fine + kPrefetch - 1 < fine_end : coarse + kPrefetch - 1 < coarse_end)
            __builtin_prefetch(&splats[take_fine ? fine[kPrefetch - 1] : coarse[kPrefetch - 1]]);
        ++c.group_candidates;
        const ProjectedSplat& ps = splats[index];
        if (ps.u + ps.half_extent < x0 || ps.u - ps.half_extent > x1 || ps.v + ps.half_extent < y0 ||
            ps.v - ps.half_extent > y1)
            continue;
        // Every lane at once, without branches (the tests' outcomes are as good as random, and lanes that are done
        // fail them): the exponent, which lanes the splat covers, and which it is behind the mesh hit of.
        using V = Sse::V;
        const V u = Sse::set1(ps.u), v = Sse::set1(ps.v), half = Sse::set1(ps.half_extent), zero = Sse::set1(0.0f);
        const V c0 = Sse::set1(ps.conic[0]), c1 = Sse::set1(ps.conic[1]), c2 = Sse::set1(ps.conic[2]);
        const V least = Sse::set1(ps.least_power), depth = Sse::set1(ps.depth), minus_half = Sse::set1(-0.5f);
        alignas(16) float power[16];
        std::uint32_t covered = 0, behind = 0;
        for (int k = 0; k < 16; k += Sse::W) {
            const V dx = Sse::sub(Sse::load(px + k), u), dy = Sse::sub(Sse::load(py + k), v);
            // -1/2 (c0 dx^2 + c2 dy^2) - c1 dx dy
            const V p = Sse::sub(Sse::mul(minus_half, Sse::add(Sse::mul(Sse::mul(c0, dx), dx), Sse::mul(Sse::mul(c2, dy), dy))),
                                 Sse::mul(Sse::mul(c1, dx), dy));
            Sse::store(power + k, p);
            const V covers = Sse::and_(Sse::and_(Sse::le(Sse::abs(dx), half), Sse::le(Sse::abs(dy), half)),
                                       Sse::and_(Sse::le(p, zero), Sse::le(least, p)));
            covered |= Sse::bits(covers) << k;
            behind |= Sse::bits(Sse::le(Sse::load(pz + k), depth)) << k;  // !(depth < mesh depth)
        }
        c.candidates += std::uint64_t(__builtin_popcount(lanes));
        lanes &= ~behind;  // the lists are front to back: these lanes are done
        for (std::uint32_t live = covered & lanes; live; live &= live - 1) {
            const int l = __builtin_ctz(live);
            if (blend(index, power[l], rays[l], view_rates[l], rngs[l], segs[l], c)) lanes &= ~(1u << l);
        }
    }
}

void CameraSplatting::trace_packet(int packet_x, int packet_y, const Ray* rays, const bool* active, const float* xs,
                                   const float* ys, Sampler* rngs, Segment* segs, Counters& c) const {
    const SplatTileLists& fine_lists = prepass_.fine();
    for (int l = 0; l < 16; ++l) segs[l] = Segment{};
    // The first mesh hit of each ray (Gaussians ignored), as a packet.
    RTCRayHit16 rh;
    alignas(64) int valid[16];
    LaneState lanes[16];
    bool any_mesh = !s_.meshes.empty();
    for (int l = 0; l < 16 && any_mesh; ++l) {
        const Ray& r = rays[l];
        valid[l] = active[l] ? -1 : 0;
        if (active[l]) set_packet_lane(rh, l, r, r.tmax);
        else set_packet_lane_inactive(rh, l);
    }
    if (any_mesh) {
        // The meshes' own scene (Gaussians are ignored); rays come back in the packet's order on every Embree path.
        TraceContext ctx(lanes, 16, TraceMode::MeshesOnly);
        ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
        rtcIntersect16(valid, s_.mesh_scene, &ctx, &rh);
    }
    float mesh_depth[16], view_rates[16];
    std::size_t tiles[16];
    std::uint32_t pending = 0;  // lanes whose tile is not composited yet
    for (int l = 0; l < 16; ++l) {
        if (!active[l]) continue;
        const bool mesh = any_mesh && rh.hit.geomID[l] != RTC_INVALID_GEOMETRY_ID;
        if (any_mesh) ++c.traced;
        mesh_depth[l] = mesh ? prepass_.view_depth(rays[l].o + rh.ray.tfar[l] * rays[l].d) : kInf;
        // (Perspective rays start at the camera, whose view depth is 0.)
        view_rates[l] = prepass_.view_depth(rays[l].o + rays[l].d);
        // The tile of the lane's pixel, not of its sample: the lists are binned for every sample of their pixels.
        tiles[l] = fine_lists.tile_of(float(packet_x + (l & 3)) + 0.5f, float(packet_y + (l >> 2)) + 0.5f,
                                      prepass_.grid_x0(), prepass_.grid_y0());
        pending |= 1u << l;
    }
    // The lanes of one fine tile together: all 16, unless a tile size that is not a multiple of 4 misaligned the packet.
    while (pending && !fine_lists.offsets.empty()) {  // (no offsets: the pre-pass was cancelled)
        const std::size_t tile = tiles[__builtin_ctz(pending)];
        std::uint32_t group = 0;
        for (std::uint32_t p = pending; p; p &= p - 1)
            if (tiles[__builtin_ctz(p)] == tile) group |= 1u << __builtin_ctz(p);
        composite(tile, group, rays, xs, ys, mesh_depth, view_rates, rngs, segs, c);
        pending &= ~group;
    }
    for (int l = 0; l < 16; ++l) {
        if (!active[l]) continue;
        Segment& seg = segs[l];
        const bool mesh = any_mesh && rh.hit.geomID[l] != RTC_INVALID_GEOMETRY_ID;
        if (seg.terminated || !mesh) continue;
        const float t_mesh = rh.ray.tfar[l];
        // As GaussianSegmentTracer::record_mesh (every top-level geometry is an instance).
        seg.mesh = true;
        const unsigned inst = rh.hit.instID[0][l];
        seg.top_geom = inst != RTC_INVALID_GEOMETRY_ID ? inst : rh.hit.geomID[l];
        seg.prim = rh.hit.primID[l];
        seg.t = seg.end = t_mesh;
        seg.u = rh.hit.u[l];
        seg.v = rh.hit.v[l];
        if (seg.transmittance > 0.5f) {
            seg.depth = seg.t;
            seg.depth_at_mesh = true;
        }
    }
}

}  // namespace raysplats
