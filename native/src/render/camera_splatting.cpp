#include "camera_splatting.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <string>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include "gaussian_callbacks.h"
#include "gaussian_primitives.h"
#include "pixel_filter.h"
#include "simd.h"
#include "raysplats/errors.h"

namespace raysplats {

namespace {

constexpr float kDilation = 0.3f;           // px^2 added to the 2D covariance's diagonal (3DGS computeCov2D)
constexpr float kJacobianClamp = 1.3f;      // x/z and y/z clamped to 1.3 x the frustum's half extent (3DGS)
constexpr float kFootprintSigmas = 3.0f;    // square half side in standard deviations (3DGS getRect's radius)

// Pixels of the pixel filter's reach around a pixel (PixelFilterSampler::reach), rounded up, plus one: camera samples
// fall within it. A multiple of 4, so that the render loop's 4 x 4 packets of pixels (from the region's corner) each
// lie in one tile.
int filter_margin(const RenderSettings& st) {
    const int reach = (st.jitter ? int(std::ceil(PixelFilterSampler::reach(st.pixel_filter, st.filter_width))) : 0) + 1;
    return (reach + 3) / 4 * 4;
}

// Not a rank (rank_of), not a key (keys).
constexpr std::uint32_t kNotVisible = 0xffffffffu;
constexpr std::uint64_t kNotVisibleKey = ~std::uint64_t(0);

}  // namespace

bool CameraSplatting::applies(const Scene::Impl& scene, const RenderSettings& settings, const Camera& camera,
                              const GaussianShader& shader) {
    if (!settings.camera_ray_splatting || camera.type != CameraType::Perspective) return false;
    for (const auto& set : scene.gaussians)
        if (shader.shading(set->index) != GaussianShading::Baked) return false;
    return true;
}

float CameraSplatting::view_depth(const glm::vec3& world_point) const {
    return -(world_to_camera_ * (world_point - camera_origin_)).z;
}

CameraSplatting::CameraSplatting(const Scene::Impl& scene, const RenderSettings& settings, const Camera& camera,
                                 const ShadowVisibility& shadow, const std::atomic<bool>* cancel)
    : s_(scene), st_(settings), shadow_(shadow) {
    auto cancelled = [cancel] { return cancel && cancel->load(std::memory_order_relaxed); };
    const CameraRayGenerator rays(camera, settings.width, settings.height);
    const CameraRayGenerator::PinholeProjection proj = rays.pinhole_projection();
    fx_ = proj.fx;
    fy_ = proj.fy;
    cx_ = proj.cx;
    cy_ = proj.cy;
    const glm::mat3 camera_linear = linear_part(camera.camera_to_world);
    world_to_camera_ = glm::inverse(camera_linear);
    camera_origin_ = translation_part(camera.camera_to_world);
    // Depths in camera space: a scaled camera matrix scales them, and its clip distances are in the same units
    // (camera.cpp: the clip range is measured along the unscaled view axis).
    const float near = camera.clip_start, far = camera.clip_end;

    const PixelRect region = render_region_of(settings);
    const int margin = filter_margin(settings);
    grid_x0_ = region.x0 - margin;
    grid_y0_ = region.y0 - margin;
    coarse_.size = kTileSize;
    coarse_.nx = (region.width() + 2 * margin + kTileSize - 1) / kTileSize;
    coarse_.ny = (region.height() + 2 * margin + kTileSize - 1) / kTileSize;
    // The fine grid subdivides the coarse one exactly, so that a fine tile lies in one coarse tile.
    static_assert(kTileSize % kFineTileSize == 0, "fine tiles subdivide coarse tiles");
    fine_.size = kFineTileSize;
    fine_.nx = coarse_.nx * (kTileSize / kFineTileSize);
    fine_.ny = coarse_.ny * (kTileSize / kFineTileSize);
    const float grid_x1 = float(grid_x0_ + coarse_.nx * kTileSize), grid_y1 = float(grid_y0_ + coarse_.ny * kTileSize);
    // A packet's samples lie within this of its pixels' squares (jitter: the pixel filter's reach from the centre).
    sample_pad_ = settings.jitter
                      ? std::max(0.0f, PixelFilterSampler::reach(settings.pixel_filter, settings.filter_width) - 0.5f)
                      : 0.0f;

    // The camera ray's SH direction is camera -> centre (GaussianSet::display_color with the camera's origin).
    const bool display = settings.blend_space == BlendSpace::Display;
    const float lim_x = kJacobianClamp * proj.half_width_tan, lim_y = kJacobianClamp * proj.half_height_tan;

    // Projects Gaussian `prim` of `set`: false when it is culled (near, far, faint, degenerate, off the grid).
    auto project = [&](const GaussianSet& set, std::uint32_t prim, ProjectedSplat& out) {
        const GaussianPrimitive& g = set.prims[prim];
        if (!(g.opacity >= kMinAlpha)) return false;
        const glm::vec3 p = world_to_camera_ * (set.world_center(prim) - camera_origin_);
        const float z = -p.z;
        if (!(z > near && z < far)) return false;
        // Sigma = L L^T in the cloud's frame, L = M^-1 (M: rows 0..2 of the primitive, GaussianPrimitive), whose
        // columns are the Gaussian's axes times their scales.
        glm::mat3 m;
        m[0] = glm::vec3(g.row0.x, g.row1.x, g.row2.x);
        m[1] = glm::vec3(g.row0.y, g.row1.y, g.row2.y);
        m[2] = glm::vec3(g.row0.z, g.row1.z, g.row2.z);
        glm::mat3 l = glm::inverse(m);
        if (set.flat) {
            // A flat primitive's third row is its unit normal: its column of L is the unit axis, scaled here by the
            // Gaussian's smallest scale (as make_primitive clamps it), so that the footprint is the 3D Gaussian's, as
            // a viewer draws it, in either mode (the mode is the geometry rays trace).
            const float* s = &set.cloud->scales[3 * std::size_t(set.cloud_index[prim])];
            const float largest = std::max(s[0], std::max(s[1], s[2]));
            l[2] *= std::max(std::min(s[0], std::min(s[1], s[2])), 1e-6f * largest);
        }
        // The Jacobian of (X, Y, Z) -> (cx + fx X / z, cy - fy Y / z), z = -Z, at the centre (x/z, y/z clamped
        // about the frustum's centre, forward.cu computeCov2D).
        const float tx = std::clamp(p.x / z, proj.center_x_tan - lim_x, proj.center_x_tan + lim_x);
        const float ty = std::clamp(p.y / z, proj.center_y_tan - lim_y, proj.center_y_tan + lim_y);
        const glm::vec3 j0(fx_ / z, 0.0f, fx_ * tx / z), j1(0.0f, -fy_ / z, -fy_ * ty / z);
        // Rows of J W A (2 x 3), applied to L's columns: K = J W A L, Sigma' = K K^T.
        const glm::mat3 wa = world_to_camera_ * set.linear;
        const glm::vec3 r0 = glm::transpose(wa) * j0, r1 = glm::transpose(wa) * j1;
        double a = kDilation, b = 0.0, c = kDilation;
        for (int k = 0; k < 3; ++k) {
            const double k0 = glm::dot(r0, l[k]), k1 = glm::dot(r1, l[k]);
            a += k0 * k0;
            b += k0 * k1;
            c += k1 * k1;
        }
        const double det = a * c - b * b;
        if (!(det > 0.0) || !std::isfinite(det)) return false;
        const double mid = 0.5 * (a + c);
        const double lambda_max = mid + std::sqrt(std::max(0.1, mid * mid - det));
        const float half = float(kFootprintSigmas * std::sqrt(lambda_max));
        const float u = cx_ + fx_ * p.x / z, v = cy_ - fy_ * p.y / z;
        if (!(u + half >= float(grid_x0_) && u - half < grid_x1 && v + half >= float(grid_y0_) && v - half < grid_y1))
            return false;
        out.u = u;
        out.v = v;
        out.conic[0] = float(c / det);
        out.conic[1] = float(-b / det);
        out.conic[2] = float(a / det);
        out.opacity = g.opacity;
        out.depth = z;
        out.half_extent = half;
        out.least_power = std::log(kMinAlpha / g.opacity) - 1e-3f;
        return true;
    };

    // Every Gaussian of the scene has a global index: primitive j of set k is set_base[k] + j.
    std::vector<std::size_t> set_base(s_.gaussians.size() + 1, 0);
    for (std::size_t k = 0; k < s_.gaussians.size(); ++k) set_base[k + 1] = set_base[k] + s_.gaussians[k]->prims.size();
    const std::size_t total = set_base.back();
    if (total >= std::size_t(kNotVisible))
        throw Error("camera-ray splatting: " + std::to_string(total) + " Gaussians are more than it indexes (2^32 - 1)");

    // 1. The visible Gaussians' keys, depth above global index (positive floats order as their bit patterns; ties go
    // by scene order), sorted.
    std::vector<std::uint64_t> keys(total, kNotVisibleKey);
    for (std::size_t k = 0; k < s_.gaussians.size(); ++k) {
        const GaussianSet& set = *s_.gaussians[k];
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, set.prims.size(), 4096),
                          [&](const tbb::blocked_range<std::size_t>& r) {
                              if (cancelled()) return;
                              for (std::size_t j = r.begin(); j != r.end(); ++j) {
                                  ProjectedSplat ps;
                                  if (!project(set, std::uint32_t(j), ps)) continue;
                                  std::uint32_t depth_bits;
                                  std::memcpy(&depth_bits, &ps.depth, sizeof depth_bits);
                                  keys[set_base[k] + j] = std::uint64_t(depth_bits) << 32 | (set_base[k] + j);
                              }
                          });
    }
    if (cancelled()) return;
    keys.erase(std::remove(keys.begin(), keys.end(), kNotVisibleKey), keys.end());
    tbb::parallel_sort(keys.begin(), keys.end());
    if (cancelled()) return;

    // 2. The splats in depth order, with their colours (the same for every camera sample). Written in the scene's
    // order, each to its rank: the Gaussians' data (SH up to 192 bytes each) is read in order, not at random.
    std::vector<std::uint32_t> rank_of(total, kNotVisible);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, keys.size(), 4096), [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i) rank_of[keys[i] & 0xffffffffu] = std::uint32_t(i);
    });
    splats_.resize(keys.size());
    sources_.resize(keys.size());
    keys.clear();
    keys.shrink_to_fit();
    const glm::vec3 origin = camera_origin_;
    for (std::size_t k = 0; k < s_.gaussians.size(); ++k) {
        const GaussianSet& set = *s_.gaussians[k];
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, set.prims.size(), 4096),
                          [&](const tbb::blocked_range<std::size_t>& r) {
                              if (cancelled()) return;
                              for (std::size_t j = r.begin(); j != r.end(); ++j) {
                                  const std::uint32_t rank = rank_of[set_base[k] + j];
                                  if (rank == kNotVisible) continue;
                                  const auto prim = std::uint32_t(j);
                                  ProjectedSplat& splat = splats_[rank];
                                  project(set, prim, splat);
                                  splat.color = display ? set.display_color(prim, origin) : set.color(prim, origin);
                                  sources_[rank] = SplatSource{set.index, prim};
                              }
                          });
    }
    if (cancelled()) return;

    // 3. Tile lists, two levels. A 4 x 4 packet of camera rays reads the list of its 16 px tile, and in a zoomed-out
    // view of a big scene that list holds thousands of splats of a pixel or two, of which the packet's sixteenth of the
    // tile meets a few percent, so splatting such a view cost several times the traced render. Small splats therefore
    // go into lists of the packets' own 4 px tiles; big ones stay in 16 px lists, where they cost 16x fewer entries
    // (4 px tiles alone multiply a big splat's entries, and the pre-pass with them). A packet merges its two lists.
    std::vector<std::uint8_t> level(splats_.size());
    for (std::size_t i = 0; i < splats_.size(); ++i) level[i] = splats_[i].half_extent <= kFineSplatMaxHalfExtent;
    bin(coarse_, level, 0, cancel);
    if (cancelled()) return;
    bin(fine_, level, 1, cancel);
}

void CameraSplatting::bin(TileLists& lists, const std::vector<std::uint8_t>& level, std::uint8_t which,
                          const std::atomic<bool>* cancel) {
    auto cancelled = [cancel] { return cancel && cancel->load(std::memory_order_relaxed); };
    const std::size_t tile_count = std::size_t(lists.nx) * std::size_t(lists.ny);
    const int size = lists.size;
    // The tiles a splat can draw in: those whose samples its square reaches where alpha can reach 1/255, i.e. where
    // q(d) = d^T Sigma'^-1 d <= 2 ln(255 a) (a exp(-q / 2) >= 1/255) somewhere on the tile widened by the samples'
    // pad. Outside that ellipse every sample skips the splat anyway, so leaving it out of those tiles changes no image;
    // it keeps thin and faint Gaussians out of most of their square's tiles. The pad lets a packet read only the lists
    // of its pixels' tile, wherever jitter put its samples (a list per tile a sample fell in cost a packet 2-4 reads).
    const double pad = sample_pad_ + 1e-3;  // (and a margin for rounding)
    auto for_each_tile = [&](const ProjectedSplat& ps, auto&& visit) {
        const float reach_x = ps.half_extent + float(pad);
        const int tx0 = std::max(0, int(std::floor((ps.u - reach_x - float(grid_x0_)) / size)));
        const int ty0 = std::max(0, int(std::floor((ps.v - reach_x - float(grid_y0_)) / size)));
        const int tx1 = std::min(lists.nx - 1, int(std::floor((ps.u + reach_x - float(grid_x0_)) / size)));
        const int ty1 = std::min(lists.ny - 1, int(std::floor((ps.v + reach_x - float(grid_y0_)) / size)));
        // (A margin for rounding: a sample whose alpha rounds up to 1/255 must find the splat in its tile.)
        const double reach = 2.0 * std::log(255.0 * double(ps.opacity)) * 1.001 + 1e-3;
        const double a = ps.conic[0], b = ps.conic[1], c = ps.conic[2];
        auto q = [&](double dx, double dy) { return a * dx * dx + 2.0 * b * dx * dy + c * dy * dy; };
        for (int ty = ty0; ty <= ty1; ++ty) {
            const double ly = double(grid_y0_ + ty * size) - ps.v - pad, hy = ly + size + 2.0 * pad;
            for (int tx = tx0; tx <= tx1; ++tx) {
                const double lx = double(grid_x0_ + tx * size) - ps.u - pad, hx = lx + size + 2.0 * pad;
                // The minimum of the convex q over the tile: 0 when the centre is inside, else on an edge, where q is
                // a parabola in the free coordinate (minimised at -b x / c, or -b y / a, clamped to the edge).
                double least = 0.0;
                if (!(lx <= 0.0 && 0.0 <= hx && ly <= 0.0 && 0.0 <= hy)) {
                    least = std::min(std::min(q(lx, std::clamp(-b * lx / c, ly, hy)), q(hx, std::clamp(-b * hx / c, ly, hy))),
                                     std::min(q(std::clamp(-b * ly / a, lx, hx), ly), q(std::clamp(-b * hy / a, lx, hx), hy)));
                }
                if (least <= reach) visit(std::size_t(ty) * lists.nx + tx);
            }
        }
    };
    // A counting sort by tile that keeps the depth order: the splats in chunks of consecutive ranks, each chunk's
    // count per tile, every chunk's start in every list (the lists' offsets plus the counts of the chunks before it),
    // and each chunk fills its splats in rank order from its starts. No atomics, and no list needs sorting after (a
    // zoomed-out view of showroom_1.5M puts 8 M entries in a few hundred tiles, where atomic counters and a sort per
    // list were most of the pre-pass).
    // A cancel (the viewport stops its jobs on the UI thread before an edit reaches the scene) is seen within this
    // many splats of a chunk, since binning a scene of ten million splats takes the order of a second on one thread.
    constexpr std::size_t kCancelCheckInterval = 4096;
    const std::size_t chunks = std::clamp<std::size_t>(splats_.size() / 256, 1, 16);
    const std::size_t chunk_size = (splats_.size() + chunks - 1) / chunks;
    std::vector<std::uint32_t> starts(chunks * tile_count, 0);  // chunk k's count, then its cursor, in tile t: [k * tile_count + t]
    tbb::parallel_for(std::size_t(0), chunks, [&](std::size_t k) {
        std::uint32_t* count = starts.data() + k * tile_count;
        for (std::size_t i = k * chunk_size, end = std::min(splats_.size(), i + chunk_size); i < end; ++i) {
            if (i % kCancelCheckInterval == 0 && cancelled()) return;
            if (level[i] == which) for_each_tile(splats_[i], [&](std::size_t t) { ++count[t]; });
        }
    });
    if (cancelled()) return;
    lists.offsets.assign(tile_count + 1, 0);
    for (std::size_t t = 0; t < tile_count; ++t) {
        std::uint64_t at = lists.offsets[t];
        for (std::size_t k = 0; k < chunks; ++k) {
            const std::uint32_t n = starts[k * tile_count + t];
            starts[k * tile_count + t] = std::uint32_t(at - lists.offsets[t]);  // (within the list: fits 32 bits)
            at += n;
        }
        lists.offsets[t + 1] = at;
    }
    lists.entries.resize(lists.offsets[tile_count]);
    tbb::parallel_for(std::size_t(0), chunks, [&](std::size_t k) {
        std::uint32_t* cursor = starts.data() + k * tile_count;
        for (std::size_t i = k * chunk_size, end = std::min(splats_.size(), i + chunk_size); i < end; ++i) {
            if (i % kCancelCheckInterval == 0 && cancelled()) return;  // (the lists unfinished: nothing renders)
            if (level[i] == which)
                for_each_tile(splats_[i], [&](std::size_t t) {
                    lists.entries[lists.offsets[t] + cursor[t]++] = std::uint32_t(i);
                });
        }
    });
}

std::size_t CameraSplatting::memory_bytes() const {
    std::size_t bytes = splats_.capacity() * sizeof(ProjectedSplat) + sources_.capacity() * sizeof(SplatSource);
    for (const TileLists* lists : {&coarse_, &fine_})
        bytes += lists->entries.capacity() * sizeof(std::uint32_t) + lists->offsets.capacity() * sizeof(std::uint64_t);
    return bytes;
}

std::size_t CameraSplatting::TileLists::tile_of(float x, float y, int x0, int y0) const {
    const int tx = std::clamp(int(std::floor((x - float(x0)) / size)), 0, nx - 1);
    const int ty = std::clamp(int(std::floor((y - float(y0)) / size)), 0, ny - 1);
    return std::size_t(ty) * nx + tx;
}

inline void CameraSplatting::composite(std::size_t fine_tile, std::uint32_t lanes, const Ray* rays, const float* xs,
                                       const float* ys, const float* mesh_depth, Sampler* rngs, Segment* segs,
                                       Counters& c) const {
    const bool display = st_.blend_space == BlendSpace::Display;
    // The box of the packet's sample positions: a splat whose square misses it is skipped with four comparisons
    // instead of one per lane. A 4 x 4 packet covers a sixteenth of a 16 px tile, and a zoomed-out view of a big scene
    // has thousands of small splats per tile list (showroom_1.5M whole at 640 x 360, 128 samples: the F12 took 7.5x
    // the traced render's time before this test).
    // With it, the lanes' samples and mesh depths, lanes not in `lanes` far off the image and in front of everything.
    float x0 = std::numeric_limits<float>::infinity(), y0 = x0, x1 = -x0, y1 = -x0;
    alignas(16) float px[16], py[16], pz[16];
    for (int l = 0; l < 16; ++l) {
        px[l] = py[l] = -1e15f;
        pz[l] = -kInf;
    }
    for (std::uint32_t live = lanes; live; live &= live - 1) {
        const int l = __builtin_ctz(live);
        x0 = std::min(x0, xs[l]);
        x1 = std::max(x1, xs[l]);
        y0 = std::min(y0, ys[l]);
        y1 = std::max(y1, ys[l]);
        px[l] = xs[l];
        py[l] = ys[l];
        pz[l] = mesh_depth[l];
    }
    // The coarse tile holding the fine one, and the two lists' ranges; a splat is in one level, so merging them by
    // rank (= depth order) visits each splat once, front to back.
    constexpr int kPerCoarse = kTileSize / kFineTileSize;
    const std::size_t fx = fine_tile % std::size_t(fine_.nx), fy = fine_tile / std::size_t(fine_.nx);
    const std::size_t tile = fy / kPerCoarse * std::size_t(coarse_.nx) + fx / kPerCoarse;
    const std::uint32_t* coarse = coarse_.entries.data() + coarse_.offsets[tile];
    const std::uint32_t* const coarse_end = coarse_.entries.data() + coarse_.offsets[tile + 1];
    const std::uint32_t* fine = fine_.entries.data() + fine_.offsets[fine_tile];
    const std::uint32_t* const fine_end = fine_.entries.data() + fine_.offsets[fine_tile + 1];
    // The splats are in depth order, so a tile's are scattered over the whole array: each read misses the cache. They
    // are fetched kPrefetch entries ahead of their turn in either list.
    constexpr std::ptrdiff_t kPrefetch = 8;
    for (std::ptrdiff_t k = 0; k < kPrefetch; ++k) {
        if (coarse + k < coarse_end) __builtin_prefetch(&splats_[coarse[k]]);
        if (fine + k < fine_end) __builtin_prefetch(&splats_[fine[k]]);
    }
    while (lanes && (coarse != coarse_end || fine != fine_end)) {
        const bool take_fine = coarse == coarse_end || (fine != fine_end && *fine < *coarse);
        const std::uint32_t index = take_fine ? *fine++ : *coarse++;
        if (take_fine ? fine + kPrefetch - 1 < fine_end : coarse + kPrefetch - 1 < coarse_end)
            __builtin_prefetch(&splats_[take_fine ? fine[kPrefetch - 1] : coarse[kPrefetch - 1]]);
        ++c.group_candidates;
        const ProjectedSplat& ps = splats_[index];
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
            const float alpha = std::min(kMaxAlpha, ps.opacity * std::exp(power[l]));
            if (alpha < kMinAlpha) continue;
            glm::vec3 color = ps.color;
            if (st_.meshes_shadow_gaussians) {
                // As GaussianSegmentTracer::gaussian_color: the lights' visibility v from the centre scales linear
                // light.
                const SplatSource& source = sources_[index];
                const float vis = shadow_.gaussian_light_visibility(
                    s_.gaussians[source.set]->world_center(source.prim), rngs[l], c);
                if (!display) color *= vis;
                else if (vis < 1.0f)
                    for (int ch = 0; ch < 3; ++ch) color[ch] = linear_to_srgb(vis * srgb_to_linear(color[ch]));
            }
            Segment& seg = segs[l];
            const float t_before = seg.transmittance;
            seg.radiance += t_before * alpha * color;
            seg.transmittance = t_before * (1.0f - alpha);
            ++seg.gaussians;
            ++c.gaussian_hits;
            const bool opaque_here = t_before > 0.5f && seg.transmittance <= 0.5f;
            const bool stop = seg.transmittance < st_.transmittance_threshold;
            if (opaque_here || stop) {
                // The point of the ray nearest the centre stands for the splat's place along the ray.
                const SplatSource& source = sources_[index];
                const GaussianSet& set = *s_.gaussians[source.set];
                const Ray& ray = rays[l];
                const float along = glm::dot(set.world_center(source.prim) - ray.o, ray.d);
                if (opaque_here) {
                    seg.depth = along;
                    const glm::vec3 n = set.flat ? set.world_normal(source.prim) : -ray.d;
                    seg.normal = glm::dot(n, ray.d) > 0.0f ? -n : n;
                }
                if (stop) {
                    seg.terminated = true;
                    seg.end = along;
                    lanes &= ~(1u << l);
                }
            }
        }
    }
}

void CameraSplatting::trace_packet(int packet_x, int packet_y, const Ray* rays, const bool* active, const float* xs,
                                   const float* ys, Sampler* rngs, Segment* segs, Counters& c) const {
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
        // Gaussians are ignored (MeshesOnly); rays come back in the packet's order on every Embree path.
        TraceContext ctx(lanes, 16, TraceMode::MeshesOnly);
        ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
        rtcIntersect16(valid, s_.scene, &ctx, &rh);
    }
    float mesh_depth[16];
    std::size_t tiles[16];
    std::uint32_t pending = 0;  // lanes whose tile is not composited yet
    for (int l = 0; l < 16; ++l) {
        if (!active[l]) continue;
        const bool mesh = any_mesh && rh.hit.geomID[l] != RTC_INVALID_GEOMETRY_ID;
        if (any_mesh) ++c.traced;
        mesh_depth[l] = mesh ? view_depth(rays[l].o + rh.ray.tfar[l] * rays[l].d) : kInf;
        // The tile of the lane's pixel, not of its sample: the lists are binned for every sample of their pixels.
        tiles[l] = fine_.tile_of(float(packet_x + (l & 3)) + 0.5f, float(packet_y + (l >> 2)) + 0.5f, grid_x0_, grid_y0_);
        pending |= 1u << l;
    }
    // The lanes of one fine tile together: all 16, unless a tile size that is not a multiple of 4 misaligned the packet.
    while (pending && !fine_.offsets.empty()) {  // (no offsets: the pre-pass was cancelled)
        const std::size_t tile = tiles[__builtin_ctz(pending)];
        std::uint32_t group = 0;
        for (std::uint32_t p = pending; p; p &= p - 1)
            if (tiles[__builtin_ctz(p)] == tile) group |= 1u << __builtin_ctz(p);
        composite(tile, group, rays, xs, ys, mesh_depth, rngs, segs, c);
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
