// Gaussian compositing: exact single-Gaussian response, sorted gathering against a brute-force reference, and
// stochastic compositing converging to the sorted image; the groups the ray test reads, in their three widths.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <random>
#include <vector>

#include "raysplats/render/renderer.h"
#include "render/gaussian_primitives.h"
#include "render_test_util.h"

using namespace raysplats;
using namespace raysplats::testing;

namespace {

Camera ortho_down_z(float height, float scale) {
    Camera cam;
    cam.type = CameraType::Orthographic;
    cam.ortho_scale = scale;
    cam.camera_to_world = Matrix4::translation(0, 0, height);
    return cam;
}

RenderSettings exact_settings(int w, int h, GaussianMode mode, BlendSpace space = BlendSpace::Linear) {
    RenderSettings s;
    s.blend_space = space;
    s.width = w;
    s.height = h;
    s.samples = 1;
    s.jitter = false;
    s.max_bounces = 0;
    s.gaussian_mode = mode;
    s.transparent_background = true;
    return s;
}

}  // namespace

// A Gaussian seen head-on (orthographic, along its smallest axis): alpha = a exp(-d^2 / 2) with
// d^2 = (u / s1)^2 + (v / s2)^2, and rgb = alpha * linear colour (linear blend space) or linear(alpha * colour)
// (display blend space, as a splat viewer shows it over black). Tolerance 1e-5 (float arithmetic).
TEST(RenderGaussian, SingleGaussianHeadOnAlphaIsExact) {
    const float angle = 0.5235988f;  // rotated 30 degrees about Z: the axes are not the image axes
    const float q[4] = {std::cos(angle / 2), 0.0f, 0.0f, std::sin(angle / 2)};
    const float pos[3] = {0.1f, -0.2f, 0.0f}, scale[3] = {0.5f, 0.25f, 0.05f}, rgb[3] = {0.9f, 0.5f, 0.2f};
    const float a = 0.8f;
    GaussianCloud cloud;
    add_gaussian(cloud, pos, q, scale, a, rgb);
    Scene scene;
    scene.add_gaussians(cloud);
    scene.set_world(black_world());
    const Camera cam = ortho_down_z(5.0f, 4.0f);
    std::vector<Film> films;
    for (BlendSpace space : {BlendSpace::Linear, BlendSpace::Display})
    for (GaussianMode mode : {GaussianMode::Flat, GaussianMode::Volumetric}) {
        const Film film = render(scene, cam, exact_settings(64, 64, mode, space));
        int checked = 0;
        for (int j = 0; j < 64; ++j)
            for (int i = 0; i < 64; ++i) {
                const double x = (i + 0.5) / 64.0 * 4.0 - 2.0 - pos[0], y = 2.0 - (j + 0.5) / 64.0 * 4.0 - pos[1];
                const double u = std::cos(angle) * x + std::sin(angle) * y, v = -std::sin(angle) * x + std::cos(angle) * y;
                const double d2 = (u / scale[0]) * (u / scale[0]) + (v / scale[1]) * (v / scale[1]);
                double expected = d2 <= 9.0 ? std::min(0.99, a * std::exp(-0.5 * d2)) : 0.0;
                if (std::abs(expected - 1.0 / 255.0) < 1e-4 || std::abs(d2 - 9.0) < 1e-3) continue;  // threshold edges
                if (expected < 1.0 / 255.0) expected = 0.0;
                const std::size_t p = std::size_t(j) * 64 + i;
                ASSERT_NEAR(film.alpha()[p], expected, 1e-5) << "pixel " << i << "," << j;
                for (int c = 0; c < 3; ++c)
                    ASSERT_NEAR(film.rgba()[4 * p + c],
                                space == BlendSpace::Linear ? expected * srgb_to_linear_ref(rgb[c])
                                                            : srgb_to_linear_ref(expected * rgb[c]),
                                1e-5);
                if (expected > 0.0) ++checked;
            }
        EXPECT_GT(checked, 100);
        films.push_back(film);
    }
    // Head-on, the maximum response along the ray of the ellipsoid equals the disk's response: the two modes agree.
    for (std::size_t p = 0; p < films[0].alpha().size(); ++p) ASSERT_NEAR(films[0].alpha()[p], films[1].alpha()[p], 1e-5);
    // Where the Gaussian is semi-transparent, linear compositing is brighter than the trained look: summed over the
    // image, red (0.9) by 2.74x (from the formulas above).
    double linear_sum = 0, display_sum = 0;
    for (std::size_t p = 0; p < films[0].alpha().size(); ++p) linear_sum += films[0].rgba()[4 * p], display_sum += films[2].rgba()[4 * p];
    EXPECT_GT(linear_sum, 2.5 * display_sum);
}

// Seen obliquely, a thick Gaussian differs between the two modes (the volumetric one sees its third axis).
TEST(RenderGaussian, FlatAndVolumetricDifferObliquely) {
    const float q[4] = {1, 0, 0, 0}, pos[3] = {0, 0, 0}, scale[3] = {0.5f, 0.4f, 0.3f}, rgb[3] = {1, 1, 1};
    GaussianCloud cloud;
    add_gaussian(cloud, pos, q, scale, 0.9f, rgb);
    Scene scene;
    scene.add_gaussians(cloud);
    Camera cam;
    cam.type = CameraType::Orthographic;
    cam.ortho_scale = 3.0f;
    cam.camera_to_world = Matrix4::look_at({3, 0, 3}, {0, 0, 0}, {0, 0, 1});
    const Film flat = render(scene, cam, exact_settings(32, 32, GaussianMode::Flat));
    const Film vol = render(scene, cam, exact_settings(32, 32, GaussianMode::Volumetric));
    float max_diff = 0;
    for (std::size_t p = 0; p < flat.alpha().size(); ++p) max_diff = std::max(max_diff, std::abs(flat.alpha()[p] - vol.alpha()[p]));
    EXPECT_GT(max_diff, 0.05f);
}

namespace {

// ---- Brute-force reference, written independently of the renderer: every Gaussian against every ray, in double.
struct RefHit {
    double t;
    double alpha;
    std::size_t index;
};

std::array<std::array<double, 3>, 3> rotation_columns(const float* q) {
    double w = q[0], x = q[1], y = q[2], z = q[3];
    const double n = std::sqrt(w * w + x * x + y * y + z * z);
    w /= n, x /= n, y /= n, z /= n;
    // R as columns (axes)
    return {{{1 - 2 * (y * y + z * z), 2 * (x * y + w * z), 2 * (x * z - w * y)},
             {2 * (x * y - w * z), 1 - 2 * (x * x + z * z), 2 * (y * z + w * x)},
             {2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)}}};
}

double dot3(const double* a, const double* b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

// Rectangles z = const (world), emissive: the opaque occluders of the reference.
struct RefQuad {
    double x0, x1, y0, y1, z;
    std::array<double, 3> emission;
};

// `display`: the Gaussians' sRGB colours are composited as they are, D = sum T_i a_i c_i, and the quad behind
// joins in display space: linear(D + T srgb(E)) (docs/design.md §4); else linear colours are composited, D + T E.
std::array<double, 4> reference_pixel(const GaussianCloud& cloud, bool flat, const std::vector<RefQuad>& quads,
                                      const CameraRay& ray, double threshold, bool display = false) {
    const double o[3] = {ray.origin[0], ray.origin[1], ray.origin[2]};
    const double d[3] = {ray.direction[0], ray.direction[1], ray.direction[2]};
    double t_mesh = ray.t_max;
    const RefQuad* hit_quad = nullptr;
    for (const RefQuad& q : quads) {
        if (d[2] == 0) continue;
        const double t = (q.z - o[2]) / d[2];
        const double x = o[0] + t * d[0], y = o[1] + t * d[1];
        if (t >= ray.t_min && t < t_mesh && x >= q.x0 && x <= q.x1 && y >= q.y0 && y <= q.y1) {
            t_mesh = t;
            hit_quad = &q;
        }
    }
    std::vector<RefHit> hits;
    for (std::size_t i = 0; i < cloud.size(); ++i) {
        const auto axes = rotation_columns(&cloud.rotations[4 * i]);
        const float* s = &cloud.scales[3 * i];
        int order[3] = {0, 1, 2};
        std::sort(order, order + 3, [&](int a, int b) { return s[a] > s[b]; });
        const double m[3] = {cloud.positions[3 * i], cloud.positions[3 * i + 1], cloud.positions[3 * i + 2]};
        const double p[3] = {o[0] - m[0], o[1] - m[1], o[2] - m[2]};
        double t, d2;
        if (flat) {
            const double* n = axes[order[2]].data();
            const double dn = dot3(d, n);
            if (dn == 0) continue;
            t = -dot3(p, n) / dn;
            const double q[3] = {p[0] + t * d[0], p[1] + t * d[1], p[2] + t * d[2]};
            const double u = dot3(q, axes[order[0]].data()) / s[order[0]], v = dot3(q, axes[order[1]].data()) / s[order[1]];
            d2 = u * u + v * v;
        } else {
            double po[3], dd[3];
            for (int k = 0; k < 3; ++k) {
                po[k] = dot3(p, axes[k].data()) / s[k];
                dd[k] = dot3(d, axes[k].data()) / s[k];
            }
            t = -dot3(po, dd) / dot3(dd, dd);
            const double q[3] = {po[0] + t * dd[0], po[1] + t * dd[1], po[2] + t * dd[2]};
            d2 = dot3(q, q);
        }
        if (d2 > 9.0 || t < ray.t_min || t > t_mesh) continue;
        const double alpha = std::min(0.99, cloud.opacities[i] * std::exp(-0.5 * d2));
        if (alpha < 1.0 / 255.0) continue;
        hits.push_back({t, alpha, i});
    }
    std::sort(hits.begin(), hits.end(), [](const RefHit& a, const RefHit& b) { return a.t < b.t || (a.t == b.t && a.index < b.index); });
    std::array<double, 4> out{0, 0, 0, 0};
    double T = 1.0;
    auto finish = [&](const std::array<double, 3>& behind) {
        for (int c = 0; c < 3; ++c)
            out[c] = display ? srgb_to_linear_ref(out[c] + T * linear_to_srgb_ref(behind[c])) : out[c] + T * behind[c];
        return out;
    };
    for (const RefHit& h : hits) {
        for (int c = 0; c < 3; ++c) {
            const double srgb = std::max(0.0, 0.5 + kShC0 * cloud.sh[h.index * 3 + c]);
            out[c] += T * h.alpha * (display ? srgb : srgb_to_linear_ref(srgb));
        }
        T *= 1.0 - h.alpha;
        if (T < threshold) {
            T = 0.0;
            out[3] = 1.0;
            return finish({0, 0, 0});
        }
    }
    out[3] = hit_quad ? 1.0 : 1.0 - T;
    return finish(hit_quad ? hit_quad->emission : std::array<double, 3>{0, 0, 0});
}

// Random Gaussians around two emissive quads at different depths (black world): a plain one, x in [-1.5, 0.2],
// y in [-1.5, 1.5], z = -0.3 (material 0: 0.2, 0.7, 0.4), and an instanced unit square moved to x in [-0.2, 0.8],
// y in [-0.5, 0.5], z = 0.35 (material 1: 0.9, 0.1, 0.3). The scene shares the meshes' arrays: they live as long.
struct TwoQuadScene {
    TestMesh plain = make_quad_z(-1.5f, 0.2f, -1.5f, 1.5f, -0.3f, 0);
    TestMesh inst = make_quad_z(-0.5f, 0.5f, -0.5f, 0.5f, 0.0f, 1);
    Scene scene;
    explicit TwoQuadScene(const GaussianCloud& cloud) {
        inst.object_to_world = Matrix4::translation(0.3f, 0.0f, 0.35f);
        scene.set_world(black_world());
        scene.add_material(emissive(0.2f, 0.7f, 0.4f));
        scene.add_material(emissive(0.9f, 0.1f, 0.3f));
        scene.add_mesh(plain.desc());
        scene.add_mesh(inst.desc());
        scene.add_gaussians(cloud);
    }
};

Camera two_quad_scene_camera() {
    Camera cam;
    cam.camera_to_world = Matrix4::look_at({0.3f, -0.4f, 4.0f}, {0, 0, 0}, {0, 1, 0});
    cam.focal_length_mm = 35.0f;
    return cam;
}

}  // namespace

// Sorted gathering (k-nearest buffer, re-traced) equals sorting every hit, on random scenes with meshes between the
// Gaussians, in both modes and both blend spaces, one plain and one instanced mesh. Max pixel error 1e-5.
TEST(RenderGaussian, SortedGatherEqualsBruteForce) {
    for (std::uint32_t seed : {1u, 2u}) {
        const GaussianCloud cloud = random_cloud(seed, 300, 1.0f);
        TwoQuadScene quad_scene(cloud);
        Scene& scene = quad_scene.scene;
        const std::vector<RefQuad> quads = {{-1.5, 0.2, -1.5, 1.5, -0.3, {0.2, 0.7, 0.4}},
                                            {-0.2, 0.8, -0.5, 0.5, 0.35, {0.9, 0.1, 0.3}}};
        const Camera cam = two_quad_scene_camera();
        for (BlendSpace space : {BlendSpace::Linear, BlendSpace::Display})
        for (GaussianMode mode : {GaussianMode::Flat, GaussianMode::Volumetric})
        for (int k : {3, 48, 128}) {
            RenderSettings s = exact_settings(48, 40, mode, space);
            s.gather_buffer_size = k;
            const Film film = render(scene, cam, s);
            double max_err = 0;
            std::uint64_t composited = 0;
            for (int j = 0; j < s.height; ++j)
                for (int i = 0; i < s.width; ++i) {
                    const CameraRay ray = generate_camera_ray(cam, s.width, s.height, i + 0.5f, j + 0.5f);
                    const auto ref = reference_pixel(cloud, mode == GaussianMode::Flat, quads, ray, s.transmittance_threshold,
                                                     space == BlendSpace::Display);
                    const std::size_t p = std::size_t(j) * s.width + i;
                    for (int c = 0; c < 4; ++c) max_err = std::max(max_err, std::abs(ref[c] - film.rgba()[4 * p + c]));
                }
            composited = film.stats.gaussian_hits;
            EXPECT_LE(max_err, 1e-5) << "seed " << seed << " mode " << int(mode) << " k " << k << " space " << int(space);
            // With k = 3 the scene must exercise re-tracing: many rays see more than 3 Gaussians.
            if (k == 3) {
                EXPECT_GT(film.stats.traced_rays, std::uint64_t(s.width) * s.height * 2);
            }
            EXPECT_GT(composited, 5000u);
        }
    }
}

// Speculative segment ends (camera rays traverse first only up to about where their neighbours' segments ended)
// change nothing: the same films, bit for bit, with and without, on scenes where the guesses are often too early
// (Gaussians in front of, between and behind two quads at different depths), in both modes, over several jittered
// samples (later samples guess from the pixel's previous one), also with a small buffer that overflows.
TEST(RenderGaussian, SpeculativeEndsChangeNothing) {
    for (std::uint32_t seed : {3u, 4u}) {
        const GaussianCloud cloud = random_cloud(seed, 300, 1.0f);
        TwoQuadScene quad_scene(cloud);
        Scene& scene = quad_scene.scene;
        const Camera cam = two_quad_scene_camera();
        for (GaussianMode mode : {GaussianMode::Flat, GaussianMode::Volumetric})
            for (int k : {4, 96}) {
                RenderSettings s = exact_settings(48, 40, mode);
                s.samples = 3;
                s.jitter = true;
                s.gather_buffer_size = k;
                s.transmittance_threshold = 0.05f;  // segments end inside the cloud, not only at the quads
                s.speculative_ends = false;
                const Film plain = render(scene, cam, s);
                s.speculative_ends = true;
                const Film fast = render(scene, cam, s);
                EXPECT_TRUE(plain.channels == fast.channels) << "seed " << seed << " mode " << int(mode) << " k " << k;
                EXPECT_EQ(plain.stats.gaussian_hits, fast.stats.gaussian_hits);
                // Some guesses were too early and those rays went on (with k = 4 the buffer overflows first).
                if (k == 96) {
                    EXPECT_GT(fast.stats.traced_rays, plain.stats.traced_rays);
                }
            }
    }
}

// Stochastic compositing is unbiased: its error against the sorted image falls like samples^-1/2, in both blend
// spaces, over a coloured world. In display space a stochastic sample is one display colour (or what lies behind) and
// the film combines the means (SampleRecord): the film must converge to the sorted linear(D + T srgb(world)), not to
// the linear composite that per-sample conversion would give.
// The slope of log(RMSE) against log(spp) over 4, 16, 64, 256 spp must be in [-0.62, -0.38].
TEST(RenderGaussian, StochasticConvergesToSorted) {
    const GaussianCloud cloud = random_cloud(7, 300, 1.0f);
    Scene scene;
    scene.add_gaussians(cloud);
    World world;
    world.color = {0.3f, 0.5f, 0.8f};
    scene.set_world(world);
    Camera cam;
    cam.camera_to_world = Matrix4::look_at({0, 0, 4}, {0, 0, 0}, {0, 1, 0});
    std::vector<Film> sorted_films;
    for (BlendSpace space : {BlendSpace::Linear, BlendSpace::Display}) {
        RenderSettings s = exact_settings(24, 24, GaussianMode::Flat, space);
        s.transparent_background = false;
        s.transmittance_threshold = 0.0f;  // the expectation of stochastic compositing is the un-truncated sum
        const Film sorted = render(scene, cam, s);
        sorted_films.push_back(sorted);
        s.compositing = Compositing::Stochastic;
        std::vector<double> xs, ys;
        for (int spp : {4, 16, 64, 256}) {
            s.samples = spp;
            const Film st = render(scene, cam, s);
            double se = 0;
            for (std::size_t i = 0; i < sorted.rgba().size(); ++i)
                se += (st.rgba()[i] - sorted.rgba()[i]) * (st.rgba()[i] - sorted.rgba()[i]);
            const double rmse = std::sqrt(se / sorted.rgba().size());
            xs.push_back(std::log(double(spp)));
            ys.push_back(std::log(rmse));
        }
        const double mx = (xs[0] + xs[1] + xs[2] + xs[3]) / 4, my = (ys[0] + ys[1] + ys[2] + ys[3]) / 4;
        double num = 0, den = 0;
        for (int i = 0; i < 4; ++i) {
            num += (xs[i] - mx) * (ys[i] - my);
            den += (xs[i] - mx) * (xs[i] - mx);
        }
        const double slope = num / den;
        EXPECT_GT(slope, -0.62) << "space " << int(space);
        EXPECT_LT(slope, -0.38) << "space " << int(space);
        EXPECT_LT(std::exp(ys[3]), 0.05) << "space " << int(space);  // 256 spp is already close
    }
    // The two spaces' sorted images differ by far more than that (else the test could not tell them apart).
    double se = 0;
    for (std::size_t i = 0; i < sorted_films[0].rgba().size(); ++i)
        se += std::pow(sorted_films[0].rgba()[i] - sorted_films[1].rgba()[i], 2);
    EXPECT_GT(std::sqrt(se / sorted_films[0].rgba().size()), 0.05);
}

// The groups are stored in three widths (GaussianGroups): every primID is found in its width's array, and every
// group there holds its Gaussians' fields in its lanes and zero support in its padding; the groups cover the
// Gaussians in order, each once. A cloud of scattered Gaussians (groups of one), clusters of three (four lanes) and
// clusters of eight (eight lanes): all three widths are used, in less memory than eight lanes each. (That the ray test
// gives the same bits in every width is what the golden films check: they were recorded with eight lanes for every
// group.)
TEST(RenderGaussian, GroupsInThreeWidthsHoldTheirGaussians) {
    GaussianCloud cloud = random_cloud(11, 300, 5.0f);
    std::mt19937 rng(3);
    std::uniform_real_distribution<float> u(-4.0f, 4.0f);
    for (int size : {3, 8}) {
        for (int cluster = 0; cluster < 20; ++cluster) {
            const float centre[3] = {u(rng), u(rng), u(rng)};
            for (int k = 0; k < size; ++k) {
                const float p[3] = {centre[0], centre[1], centre[2] + 1e-3f * float(k)};
                const float q[4] = {1.0f, 0.0f, 0.0f, 0.0f}, sc[3] = {0.01f, 0.01f, 0.01f}, c[3] = {0.5f, 0.5f, 0.5f};
                add_gaussian(cloud, p, q, sc, 0.8f, c);
            }
        }
    }
    for (GaussianMode mode : {GaussianMode::Flat, GaussianMode::Volumetric}) {
        GaussianSet set;
        set.cloud = &cloud;
        set.prepare(mode, false);
        GaussianChunk chunk;
        chunk.set = &set;
        chunk.count = std::uint32_t(cloud.size());
        set.build_groups(chunk);
        const GaussianGroups& groups = chunk.groups;
        ASSERT_EQ(groups.size(), chunk.group_bounds.size());
        EXPECT_GT(groups.singles.size(), 0u);
        EXPECT_GT(groups.quads.size(), 0u);
        EXPECT_GT(groups.wide.size(), 0u);
        EXPECT_EQ(groups.singles.size() + groups.quads.size() + groups.wide.size(), groups.size());
        EXPECT_LT(groups.singles.size() * sizeof(GaussianSingle) + groups.quads.size() * sizeof(GaussianQuad) +
                      groups.wide.size() * sizeof(GaussianGroup),
                  groups.size() * sizeof(GaussianGroup) / 2);
        std::vector<int> seen[3];  // the indices found in each width's array
        std::uint32_t next = 0;    // the first Gaussian after the groups so far
        const auto check = [&](const auto& g, std::uint32_t count, int lanes, std::uint32_t prim) {
            EXPECT_GE(g.first, next) << "group " << prim;
            next = g.first + count;
            for (int lane = 0; lane < lanes; ++lane) {
                if (std::uint32_t(lane) >= count) {
                    EXPECT_EQ(g.support[lane], 0.0f) << "padding lane " << lane << " of group " << prim;
                    continue;
                }
                const GaussianPrimitive& p = set.prims[g.first + lane];
                const glm::vec3 rows[3] = {p.row0, p.row1, p.row2};
                for (int a = 0; a < 3; ++a) {
                    EXPECT_EQ(g.center[a][lane], p.center[a]);
                    for (int r = 0; r < 3; ++r) EXPECT_EQ(g.row[3 * r + a][lane], rows[r][a]);
                }
                EXPECT_EQ(g.support[lane], p.support_sq);
                EXPECT_EQ(g.opacity[lane], p.opacity);
                EXPECT_EQ(g.cloud_index[lane], p.cloud_index);
                EXPECT_GT(p.support_sq, 0.0f) << "a Gaussian that can never reach 1/255 is left out of the groups";
            }
        };
        for (std::uint32_t prim = 0; prim < groups.size(); ++prim) {
            const GaussianGroups::Location at = groups.locate(prim);
            const int width = int(at.width);
            seen[width].push_back(int(at.index));
            if (at.width == GaussianGroups::Width::One) {
                ASSERT_LT(at.index, groups.singles.size());
                check(groups.singles[at.index], 1, 1, prim);
            } else if (at.width == GaussianGroups::Width::Four) {
                ASSERT_LT(at.index, groups.quads.size());
                const GaussianQuad& g = groups.quads[at.index];
                EXPECT_TRUE(g.count >= 2 && g.count <= 4) << "group " << prim;
                check(g, g.count, 4, prim);
            } else {
                ASSERT_LT(at.index, groups.wide.size());
                const GaussianGroup& g = groups.wide[at.index];
                EXPECT_TRUE(g.count >= 5 && g.count <= 8) << "group " << prim;
                check(g, g.count, kGroupWidth, prim);
            }
        }
        // Each width's groups are found once each, in primID order.
        for (int w = 0; w < 3; ++w)
            for (std::size_t i = 0; i < seen[w].size(); ++i) EXPECT_EQ(seen[w][i], int(i)) << "width " << w;
    }
}
