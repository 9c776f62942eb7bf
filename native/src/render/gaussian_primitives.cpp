#include "gaussian_primitives.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstring>
#include <limits>

#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include "core/linear_algebra.h"
#include "core/morton_order.h"
#include "raysplats/spherical_harmonics.h"
#include "render_math.h"

namespace raysplats {
namespace {

// Squared Mahalanobis radius of a Gaussian's support: 3, tightened to where a * G reaches 1/255 (hits below are
// skipped anyway): a exp(-r^2 / 2) = 1/255  <=>  r^2 = 2 ln(255 a). Not positive when it never reaches 1/255.
float support_sq(float opacity) { return std::min(kGaussianSupportSq, 2.0f * std::log(255.0f * opacity)); }

// Axis-aligned box of a Gaussian's support; false when it can never reach kMinAlpha.
bool gaussian_box(const GaussianPrimitive& g, bool flat, glm::vec3& lower, glm::vec3& upper) {
    // Columns of M^-1 (M = rows 0..2) are the world-space axes scaled by the standard deviations; for flat
    // Gaussians columns 0 and 1 span the disk (row 2 is orthogonal to both by construction).
    glm::mat3 m;
    m[0] = glm::vec3(g.row0.x, g.row1.x, g.row2.x);
    m[1] = glm::vec3(g.row0.y, g.row1.y, g.row2.y);
    m[2] = glm::vec3(g.row0.z, g.row1.z, g.row2.z);  // glm is column-major: m[c][r] = row r, column c
    const glm::mat3 l = glm::inverse(m);
    // Gaussians that never reach 1/255 get no box and are left out of every group.
    const float r2 = g.support_sq;
    if (!(r2 > 0.0f)) return false;
    const float radius = std::sqrt(r2);
    glm::vec3 half;
    for (int j = 0; j < 3; ++j) {
        float s = l[0][j] * l[0][j] + l[1][j] * l[1][j];
        if (!flat) s += l[2][j] * l[2][j];
        half[j] = radius * std::sqrt(s);
    }
    if (!std::isfinite(half.x + half.y + half.z)) half = glm::vec3(0.0f);  // degenerate: never hit anyway
    lower = g.center - half;
    upper = g.center + half;
    return true;
}

float half_area(const glm::vec3& lower, const glm::vec3& upper) {
    const glm::vec3 e = upper - lower;
    return e.x * e.y + e.y * e.z + e.z * e.x;
}

}  // namespace

void GaussianGroups::assign(const std::vector<Width>& widths) {
    size_ = widths.size();
    blocks_.assign((size_ + 63) / 64, Block{});
    std::uint32_t wide_count = 0, quad_count = 0;
    for (std::size_t b = 0; b < blocks_.size(); ++b) {
        Block& block = blocks_[b];
        block.wide_before = wide_count;
        block.quads_before = quad_count;
        for (std::size_t i = 64 * b; i < std::min(size_, 64 * b + 64); ++i) {
            const std::uint64_t bit = std::uint64_t(1) << (i & 63u);
            if (widths[i] == Width::Eight) block.wide |= bit, ++wide_count;
            if (widths[i] == Width::Four) block.quads |= bit, ++quad_count;
        }
    }
    // (clear first: resize would copy the old groups into a new allocation, writing pages the fill writes again.)
    singles.clear();
    quads.clear();
    wide.clear();
    singles.resize(size_ - wide_count - quad_count);
    quads.resize(quad_count);
    wide.resize(wide_count);
}

void GaussianSet::set_transform(const Matrix4& m) {
    object_to_world = m;
    linear = linear_part(m);
    translation = translation_part(m);
    world_to_object_dir = glm::inverse(linear);
    normal_matrix = glm::transpose(world_to_object_dir);
}

namespace {

// The axes of scales s[0..2] from the largest scale to the smallest: the primitive's rows 0, 1 and 2.
void order_by_scale(const float* s, int order[3]) {
    order[0] = 0, order[1] = 1, order[2] = 2;
    std::sort(order, order + 3, [&](int l, int r2) { return s[l] > s[r2]; });
}

// The primitive of Gaussian i of a cloud (see GaussianPrimitive).
GaussianPrimitive make_primitive(const GaussianCloud& c, std::size_t i, bool flat) {
    const float* q = &c.rotations[4 * i];
    glm::vec4 qq(q[0], q[1], q[2], q[3]);
    const float qn = glm::length(qq);
    qq = qn > 0.0f ? qq / qn : glm::vec4(1, 0, 0, 0);
    const float w = qq[0], x = qq[1], y = qq[2], z = qq[3];
    // Columns of R: the Gaussian's axes.
    const std::array<float, 9> r = la::quaternion_to_rotation(w, x, y, z);
    const glm::vec3 axis[3] = {{r[0], r[3], r[6]}, {r[1], r[4], r[7]}, {r[2], r[5], r[8]}};
    const float* s = &c.scales[3 * i];
    int order[3];
    order_by_scale(s, order);
    const float smax = std::max(s[order[0]], 1e-30f);
    auto inv_scale = [&](int k) { return 1.0f / std::max(s[k], 1e-6f * smax); };
    GaussianPrimitive g;
    g.center = glm::vec3(c.positions[3 * i], c.positions[3 * i + 1], c.positions[3 * i + 2]);
    g.opacity = std::min(std::max(c.opacities[i], 0.0f), 1.0f);
    g.row0 = axis[order[0]] * inv_scale(order[0]);
    g.row1 = axis[order[1]] * inv_scale(order[1]);
    g.row2 = flat ? axis[order[2]] : axis[order[2]] * inv_scale(order[2]);
    g.cloud_index = std::uint32_t(i);
    g.thin_scale = std::max(std::min(s[0], std::min(s[1], s[2])), 1e-6f * std::max(s[0], std::max(s[1], s[2])));
    g.support_sq = support_sq(g.opacity);
    return g;
}

}  // namespace

std::vector<char> GaussianSet::prepare(GaussianMode mode, bool keep_order) {
    const bool was_flat = flat;
    flat = mode == GaussianMode::Flat;
    const GaussianCloud& c = *cloud;
    const std::size_t n = c.size();
    keep_order = keep_order && cloud_index.size() == n && was_flat == flat;
    const std::size_t chunk_count = (n + std::size_t(chunk_size) - 1) / std::size_t(chunk_size);
    std::vector<std::atomic<bool>> chunk_changed(chunk_count);
    for (auto& f : chunk_changed) f = !keep_order;
    prims.resize(n);
    const bool deg0 = c.sh_degree == 0;
    if (deg0) {
        linear_rgb.resize(3 * n);
        display_rgb.resize(3 * n);
    } else {
        linear_rgb.clear();
        display_rgb.clear();
    }
    if (!keep_order) {
        cloud_index = morton_order(c);
        prim_index.resize(n);
        for (std::size_t j = 0; j < n; ++j) prim_index[cloud_index[j]] = std::uint32_t(j);
    }

    // In the cloud's order, each primitive written to its place: the cloud's arrays are read in order and one cache
    // line written at random, where the Morton order read four or five arrays at random.
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 4096), [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i) {
            const std::uint32_t j = prim_index[i];
            const GaussianPrimitive g = make_primitive(c, i, flat);
            if (keep_order && std::memcmp(&g, &prims[j], sizeof(g)) != 0)
                chunk_changed[j / std::size_t(chunk_size)].store(true, std::memory_order_relaxed);
            prims[j] = g;
            if (deg0) store_linear_rgb(j, i);
        }
    });
    std::vector<char> changed(chunk_count);
    for (std::size_t k = 0; k < chunk_count; ++k) changed[k] = chunk_changed[k].load();
    return changed;
}

std::vector<char> GaussianSet::prepare_rows(const std::vector<std::uint32_t>& rows) {
    const GaussianCloud& c = *cloud;
    std::vector<char> changed((c.size() + std::size_t(chunk_size) - 1) / std::size_t(chunk_size), 0);
    for (const std::uint32_t i : rows) {
        const std::uint32_t j = prim_index[i];
        const GaussianPrimitive g = make_primitive(c, i, flat);
        if (std::memcmp(&g, &prims[j], sizeof(g)) != 0) changed[j / chunk_size] = 1;
        prims[j] = g;
        if (!linear_rgb.empty()) store_linear_rgb(j, i);
    }
    return changed;
}

void GaussianSet::store_linear_rgb(std::uint32_t j, std::size_t i) {
    const float* dc = &cloud->sh[3 * i];
    for (int ch = 0; ch < 3; ++ch) {
        display_rgb[3 * j + ch] = std::max(0.0f, sh_dc_to_display_single(dc[ch]));
        linear_rgb[3 * j + ch] = srgb_to_linear(display_rgb[3 * j + ch]);
    }
}

glm::vec3 GaussianSet::display_color(std::uint32_t i, const glm::vec3& origin) const {
    if (!display_rgb.empty()) return {display_rgb[3 * i], display_rgb[3 * i + 1], display_rgb[3 * i + 2]};
    // Reference 3DGS: the SH are evaluated in the direction from the camera (ray origin) to the centre, here in
    // the cloud's frame: A^-1 (A c + b - o) = c - A^-1 (o - b).
    glm::vec3 dir = prims[i].center - world_to_object_dir * (origin - translation);
    const float len = glm::length(dir);
    dir = len > 0.0f ? dir / len : glm::vec3(0, 0, 1);
    const int k = cloud->coeffs_per_channel();
    const auto rgb = evaluate_sh(cloud->sh_degree, &cloud->sh[std::size_t(cloud_index[i]) * k * 3], dir.x, dir.y, dir.z);
    return {rgb[0], rgb[1], rgb[2]};
}

glm::vec3 GaussianSet::color(std::uint32_t i, const glm::vec3& origin) const {
    if (!linear_rgb.empty()) return {linear_rgb[3 * i], linear_rgb[3 * i + 1], linear_rgb[3 * i + 2]};
    const glm::vec3 rgb = display_color(i, origin);
    return {srgb_to_linear(rgb[0]), srgb_to_linear(rgb[1]), srgb_to_linear(rgb[2])};
}

// Greedy over the chunk's Gaussians in Morton order, in independent blocks of 4096 (parallel, deterministic): a
// group takes the next Gaussian while it has fewer than kGroupWidth and the surface area of the union box stays
// at most the sum of its members' box areas (a ray that reaches the union box would have reached about as many
// member boxes: what grouping saves is the per-primitive overhead, not Gaussian tests). A Gaussian without a box
// ends the group and is left out. On showroom_1.5M (bench_render) this gives about 5.6 Gaussians per group
// reached; allowing 1.5x or 2x the area made groups fuller but every ray test more Gaussians (slower), 0.8x or
// 0.9x made more groups (slower sorted); groups of 4 gained about half as much, groups of 16 nothing.
void GaussianSet::build_groups(GaussianChunk& chunk) const {
    struct Spec {
        std::uint32_t first, count;
        glm::vec3 lower, upper;
    };
    constexpr std::uint32_t kBlock = 4096;
    const std::uint32_t blocks = (chunk.count + kBlock - 1) / kBlock;
    std::vector<std::vector<Spec>> specs(blocks);
    tbb::parallel_for(std::uint32_t(0), blocks, [&](std::uint32_t b) {
        const std::uint32_t begin = b * kBlock, end = std::min(chunk.count, begin + kBlock);
        std::vector<Spec>& out = specs[b];
        out.reserve((end - begin) / 2);
        bool open = false;
        float area_sum = 0.0f;
        for (std::uint32_t j = begin; j < end; ++j) {
            glm::vec3 lo, hi;
            if (!gaussian_box(prims[chunk.offset + j], flat, lo, hi)) {
                open = false;
                continue;
            }
            const float area = half_area(lo, hi);
            if (open) {
                Spec& s = out.back();
                const glm::vec3 ulo = glm::min(s.lower, lo), uhi = glm::max(s.upper, hi);
                const float ua = half_area(ulo, uhi);
                if (s.count < std::uint32_t(kGroupWidth) && ua <= area_sum + area) {
                    s.lower = ulo;
                    s.upper = uhi;
                    ++s.count;
                    area_sum += area;
                    continue;
                }
            }
            out.push_back(Spec{j, 1, lo, hi});
            area_sum = area;
            open = true;
        }
    });
    std::vector<std::size_t> base(blocks + 1, 0);
    for (std::uint32_t b = 0; b < blocks; ++b) base[b + 1] = base[b] + specs[b].size();
    // Each group in the narrowest width that holds it; with deformation all are wide (DeformedLanes and
    // deformed_group work on whole groups).
    const bool all_wide = deformation.steps >= 2;
    std::vector<GaussianGroups::Width> widths(base[blocks]);
    for (std::uint32_t b = 0; b < blocks; ++b)
        for (std::size_t k = 0; k < specs[b].size(); ++k) {
            const std::uint32_t n = specs[b][k].count;
            widths[base[b] + k] = all_wide || n > 4 ? GaussianGroups::Width::Eight
                                  : n > 1           ? GaussianGroups::Width::Four
                                                    : GaussianGroups::Width::One;
        }
    chunk.groups.assign(widths);  // (every field of every group is written below)
    chunk.group_bounds.resize(base[blocks]);
    // Writes the lanes of a group of N lanes: the spec's Gaussians, then padding (zero rows fail the ray test: a zero
    // denominator; zero support rejects the lane anyway).
    const auto fill = [&](auto& g, const Spec& s) {
        constexpr int lanes = int(sizeof(g.opacity) / sizeof(float));
        for (int lane = 0; lane < lanes; ++lane) {
            GaussianPrimitive p;
            if (std::uint32_t(lane) < s.count) p = prims[chunk.offset + s.first + lane];
            else std::memset(&p, 0, sizeof(p));
            const glm::vec3 rows[3] = {p.row0, p.row1, p.row2};
            for (int a = 0; a < 3; ++a) {
                g.center[a][lane] = p.center[a];
                for (int r = 0; r < 3; ++r) g.row[3 * r + a][lane] = rows[r][a];
            }
            g.support[lane] = std::uint32_t(lane) < s.count ? p.support_sq : 0.0f;
            g.opacity[lane] = p.opacity;
            g.cloud_index[lane] = p.cloud_index;
        }
        g.first = s.first;
        if constexpr (lanes > 1) g.count = s.count;  // (a group of one lane has no room for its count, which is 1)
    };
    tbb::parallel_for(std::uint32_t(0), blocks, [&](std::uint32_t b) {
        for (std::size_t k = 0; k < specs[b].size(); ++k) {
            const Spec& s = specs[b][k];
            const GaussianGroups::Location at = chunk.groups.locate(std::uint32_t(base[b] + k));
            if (at.width == GaussianGroups::Width::Eight) fill(chunk.groups.wide[at.index], s);
            else if (at.width == GaussianGroups::Width::Four) fill(chunk.groups.quads[at.index], s);
            else fill(chunk.groups.singles[at.index], s);
            RTCBounds& bb = chunk.group_bounds[base[b] + k];
            bb = RTCBounds{};
            bb.lower_x = s.lower.x;
            bb.lower_y = s.lower.y;
            bb.lower_z = s.lower.z;
            bb.upper_x = s.upper.x;
            bb.upper_y = s.upper.y;
            bb.upper_z = s.upper.z;
        }
    });
}

// The lanes at each step are the frame's groups' Gaussians (the same membership, so the callbacks keep every other
// field of the group), with their rows in the first step's order of scales at every step (Scene::
// set_gaussians_deformation aligned the steps' axes), so that a row stays one axis.
// Bounds: Embree takes a user primitive's bounds at each time step and assumes them linearly interpolated in
// between (rtcSetGeometryTimeStepCount; the bounds callback's timeStep), so they must contain the Gaussian at every
// time of the segment, not only at the steps. A lane's box at step k is its centre there plus, on every axis, its
// support radius times the largest standard deviation it has at any step: a sphere that holds the Gaussian however
// it turns, and whose linear interpolation holds the interpolated Gaussian (its centre moves linearly, its scales
// stay below that largest one).
void GaussianSet::build_deformation(GaussianChunk& chunk) const {
    const std::size_t steps = deformation.steps, groups = chunk.groups.size(), n = cloud->size();
    chunk.deformed.clear();
    chunk.deformed_bounds.clear();
    if (steps < 2) return;
    // (Groups made before the deformation was set are regrouped, all wide.)
    if (chunk.groups.wide.size() != groups) build_groups(chunk);
    chunk.deformed.assign(steps * groups, DeformedLanes{});
    chunk.deformed_bounds.assign(steps * groups, RTCBounds{});
    tbb::parallel_for(std::size_t(0), groups, [&](std::size_t gi) {
        const GaussianGroup& g = chunk.groups.wide[gi];
        float reach[kGroupWidth] = {};
        for (std::uint32_t lane = 0; lane < g.count; ++lane) {
            const std::size_t i = g.cloud_index[lane];
            // (The steps' axes are aligned with one another, not with the cloud's: their own order of scales.)
            int order[3];
            order_by_scale(&deformation.scales[3 * i], order);
            float largest = 0.0f;
            for (std::size_t k = 0; k < steps; ++k) {
                DeformedLanes& d = chunk.deformed[k * groups + gi];
                const std::size_t at = k * n + i;
                for (int a = 0; a < 3; ++a) d.center[a][lane] = deformation.positions[3 * at + a];
                for (int a = 0; a < 4; ++a) d.rotation[a][lane] = deformation.rotations[4 * at + a];
                for (int r = 0; r < 3; ++r) {
                    d.scale[r][lane] = deformation.scales[3 * at + order[r]];
                    d.axis[r][lane] = std::uint8_t(order[r]);
                    largest = std::max(largest, d.scale[r][lane]);
                }
            }
            reach[lane] = std::sqrt(g.support[lane]) * largest;
        }
        for (std::size_t k = 0; k < steps; ++k) {
            const DeformedLanes& d = chunk.deformed[k * groups + gi];
            glm::vec3 lower(std::numeric_limits<float>::infinity()), upper(-std::numeric_limits<float>::infinity());
            for (std::uint32_t lane = 0; lane < g.count; ++lane) {
                const glm::vec3 c(d.center[0][lane], d.center[1][lane], d.center[2][lane]);
                lower = glm::min(lower, c - reach[lane]);
                upper = glm::max(upper, c + reach[lane]);
            }
            RTCBounds& bb = chunk.deformed_bounds[k * groups + gi];
            bb.lower_x = lower.x, bb.lower_y = lower.y, bb.lower_z = lower.z;
            bb.upper_x = upper.x, bb.upper_y = upper.y, bb.upper_z = upper.z;
        }
    });
}

// Between two steps a Gaussian's centre and scales are interpolated linearly and its rotation by the normalised
// linear interpolation of its quaternions (sign-aligned when they were stored, so that it turns the short way): at
// the steps it is exact, between them it turns at nearly constant speed over the small angles of one step, and the
// rows rebuilt from it stay orthogonal, so the Gaussian keeps its shape. (Interpolating the rows themselves would
// shorten a turning Gaussian's inverse-scale rows, that is grow the Gaussian, beyond its bounds.) The rows are
// made as make_primitive makes them, in the first step's order of scales.
void GaussianSet::deformed_group(const GaussianChunk& chunk, std::uint32_t group, float time,
                                 GaussianGroup& out) const {
    const GaussianGroup& g = chunk.groups.wide[group];  // (with deformation every group is wide)
    out = g;
    const std::size_t steps = deformation.steps, groups = chunk.groups.size();
    const float f = glm::clamp(time, 0.0f, 1.0f) * float(steps - 1);
    const std::size_t k = std::min(std::size_t(f), steps - 2);
    const float w = f - float(k), v = 1.0f - w;
    const DeformedLanes& a = chunk.deformed[k * groups + group];
    const DeformedLanes& b = chunk.deformed[(k + 1) * groups + group];
    for (std::uint32_t lane = 0; lane < g.count; ++lane) {
        for (int c = 0; c < 3; ++c) out.center[c][lane] = v * a.center[c][lane] + w * b.center[c][lane];
        glm::vec4 q;
        for (int c = 0; c < 4; ++c) q[c] = v * a.rotation[c][lane] + w * b.rotation[c][lane];
        q /= glm::length(q);  // (sign-aligned unit quaternions: |q| >= 1/sqrt(2))
        const std::array<float, 9> r = la::quaternion_to_rotation(q[0], q[1], q[2], q[3]);
        float scale[3];
        for (int row = 0; row < 3; ++row) scale[row] = v * a.scale[row][lane] + w * b.scale[row][lane];
        const float smax = std::max(scale[0], 1e-30f);
        for (int row = 0; row < 3; ++row) {
            const int axis = a.axis[row][lane];
            const float inv = flat && row == 2 ? 1.0f : 1.0f / std::max(scale[row], 1e-6f * smax);
            for (int c = 0; c < 3; ++c) out.row[3 * row + c][lane] = r[3 * c + axis] * inv;
        }
    }
}

void GaussianSet::update_geometry(GaussianChunk& chunk) const {
    build_groups(chunk);
    build_deformation(chunk);
    // User geometry: Embree asks the bounds callback for every primitive when the geometry is committed (and the
    // scene that holds it), so the groups must be final here; the chunk's scene is committed by the caller. With
    // deformation, at each time step (gaussian_callbacks.cpp).
    rtcSetGeometryTimeStepCount(chunk.geometry, deformation.steps >= 2 ? unsigned(deformation.steps) : 1u);
    rtcSetGeometryUserPrimitiveCount(chunk.geometry, unsigned(chunk.groups.size()));
    rtcCommitGeometry(chunk.geometry);
}

}  // namespace raysplats
