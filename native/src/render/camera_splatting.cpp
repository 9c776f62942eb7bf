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
#include "raysplats/errors.h"

namespace raysplats {

namespace {

constexpr float kDilation = 0.3f;           // px^2 added to the 2D covariance's diagonal (3DGS computeCov2D)
constexpr float kJacobianClamp = 1.3f;      // x/z and y/z clamped to 1.3 x the frustum's half extent (3DGS)
constexpr float kFootprintSigmas = 3.0f;    // square half side in standard deviations (3DGS getRect's radius)

// Pixels of the pixel filter's reach around a pixel (pixel_filter.h: box w / 2, Gaussian 3 w / 2, Blackman-Harris w),
// rounded up, plus one: camera samples fall within it. A multiple of 4, so that the render loop's 4 x 4 packets of
// pixels (from the region's corner) each lie in one tile.
int filter_margin(const RenderSettings& st) {
    const int reach = (st.jitter ? int(std::ceil(1.5f * st.filter_width)) : 0) + 1;
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
    tiles_x_ = (region.width() + 2 * margin + kTileSize - 1) / kTileSize;
    tiles_y_ = (region.height() + 2 * margin + kTileSize - 1) / kTileSize;
    const float grid_x1 = float(grid_x0_ + tiles_x_ * kTileSize), grid_y1 = float(grid_y0_ + tiles_y_ * kTileSize);

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
    shades_.resize(keys.size());
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
                                  project(set, prim, splats_[rank]);
                                  SplatShade& shade = shades_[rank];
                                  shade.color = display ? set.display_color(prim, origin) : set.color(prim, origin);
                                  shade.set = set.index;
                                  shade.prim = prim;
                              }
                          });
    }
    if (cancelled()) return;

    // 3. Tile lists: count, offsets, fill, and each list back in depth order.
    const std::size_t tile_count = std::size_t(tiles_x_) * std::size_t(tiles_y_);
    // The tiles a splat can draw in: those its square touches where alpha can reach 1/255, i.e. where
    // q(d) = d^T Sigma'^-1 d <= 2 ln(255 a) (a exp(-q / 2) >= 1/255) somewhere on the tile. Outside that ellipse every
    // sample skips the splat anyway, so leaving it out of those tiles changes no image; it keeps thin and faint
    // Gaussians out of most of their square's tiles.
    auto for_each_tile = [&](const ProjectedSplat& ps, auto&& visit) {
        const int tx0 = std::max(0, int(std::floor((ps.u - ps.half_extent - float(grid_x0_)) / kTileSize)));
        const int ty0 = std::max(0, int(std::floor((ps.v - ps.half_extent - float(grid_y0_)) / kTileSize)));
        const int tx1 = std::min(tiles_x_ - 1, int(std::floor((ps.u + ps.half_extent - float(grid_x0_)) / kTileSize)));
        const int ty1 = std::min(tiles_y_ - 1, int(std::floor((ps.v + ps.half_extent - float(grid_y0_)) / kTileSize)));
        // (A margin for rounding: a sample whose alpha rounds up to 1/255 must find the splat in its tile.)
        const double reach = 2.0 * std::log(255.0 * double(ps.opacity)) * 1.001 + 1e-3;
        const double a = ps.conic[0], b = ps.conic[1], c = ps.conic[2];
        auto q = [&](double dx, double dy) { return a * dx * dx + 2.0 * b * dx * dy + c * dy * dy; };
        for (int ty = ty0; ty <= ty1; ++ty) {
            const double ly = double(grid_y0_ + ty * kTileSize) - ps.v, hy = ly + kTileSize;
            for (int tx = tx0; tx <= tx1; ++tx) {
                const double lx = double(grid_x0_ + tx * kTileSize) - ps.u, hx = lx + kTileSize;
                // The minimum of the convex q over the tile: 0 when the centre is inside, else on an edge, where q is
                // a parabola in the free coordinate (minimised at -b x / c, or -b y / a, clamped to the edge).
                double least = 0.0;
                if (!(lx <= 0.0 && 0.0 <= hx && ly <= 0.0 && 0.0 <= hy)) {
                    least = std::min(std::min(q(lx, std::clamp(-b * lx / c, ly, hy)), q(hx, std::clamp(-b * hx / c, ly, hy))),
                                     std::min(q(std::clamp(-b * ly / a, lx, hx), ly), q(std::clamp(-b * hy / a, lx, hx), hy)));
                }
                if (least <= reach) visit(std::size_t(ty) * tiles_x_ + tx);
            }
        }
    };
    std::vector<std::atomic<std::uint32_t>> counts(tile_count);
    for (auto& n : counts) n.store(0, std::memory_order_relaxed);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, splats_.size(), 4096), [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i)
            for_each_tile(splats_[i], [&](std::size_t t) { counts[t].fetch_add(1, std::memory_order_relaxed); });
    });
    if (cancelled()) return;
    offsets_.assign(tile_count + 1, 0);
    for (std::size_t t = 0; t < tile_count; ++t) offsets_[t + 1] = offsets_[t] + counts[t].load(std::memory_order_relaxed);
    entries_.resize(offsets_[tile_count]);
    for (std::size_t t = 0; t < tile_count; ++t) counts[t].store(0, std::memory_order_relaxed);  // the fill cursors
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, splats_.size(), 4096), [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i)
            for_each_tile(splats_[i], [&](std::size_t t) {
                entries_[offsets_[t] + counts[t].fetch_add(1, std::memory_order_relaxed)] = std::uint32_t(i);
            });
    });
    if (cancelled()) return;
    // Filled in any order by the threads: sorting each list's indices restores the depth order (deterministic).
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, tile_count, 1), [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t t = r.begin(); t != r.end(); ++t)
            std::sort(entries_.begin() + std::ptrdiff_t(offsets_[t]), entries_.begin() + std::ptrdiff_t(offsets_[t + 1]));
    });
}

std::size_t CameraSplatting::memory_bytes() const {
    return splats_.capacity() * sizeof(ProjectedSplat) + shades_.capacity() * sizeof(SplatShade) +
           entries_.capacity() * sizeof(std::uint32_t) +
           offsets_.capacity() * sizeof(std::uint64_t);
}

std::size_t CameraSplatting::tile_of(float x, float y) const {
    const int tx = std::clamp(int(std::floor((x - float(grid_x0_)) / kTileSize)), 0, tiles_x_ - 1);
    const int ty = std::clamp(int(std::floor((y - float(grid_y0_)) / kTileSize)), 0, tiles_y_ - 1);
    return std::size_t(ty) * tiles_x_ + tx;
}

inline void CameraSplatting::composite(std::size_t tile, std::uint32_t lanes, const Ray* rays, const float* xs,
                                       const float* ys, const float* mesh_depth, Sampler* rngs, Segment* segs,
                                       Counters& c) const {
    const bool display = st_.blend_space == BlendSpace::Display;
    // The box of the packet's sample positions: a splat whose square misses it is skipped with four comparisons
    // instead of one per lane. A 4 x 4 packet covers a sixteenth of a 16 px tile, and a zoomed-out view of a big scene
    // has thousands of small splats per tile list (showroom_1.5M whole at 640 x 360, 128 samples: the F12 took 7.5x
    // the traced render's time before this test).
    float x0 = std::numeric_limits<float>::infinity(), y0 = x0, x1 = -x0, y1 = -x0;
    for (std::uint32_t live = lanes; live; live &= live - 1) {
        const int l = __builtin_ctz(live);
        x0 = std::min(x0, xs[l]);
        x1 = std::max(x1, xs[l]);
        y0 = std::min(y0, ys[l]);
        y1 = std::max(y1, ys[l]);
    }
    for (std::uint64_t e = offsets_[tile]; e < offsets_[tile + 1] && lanes; ++e) {
        const std::uint32_t index = entries_[e];
        const ProjectedSplat& ps = splats_[index];
        if (ps.u + ps.half_extent < x0 || ps.u - ps.half_extent > x1 || ps.v + ps.half_extent < y0 ||
            ps.v - ps.half_extent > y1)
            continue;
        for (std::uint32_t live = lanes; live; live &= live - 1) {
            const int l = __builtin_ctz(live);
            if (!(ps.depth < mesh_depth[l])) {  // the list is front to back: this lane is done
                lanes &= ~(1u << l);
                continue;
            }
            const float dx = xs[l] - ps.u, dy = ys[l] - ps.v;
            if (std::abs(dx) > ps.half_extent || std::abs(dy) > ps.half_extent) continue;
            const float power = -0.5f * (ps.conic[0] * dx * dx + ps.conic[2] * dy * dy) - ps.conic[1] * dx * dy;
            if (power > 0.0f) continue;
            const float alpha = std::min(kMaxAlpha, ps.opacity * std::exp(power));
            if (alpha < kMinAlpha) continue;
            const SplatShade& shade = shades_[index];
            const GaussianSet& set = *s_.gaussians[shade.set];
            glm::vec3 color = shade.color;
            if (st_.meshes_shadow_gaussians) {
                // As GaussianSegmentTracer::gaussian_color: the lights' visibility v from the centre scales linear
                // light.
                const float vis = shadow_.gaussian_light_visibility(set.world_center(shade.prim), rngs[l], c);
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
                const Ray& ray = rays[l];
                const float along = glm::dot(set.world_center(shade.prim) - ray.o, ray.d);
                if (opaque_here) {
                    seg.depth = along;
                    const glm::vec3 n = set.flat ? set.world_normal(shade.prim) : -ray.d;
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

void CameraSplatting::trace_packet(const Ray* rays, const bool* active, const float* xs, const float* ys,
                                   Sampler* rngs, Segment* segs, Counters& c) const {
    for (int l = 0; l < 16; ++l) segs[l] = Segment{};
    // The first mesh hit of each ray (Gaussians ignored), as a packet.
    RTCRayHit16 rh;
    alignas(64) int valid[16];
    LaneState lanes[16];
    bool any_mesh = !s_.meshes.empty();
    for (int l = 0; l < 16 && any_mesh; ++l) {
        const Ray& r = rays[l];
        valid[l] = active[l] ? -1 : 0;
        set_packet_lane(rh, l, r, r.tmax);
    }
    if (any_mesh) {
        TraceContext ctx(lanes, TraceMode::MeshesOnly);
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
        tiles[l] = tile_of(xs[l], ys[l]);
        pending |= 1u << l;
    }
    // The lanes of one tile together (all 16, unless jitter carried some samples over a tile's edge).
    while (pending && !offsets_.empty()) {  // (no offsets: the pre-pass was cancelled)
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
