// Camera-ray splatting (RenderSettings::camera_ray_splatting, src/render/camera_splatting.h): a single Gaussian's
// image is the EWA 2D Gaussian of the 3DGS rasterizer, computed here independently in its own (OpenCV) conventions;
// Gaussians composite in centre-depth order, across the two levels of tile lists too; meshes in front hide them and
// meshes behind show through them; the render region and jittered samples see the same splats; and where it does not
// apply the image is the traced one, bit for bit.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "raysplats/render/renderer.h"
#include "render/camera_splat_prepass.h"
#include "render_test_util.h"

using namespace raysplats;
using namespace raysplats::testing;

namespace {

// A pinhole camera at the origin looking down -Z (Blender's camera frame is the world's): focal length f_px pixels.
constexpr int kSize = 33;  // odd: the optical axis passes through the centre of pixel 16
constexpr double kLens = 50.0, kSensor = 36.0;
constexpr double kFocalPx = kSize * kLens / kSensor;

Camera pinhole() {
    Camera cam;
    cam.focal_length_mm = float(kLens);
    cam.sensor_width_mm = float(kSensor);
    cam.sensor_fit = SensorFit::Horizontal;
    cam.clip_start = 0.1f;
    return cam;
}

// A sun of power 1 whose light travels up the world's +Y axis (its local -Z turned to +Y).
Light sun_from_below() {
    Light sun;
    sun.type = LightType::Sun;
    sun.power = 1.0f;
    sun.light_to_world = Matrix4::rotation(1.5707963f, 1, 0, 0);
    return sun;
}

RenderSettings splat_settings(bool splatting, BlendSpace space = BlendSpace::Display,
                              GaussianMode mode = GaussianMode::Volumetric) {
    RenderSettings s;
    s.width = s.height = kSize;
    s.samples = 1;
    s.jitter = false;
    s.max_bounces = 0;
    s.gaussian_mode = mode;
    s.blend_space = space;
    s.transparent_background = true;
    s.camera_ray_splatting = splatting;
    return s;
}

// The 3DGS rasterizer's alpha of one Gaussian at pixel (i, j) (its centre, i + 0.5, j + 0.5), written from the paper
// and forward.cu in OpenCV view space (x right, y down, z forward): Sigma' = J Sigma J^T + 0.3 I, J the perspective
// Jacobian at the centre (not clamped here: the centre is well inside the frustum). `axes`: how many of the Gaussian's
// axes (largest first) its covariance has (3, or 2 for the flat disk).
double ewa_alpha(const float pos[3], const float q[4], const float scale[3], float opacity, int axes, int i, int j,
                 int size = kSize) {
    const double focal = size * kLens / kSensor;
    const double w = q[0], x = q[1], y = q[2], z = q[3];
    const double r[3][3] = {{1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)},
                            {2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)},
                            {2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)}};
    int order[3] = {0, 1, 2};
    std::sort(order, order + 3, [&](int a, int b) { return scale[a] > scale[b]; });
    double sigma[3][3] = {};
    for (int k = 0; k < axes; ++k) {
        const int a = order[k];
        for (int m = 0; m < 3; ++m)
            for (int n = 0; n < 3; ++n) sigma[m][n] += r[m][a] * r[n][a] * double(scale[a]) * scale[a];
    }
    // World (Blender camera frame) to OpenCV view: diag(1, -1, -1).
    const double flip[3] = {1, -1, -1};
    double s[3][3];
    for (int m = 0; m < 3; ++m)
        for (int n = 0; n < 3; ++n) s[m][n] = flip[m] * flip[n] * sigma[m][n];
    const double px = pos[0], py = -pos[1], pz = -pos[2];
    const double jac[2][3] = {{focal / pz, 0, -focal * px / (pz * pz)}, {0, focal / pz, -focal * py / (pz * pz)}};
    double cov[2][2] = {};
    for (int a = 0; a < 2; ++a)
        for (int b = 0; b < 2; ++b)
            for (int m = 0; m < 3; ++m)
                for (int n = 0; n < 3; ++n) cov[a][b] += jac[a][m] * s[m][n] * jac[b][n];
    cov[0][0] += 0.3;
    cov[1][1] += 0.3;
    const double det = cov[0][0] * cov[1][1] - cov[0][1] * cov[0][1];
    const double u = focal * px / pz + 0.5 * size, v = focal * py / pz + 0.5 * size;
    const double dx = i + 0.5 - u, dy = j + 0.5 - v;
    const double power = -0.5 * (cov[1][1] * dx * dx + cov[0][0] * dy * dy - 2 * cov[0][1] * dx * dy) / det;
    return std::min(0.99, opacity * std::exp(power));
}

}  // namespace

// One rotated, elongated Gaussian off the optical axis: every pixel's alpha is the EWA 2D Gaussian's (1e-5, float
// arithmetic), in both Gaussian modes (flat: the disk of its two largest axes), and its colour is linear(alpha c)
// (display blend space, over black); the traced image of the same Gaussian differs (what the setting is for). The
// footprint is the whole 3D Gaussian's in flat mode too (flat mode traces a disk; a viewer draws the Gaussian).
TEST(CameraSplatting, SingleGaussianIsTheEwaFootprint) {
    const float angle = 0.7f;
    const float q[4] = {std::cos(angle / 2), 0.3f * std::sin(angle / 2), 0.2f * std::sin(angle / 2),
                        std::sqrt(1.0f - 0.13f) * std::sin(angle / 2)};
    const float pos[3] = {0.12f, -0.05f, -3.0f}, scale[3] = {0.25f, 0.08f, 0.15f}, rgb[3] = {0.9f, 0.5f, 0.2f};
    const float a = 0.8f;
    GaussianCloud cloud;
    add_gaussian(cloud, pos, q, scale, a, rgb);
    Scene scene;
    scene.add_gaussians(cloud);
    scene.set_world(black_world());
    for (GaussianMode mode : {GaussianMode::Volumetric, GaussianMode::Flat}) {
        const Film film = render(scene, pinhole(), splat_settings(true, BlendSpace::Display, mode));
        EXPECT_TRUE(film.stats.camera_ray_splatting);
        EXPECT_EQ(film.stats.splats, 1u);
        const Film traced = render(scene, pinhole(), splat_settings(false, BlendSpace::Display, mode));
        EXPECT_FALSE(traced.stats.camera_ray_splatting);
        int checked = 0;
        double traced_difference = 0.0;
        for (int j = 0; j < kSize; ++j)
            for (int i = 0; i < kSize; ++i) {
                double expected = ewa_alpha(pos, q, scale, a, 3, i, j);
                if (std::abs(expected - 1.0 / 255.0) < 1e-4) continue;  // the cut's edge
                if (expected < 1.0 / 255.0) expected = 0.0;
                const std::size_t p = std::size_t(j) * kSize + i;
                ASSERT_NEAR(film.alpha()[p], expected, 1e-5) << "pixel " << i << "," << j;
                for (int c = 0; c < 3; ++c)
                    ASSERT_NEAR(film.rgba()[4 * p + c], srgb_to_linear_ref(expected * rgb[c]), 1e-4);
                traced_difference = std::max(traced_difference, std::abs(double(traced.alpha()[p]) - expected));
                if (expected > 0.05) ++checked;
            }
        EXPECT_GT(checked, 20);
        EXPECT_GT(traced_difference, 0.01) << "the traced image is the exact ray response, not the footprint";
        // Not the disk's footprint (its third axis, 0.15, is not thin), in flat mode either.
        double disk_difference = 0.0;
        for (int j = 0; j < kSize; ++j)
            for (int i = 0; i < kSize; ++i)
                disk_difference = std::max(disk_difference, std::abs(film.alpha()[std::size_t(j) * kSize + i] -
                                                                     ewa_alpha(pos, q, scale, a, 2, i, j)));
        EXPECT_GT(disk_difference, 0.01);
    }
}

// A long, thin, faint Gaussian across the image: its tile lists hold only the tiles where it can reach alpha 1/255,
// far fewer than its 3-sigma square covers, and every pixel is still the EWA footprint's.
TEST(CameraSplatting, ThinGaussiansBinOnlyWhereTheyShow) {
    const int size = 255;
    const float angle = 0.785398f;  // 45 degrees about the view axis: the diagonal of its square
    const float q[4] = {std::cos(angle / 2), 0.0f, 0.0f, std::sin(angle / 2)};
    const float pos[3] = {0.0f, 0.0f, -3.0f}, scale[3] = {0.6f, 0.004f, 0.004f}, rgb[3] = {1, 1, 1};
    const float a = 0.2f;
    GaussianCloud cloud;
    add_gaussian(cloud, pos, q, scale, a, rgb);
    Scene scene;
    scene.add_gaussians(cloud);
    scene.set_world(black_world());
    RenderSettings st = splat_settings(true);
    st.width = st.height = size;
    const Film film = render(scene, pinhole(), st);
    ASSERT_EQ(film.stats.splats, 1u);
    // Its square: 3 sigma of the long axis, 0.6 * f / 3 * 3 = 212 px half side at 45 degrees -> the whole 16 x 16
    // tiles of the image; the ellipse crosses about a diagonal's worth of them.
    const std::uint64_t square_tiles = 17 * 17;
    EXPECT_LT(film.stats.splat_tile_entries, square_tiles / 3);
    int checked = 0;
    for (int j = 0; j < size; ++j)
        for (int i = 0; i < size; ++i) {
            double expected = ewa_alpha(pos, q, scale, a, 3, i, j, size);
            if (std::abs(expected - 1.0 / 255.0) < 1e-4) continue;
            if (expected < 1.0 / 255.0) expected = 0.0;
            // Relative 2 %: far out along a thin Gaussian at 45 degrees the float conic's terms (~1e5) cancel to a
            // power of a few units, as in the 3DGS rasterizer's float arithmetic; a missing tile would give 0.
            ASSERT_NEAR(film.alpha()[std::size_t(j) * size + i], expected, 1e-5 + 0.02 * expected)
                << "pixel " << i << "," << j;
            checked += expected > 0.0;
        }
    EXPECT_GT(checked, 300);
}

// The binning finds a row of tiles from the ellipse's extent within the row's band (SplatEllipse::row_extent). Against
// the extent found by brute force (the ellipse's span at 4,001 heights across the band, each solved for x): the same
// ends, for round, elongated and needle-thin ellipses at every angle, bands through, above, below and across the tips;
// and a band that misses the ellipse is reported as missing it.
TEST(CameraSplatting, EllipseRowExtentIsTheBruteForceOne) {
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    int rows = 0, missed = 0;
    for (int trial = 0; trial < 2000; ++trial) {
        // Sigma' = R diag(s1^2, s2^2) R^T, its conic the inverse; r = 2 ln(255 a) for an opacity in (1/255, 1].
        const double angle = 3.14159265 * unit(rng), s1 = 0.3 + 20.0 * unit(rng);
        const double s2 = trial % 4 == 0 ? s1 * 1e-3 : 0.3 + 20.0 * unit(rng);
        const double cs = std::cos(angle), sn = std::sin(angle);
        const double sxx = cs * cs * s1 * s1 + sn * sn * s2 * s2, syy = sn * sn * s1 * s1 + cs * cs * s2 * s2;
        const double sxy = cs * sn * (s1 * s1 - s2 * s2), det = sxx * syy - sxy * sxy;
        const double a = syy / det, b = -sxy / det, c = sxx / det, r = 2.0 * std::log(255.0 * (0.01 + unit(rng)));
        const SplatEllipse ellipse(a, b, c, r);
        const double y_half = std::sqrt(r * a / (a * c - b * b));
        const double y0 = (2.4 * unit(rng) - 1.2) * y_half, y1 = y0 + 4.0 * unit(rng) * (trial % 3 == 0 ? y_half : 1.0);
        double lo = std::numeric_limits<double>::infinity(), hi = -lo;
        constexpr int kSteps = 4000;
        for (int k = 0; k <= kSteps; ++k) {
            const double y = y0 + (y1 - y0) * k / kSteps, disc = b * b * y * y - a * (c * y * y - r);
            if (disc < 0.0) continue;  // (a x^2 + 2 b y x + c y^2 - r = 0 has no root: not on the ellipse)
            lo = std::min(lo, (-b * y - std::sqrt(disc)) / a);
            hi = std::max(hi, (-b * y + std::sqrt(disc)) / a);
        }
        double x0 = 0.0, x1 = 0.0;
        const bool meets = ellipse.row_extent(y0, y1, x0, x1);
        if (lo > hi) {
            // No sampled height is on the ellipse: the band misses it, or grazes it between two samples.
            if (y0 > y_half * (1 + 1e-9) || y1 < -y_half * (1 + 1e-9)) {
                EXPECT_FALSE(meets) << "trial " << trial;
                ++missed;
            }
            continue;
        }
        ASSERT_TRUE(meets) << "trial " << trial;
        // Sampled ends lie within the true ones, by at most the span's change over one step of height.
        const double tolerance = 1e-9 * (std::abs(lo) + std::abs(hi) + 1.0);
        const double step_change = 4.0 * std::sqrt(r * c / (a * c - b * b)) * std::sqrt((y1 - y0) / kSteps / y_half) + tolerance;
        EXPECT_LE(x0, lo + tolerance) << "trial " << trial;
        EXPECT_GE(x1, hi - tolerance) << "trial " << trial;
        EXPECT_GE(x0, lo - step_change) << "trial " << trial;
        EXPECT_LE(x1, hi + step_change) << "trial " << trial;
        ++rows;
    }
    EXPECT_GT(rows, 1000);
    EXPECT_GT(missed, 100);
    // Not positive definite (a conic rounded to a line): every band is reached, all across.
    double x0 = 0.0, x1 = 0.0;
    EXPECT_TRUE(SplatEllipse(1.0, 1.0, 1.0, 4.0).row_extent(5.0, 6.0, x0, x1));
    EXPECT_TRUE(std::isinf(x0) && x0 < 0.0 && std::isinf(x1) && x1 > 0.0);
}

// Two Gaussians on the optical axis, in two clouds, the far one (blue) given first: the nearer centre (red) is
// composited first, C = a1 c1 + (1 - a1) a2 c2, at the centre pixel (the 2D Gaussians' peak: alpha = opacity).
TEST(CameraSplatting, CompositesInCentreDepthOrder) {
    const float q[4] = {1, 0, 0, 0}, s[3] = {0.3f, 0.3f, 0.3f};
    const float far_pos[3] = {0, 0, -4}, near_pos[3] = {0, 0, -3};
    const float blue[3] = {0, 0, 1}, red[3] = {1, 0, 0};
    GaussianCloud far_cloud, near_cloud;
    add_gaussian(far_cloud, far_pos, q, s, 0.7f, blue);
    add_gaussian(near_cloud, near_pos, q, s, 0.6f, red);
    Scene scene;
    scene.add_gaussians(far_cloud);
    scene.add_gaussians(near_cloud);
    scene.set_world(black_world());
    for (BlendSpace space : {BlendSpace::Display, BlendSpace::Linear}) {
        const Film film = render(scene, pinhole(), splat_settings(true, space));
        const std::size_t p = std::size_t(kSize / 2) * kSize + kSize / 2;
        const double r = 0.6, b = (1.0 - 0.6) * 0.7;  // red first, blue behind it
        EXPECT_NEAR(film.alpha()[p], 1.0 - (1.0 - 0.6) * (1.0 - 0.7), 1e-6);
        // Display: linear(C); linear: C of the linear colours (1 and 0 are their own linear values).
        EXPECT_NEAR(film.rgba()[4 * p + 0], space == BlendSpace::Display ? srgb_to_linear_ref(r) : r, 1e-4);
        EXPECT_NEAR(film.rgba()[4 * p + 2], space == BlendSpace::Display ? srgb_to_linear_ref(b) : b, 1e-4);
    }
}

// The same across the two levels of tile lists: a small Gaussian (a footprint of about 2 px: the 4 px lists) and a
// big one (about 10 px: the 16 px lists) on the optical axis, either in front: a packet merges the lists in depth order.
TEST(CameraSplatting, SmallAndBigSplatsCompositeInDepthOrder) {
    const float q[4] = {1, 0, 0, 0}, small_scale[3] = {0.02f, 0.02f, 0.02f}, big_scale[3] = {0.3f, 0.3f, 0.3f};
    const float blue[3] = {0, 0, 1}, red[3] = {1, 0, 0};
    for (bool small_in_front : {true, false}) {
        const float near_pos[3] = {0, 0, -3}, far_pos[3] = {0, 0, -4};
        GaussianCloud small, big;
        add_gaussian(small, small_in_front ? near_pos : far_pos, q, small_scale, 0.6f, blue);
        add_gaussian(big, small_in_front ? far_pos : near_pos, q, big_scale, 0.7f, red);
        Scene scene;
        scene.add_gaussians(big);
        scene.add_gaussians(small);
        scene.set_world(black_world());
        const Film film = render(scene, pinhole(), splat_settings(true));
        const std::size_t p = std::size_t(kSize / 2) * kSize + kSize / 2;
        const double a_near = small_in_front ? 0.6 : 0.7, a_far = small_in_front ? 0.7 : 0.6;
        const double blue_part = small_in_front ? a_near : (1.0 - a_near) * a_far;
        const double red_part = small_in_front ? (1.0 - a_near) * a_far : a_near;
        EXPECT_NEAR(film.alpha()[p], 1.0 - (1.0 - a_near) * (1.0 - a_far), 1e-6) << small_in_front;
        EXPECT_NEAR(film.rgba()[4 * p + 0], srgb_to_linear_ref(red_part), 1e-4) << small_in_front;
        EXPECT_NEAR(film.rgba()[4 * p + 2], srgb_to_linear_ref(blue_part), 1e-4) << small_in_front;
    }
}

// A mesh (an emissive quad, radiance e) across the optical axis: in front of the Gaussian it hides it; behind it,
// it shows through with the transmittance left, combined in display space: linear(a c + (1 - a) srgb(e)).
TEST(CameraSplatting, MeshesInFrontHideAndBehindShowThrough) {
    const float q[4] = {1, 0, 0, 0}, s[3] = {0.3f, 0.3f, 0.3f}, pos[3] = {0, 0, -3}, rgb[3] = {0.8f, 0.4f, 0.1f};
    const float a = 0.6f, e = 0.5f;
    GaussianCloud cloud;
    add_gaussian(cloud, pos, q, s, a, rgb);
    for (float mesh_z : {-2.0f, -5.0f}) {
        Scene scene;
        const std::uint32_t material = scene.add_material(emissive(e, e, e));
        const TestMesh quad = make_quad_z(-5, 5, -5, 5, mesh_z, material);
        scene.add_mesh(quad.desc());
        scene.add_gaussians(cloud);
        scene.set_world(black_world());
        const Film film = render(scene, pinhole(), splat_settings(true));
        ASSERT_TRUE(film.stats.camera_ray_splatting);
        const std::size_t p = std::size_t(kSize / 2) * kSize + kSize / 2;
        EXPECT_NEAR(film.alpha()[p], 1.0, 1e-6);
        for (int c = 0; c < 3; ++c) {
            const double expected =
                mesh_z > pos[2] ? e : srgb_to_linear_ref(a * rgb[c] + (1.0 - a) * linear_to_srgb_ref(e));
            EXPECT_NEAR(film.rgba()[4 * p + c], expected, 2e-4) << "mesh at z " << mesh_z << ", channel " << c;
        }
    }
}

// Jittered samples under a Blackman-Harris filter and a render region: the region's pixels are those of the whole
// image bit for bit (the tile grid follows the region, the splats a sample sees do not), and the render is
// deterministic.
TEST(CameraSplatting, RegionAndJitterSeeTheSameSplats) {
    const GaussianCloud cloud = random_cloud(7, 300, 1.0f);
    Scene scene;
    scene.add_gaussians(cloud, Matrix4::translation(0.0f, 0.0f, -4.0f));
    scene.set_world(black_world());
    RenderSettings st = splat_settings(true);
    st.width = 96;
    st.height = 64;
    st.samples = 4;
    st.jitter = true;
    st.pixel_filter = PixelFilter::BlackmanHarris;
    st.filter_width = 1.5f;
    const Film whole = render(scene, pinhole(), st);
    const Film again = render(scene, pinhole(), st);
    ASSERT_TRUE(whole.stats.camera_ray_splatting);
    EXPECT_EQ(whole.rgba(), again.rgba());
    RenderSettings part = st;
    part.region_x = 37;
    part.region_y = 21;
    part.region_width = 29;
    part.region_height = 17;
    const Film region = render(scene, pinhole(), part);
    int covered = 0;
    for (int y = part.region_y; y < part.region_y + part.region_height; ++y)
        for (int x = part.region_x; x < part.region_x + part.region_width; ++x) {
            const std::size_t p = std::size_t(y) * st.width + x;
            for (int c = 0; c < 4; ++c) ASSERT_EQ(region.rgba()[4 * p + c], whole.rgba()[4 * p + c]) << x << "," << y;
            covered += whole.alpha()[p] > 0.1f;
        }
    EXPECT_GT(covered, 50);
}

// Where it does not apply (an orthographic camera; a LIT cloud in the scene) the render is the traced one bit for
// bit, and says so; the setting off is the traced render (the golden image tests hold it to today's images).
TEST(CameraSplatting, FallsBackToTracingBitForBit) {
    const GaussianCloud cloud = random_cloud(3, 200, 1.0f);
    Scene scene;
    const std::uint32_t material = scene.add_material(emissive(0.3f, 0.6f, 0.9f));
    const TestMesh quad = make_quad_z(-3, 3, -3, 3, -6, material);
    scene.add_mesh(quad.desc());
    const std::uint32_t index = scene.add_gaussians(cloud, Matrix4::translation(0.0f, 0.0f, -4.0f));
    scene.set_world(black_world());
    Camera ortho = pinhole();
    ortho.type = CameraType::Orthographic;
    ortho.ortho_scale = 3.0f;
    const Film ortho_on = render(scene, ortho, splat_settings(true));
    const Film ortho_off = render(scene, ortho, splat_settings(false));
    EXPECT_FALSE(ortho_on.stats.camera_ray_splatting);
    EXPECT_EQ(ortho_on.rgba(), ortho_off.rgba());

    const Film baked_on = render(scene, pinhole(), splat_settings(true));
    EXPECT_TRUE(baked_on.stats.camera_ray_splatting);
    scene.set_gaussian_shading(index, GaussianShading::Lit);
    const Film lit_on = render(scene, pinhole(), splat_settings(true));
    const Film lit_off = render(scene, pinhole(), splat_settings(false));
    EXPECT_FALSE(lit_on.stats.camera_ray_splatting);
    EXPECT_EQ(lit_on.rgba(), lit_off.rgba());
    EXPECT_NE(baked_on.rgba(), lit_on.rgba());
}

// A lens shift moves the image plane, not the view: the splatted image moves by the shift, in whole pixels here
// (shift_x 4 / 33 of the fitted width: 4 pixels to the left), and is otherwise the same (1e-5).
TEST(CameraSplatting, LensShiftTranslatesTheImage) {
    const float angle = 0.4f;
    const float q[4] = {std::cos(angle / 2), 0.0f, std::sin(angle / 2), 0.0f};
    const float pos[3] = {0.3f, 0.1f, -3.0f}, scale[3] = {0.3f, 0.1f, 0.2f}, rgb[3] = {0.2f, 0.9f, 0.4f};
    GaussianCloud cloud;
    add_gaussian(cloud, pos, q, scale, 0.9f, rgb);
    Scene scene;
    scene.add_gaussians(cloud);
    scene.set_world(black_world());
    Camera cam = pinhole();
    const Film centred = render(scene, cam, splat_settings(true));
    cam.shift_x = 4.0f / float(kSize);
    const Film shifted = render(scene, cam, splat_settings(true));
    int covered = 0;
    for (int j = 0; j < kSize; ++j)
        for (int i = 0; i + 4 < kSize; ++i) {
            const float a = shifted.alpha()[std::size_t(j) * kSize + i];
            ASSERT_NEAR(a, centred.alpha()[std::size_t(j) * kSize + i + 4], 1e-5) << i << "," << j;
            covered += a > 0.1f;
        }
    EXPECT_GT(covered, 20);
}

// meshes_shadow_gaussians: a splatted Gaussian is darkened by the lights' visibility from its centre as a traced
// one is. A sun shining along +Y and a box under the Gaussian (out of the camera's view at the centre pixel): where
// the box hides the sun the centre pixel is black, without it the Gaussian's colour, and splatted equals traced there
// (at the centre both give alpha = opacity).
TEST(CameraSplatting, MeshesShadowGaussiansAsTraced) {
    const float q[4] = {1, 0, 0, 0}, s[3] = {0.2f, 0.2f, 0.2f}, pos[3] = {0, 0, -3}, rgb[3] = {0.8f, 0.6f, 0.4f};
    GaussianCloud cloud;
    add_gaussian(cloud, pos, q, s, 0.7f, rgb);
    const float lo[3] = {-1.0f, -1.2f, -4.0f}, hi[3] = {1.0f, -1.0f, -2.0f};
    for (bool blocked : {false, true}) {
        Scene scene;
        const std::uint32_t material = scene.add_material(Material{});
        const TestMesh box = make_box(lo, hi, material);
        if (blocked) scene.add_mesh(box.desc());
        scene.add_gaussians(cloud);
        scene.set_world(black_world());
        scene.add_light(sun_from_below());
        RenderSettings on = splat_settings(true), off = splat_settings(false);
        on.meshes_shadow_gaussians = off.meshes_shadow_gaussians = true;
        const Film splatted = render(scene, pinhole(), on), traced = render(scene, pinhole(), off);
        ASSERT_TRUE(splatted.stats.camera_ray_splatting);
        const std::size_t p = std::size_t(kSize / 2) * kSize + kSize / 2;
        for (int c = 0; c < 3; ++c) {
            EXPECT_NEAR(splatted.rgba()[4 * p + c], traced.rgba()[4 * p + c], 1e-4) << "blocked " << blocked;
            EXPECT_NEAR(splatted.rgba()[4 * p + c], blocked ? 0.0 : srgb_to_linear_ref(0.7 * rgb[c]), 2e-4);
        }
    }
}

// The pre-pass projects four Gaussians to an instruction (CameraSplatPrepass::project4) and the rest one at a time;
// both take the same operations in the same order, so a frame is bit for bit the frame of the one-at-a-time path
// (RAYSPLATS_PROJECTION=scalar): thousands of random Gaussians, flat and volumetric, some behind the camera, some
// thin, in two clouds of which one is moved and turned.
TEST(CameraSplatting, FourAtOnceProjectsAsOneAtATime) {
    const GaussianCloud first = random_cloud(21, 4003, 2.0f), second = random_cloud(22, 1502, 1.5f);
    Scene scene;
    scene.add_gaussians(first, Matrix4::translation(0.3f, -0.2f, -4.0f));
    scene.add_gaussians(second, Matrix4::translation(-0.5f, 0.4f, -3.0f) * Matrix4::rotation(0.6f, 0.3f, 0.9f, 0.2f));
    scene.set_world(black_world());
    for (GaussianMode mode : {GaussianMode::Volumetric, GaussianMode::Flat}) {
        RenderSettings st = splat_settings(true, BlendSpace::Display, mode);
        st.width = 96;
        st.height = 64;
        st.jitter = true;
        const Film four = render(scene, pinhole(), st);
        ::setenv("RAYSPLATS_PROJECTION", "scalar", 1);
        const Film one = render(scene, pinhole(), st);
        ::unsetenv("RAYSPLATS_PROJECTION");
        ASSERT_TRUE(four.stats.camera_ray_splatting);
        EXPECT_GT(four.stats.splats, 3000u);
        EXPECT_EQ(four.stats.splats, one.stats.splats);
        EXPECT_EQ(four.stats.splat_tile_entries, one.stats.splat_tile_entries);
        for (const FilmChannel channel : {FilmChannel::Combined, FilmChannel::Depth, FilmChannel::Alpha})
            EXPECT_EQ(four[channel], one[channel]) << film_channels()[std::size_t(channel)].key;
        double sum = 0.0;
        for (float a : four.alpha()) sum += a;
        EXPECT_GT(sum, 0.05 * four.pixel_count());
    }
}

// The meshes' own top-level scene, which camera-ray splatting traces for its mesh hits and the meshes' shadows on
// Gaussians, follows the meshes: after a quad in front of a Gaussian and a box shading it from the sun are moved away
// (Scene::update_mesh, the scene updated, not rebuilt) the frame equals a fresh scene's with the meshes there, bit
// for bit, and shows the lit Gaussian the meshes hid before.
TEST(CameraSplatting, MovedMeshesAreWhereTheyAreNow) {
    const float q[4] = {1, 0, 0, 0}, s[3] = {0.2f, 0.2f, 0.2f}, pos[3] = {0, 0, -3}, rgb[3] = {0.8f, 0.6f, 0.4f};
    GaussianCloud cloud;
    add_gaussian(cloud, pos, q, s, 0.7f, rgb);
    const float lo[3] = {-1.0f, -1.2f, -4.0f}, hi[3] = {1.0f, -1.0f, -2.0f};
    auto make_scene = [&](Scene& scene, TestMesh& quad, TestMesh& box, bool moved) {
        const std::uint32_t material = scene.add_material(emissive(0.5f, 0.5f, 0.5f));
        quad = make_quad_z(-0.5f, 0.5f, -0.5f, 0.5f, -2.0f, material);
        box = make_box(lo, hi, scene.add_material(Material{}));
        if (moved) {
            quad.object_to_world = Matrix4::translation(20.0f, 0.0f, 0.0f);
            box.object_to_world = Matrix4::translation(0.0f, 0.0f, 30.0f);
        }
        scene.add_mesh(quad.desc());
        scene.add_mesh(box.desc());
        scene.add_gaussians(cloud);
        scene.set_world(black_world());
        scene.add_light(sun_from_below());
    };
    RenderSettings st = splat_settings(true);
    st.meshes_shadow_gaussians = true;
    Scene scene, fresh;
    TestMesh quad, box, fresh_quad, fresh_box;
    make_scene(scene, quad, box, false);
    make_scene(fresh, fresh_quad, fresh_box, true);
    const Film before = render(scene, pinhole(), st);
    ASSERT_TRUE(before.stats.camera_ray_splatting);
    quad.object_to_world = Matrix4::translation(20.0f, 0.0f, 0.0f);
    box.object_to_world = Matrix4::translation(0.0f, 0.0f, 30.0f);
    scene.update_mesh(0, quad.desc());
    scene.update_mesh(1, box.desc());
    const Film after = render(scene, pinhole(), st), expected = render(fresh, pinhole(), st);
    ASSERT_EQ(after.pixel_count(), expected.pixel_count());
    for (std::size_t k = 0; k < 4 * after.pixel_count(); ++k) ASSERT_EQ(after.rgba()[k], expected.rgba()[k]) << k;
    const std::size_t p = std::size_t(kSize / 2) * kSize + kSize / 2;
    for (int c = 0; c < 3; ++c) {
        EXPECT_NEAR(before.rgba()[4 * p + c], 0.5, 1e-4) << "the quad in front";
        EXPECT_NEAR(after.rgba()[4 * p + c], srgb_to_linear_ref(0.7 * rgb[c]), 2e-4) << "the Gaussian, lit";
    }
}

// Gaussians nearer than the camera's clip start are cut (the rasterizer's near cut), as are those beyond its end.
TEST(CameraSplatting, ClipRangeCutsCentres) {
    const float q[4] = {1, 0, 0, 0}, s[3] = {0.3f, 0.3f, 0.3f}, pos[3] = {0, 0, -3}, rgb[3] = {1, 1, 1};
    GaussianCloud cloud;
    add_gaussian(cloud, pos, q, s, 0.8f, rgb);
    Scene scene;
    scene.add_gaussians(cloud);
    scene.set_world(black_world());
    const std::size_t p = std::size_t(kSize / 2) * kSize + kSize / 2;
    Camera cam = pinhole();
    EXPECT_NEAR(render(scene, cam, splat_settings(true)).alpha()[p], 0.8, 1e-6);
    cam.clip_start = 3.1f;
    EXPECT_EQ(render(scene, cam, splat_settings(true)).alpha()[p], 0.0f);
    cam.clip_start = 0.1f;
    cam.clip_end = 2.9f;
    EXPECT_EQ(render(scene, cam, splat_settings(true)).alpha()[p], 0.0f);
}

// A render cancelled before it starts ends at once, marked cancelled, with an empty film (the pre-pass stops too).
TEST(CameraSplatting, CancelledBeforeStart) {
    const GaussianCloud cloud = random_cloud(5, 1000, 1.0f);
    Scene scene;
    scene.add_gaussians(cloud, Matrix4::translation(0.0f, 0.0f, -4.0f));
    std::atomic<bool> cancel{true};
    const Film film = render(scene, pinhole(), splat_settings(true), {}, &cancel);
    EXPECT_TRUE(film.stats.cancelled);
    EXPECT_EQ(film.stats.samples, 0);
    for (float alpha : film.alpha()) ASSERT_EQ(alpha, 0.0f);
}

// A scene that keeps its frame buffers (Scene::set_keep_frame_buffers, for Persistent Data) renders each frame bit for
// bit as a scene that does not: a frame with fewer splats and tile entries after one with more (what the kept arrays
// held beyond the new frame's lengths), a different image size, and a frame with more entries than any before (the
// arrays grown without what they held). It holds the storage between frames and frees it
// when told to stop keeping it; a scene that does not keep it holds none.
TEST(CameraSplatting, KeptFrameBuffersRenderAsAFreshScene) {
    const GaussianCloud cloud = random_cloud(11, 600, 1.0f);
    Scene kept, fresh;
    for (Scene* scene : {&kept, &fresh}) {
        scene->add_gaussians(cloud, Matrix4::translation(0.0f, 0.0f, -4.0f));
        scene->set_world(black_world());
    }
    kept.set_keep_frame_buffers(true);
    RenderSettings wide = splat_settings(true);
    wide.width = 80;
    wide.height = 60;
    wide.samples = 2;
    wide.jitter = true;
    RenderSettings narrow = wide;
    narrow.width = 48;
    narrow.height = 40;
    Camera near_view = pinhole(), far_view = pinhole();
    near_view.camera_to_world = Matrix4::translation(0.8f, -0.4f, -2.0f);  // closer: fewer, bigger splats in view
    far_view.camera_to_world = Matrix4::translation(0.0f, 0.0f, 6.0f);

    const Film first = render(kept, pinhole(), wide);
    ASSERT_TRUE(first.stats.camera_ray_splatting);
    const std::size_t held = kept.kept_frame_buffer_bytes();
    EXPECT_GT(held, first.stats.splat_bytes);  // (the splats and lists, and the working arrays)
    EXPECT_EQ(first.rgba(), render(fresh, pinhole(), wide).rgba());
    EXPECT_EQ(fresh.kept_frame_buffer_bytes(), 0u);

    RenderSettings big = wide;  // (more tile entries than any frame before: the kept arrays grow)
    big.width = 120;
    big.height = 90;
    for (const auto& [camera, st] : {std::pair{near_view, narrow}, std::pair{far_view, wide}, std::pair{pinhole(), big}}) {
        const Film again = render(kept, camera, st);
        const Film reference = render(fresh, camera, st);
        ASSERT_TRUE(again.stats.camera_ray_splatting);
        EXPECT_EQ(again.stats.splats, reference.stats.splats);
        EXPECT_EQ(again.stats.splat_tile_entries, reference.stats.splat_tile_entries);
        for (const FilmChannel channel : {FilmChannel::Combined, FilmChannel::Depth, FilmChannel::Normal,
                                          FilmChannel::Alpha, FilmChannel::GaussianCount})
            EXPECT_EQ(again[channel], reference[channel]) << film_channels()[std::size_t(channel)].key;
    }
    EXPECT_LT(render(kept, near_view, narrow).stats.splats, first.stats.splats);
    EXPECT_GT(render(kept, pinhole(), big).stats.splat_tile_entries, first.stats.splat_tile_entries);
    EXPECT_GT(kept.kept_frame_buffer_bytes(), held);  // (capacity only grows, and it grew)
    kept.set_keep_frame_buffers(false);
    EXPECT_EQ(kept.kept_frame_buffer_bytes(), 0u);
}

// A kept scene also keeps the render's tiles, and the next render of the same size and passes restarts them in their
// memory: every channel, the Cryptomatte ranks, adaptive sampling's noise sums and the light passes' sums are as a
// fresh render's, bit for bit, the frame after a frame of another view and after one of another size.
TEST(CameraSplatting, KeptTilesRestartAsNewTiles) {
    const GaussianCloud cloud = random_cloud(13, 600, 1.0f);
    Scene kept, fresh;
    for (Scene* scene : {&kept, &fresh}) {
        scene->add_gaussians(cloud, Matrix4::translation(0.0f, 0.0f, -4.0f));
        scene->set_world(black_world());
        scene->set_gaussian_cryptomatte_names(0, "splats", "", "");
    }
    kept.set_keep_frame_buffers(true);
    RenderSettings st = splat_settings(true);
    st.width = 72;
    st.height = 56;
    st.tile_size = 32;  // (several tiles, one of them cut by the image's edge)
    st.samples = 20;
    st.jitter = true;
    st.light_passes = true;
    st.cryptomatte_object = true;
    st.adaptive_sampling = true;
    st.adaptive_threshold = 0.5f;
    st.adaptive_min_samples = 16;  // (its first check is after 16 samples)
    RenderSettings other_size = st;
    other_size.width = 40;
    Camera near_view = pinhole(), far_view = pinhole();
    near_view.camera_to_world = Matrix4::translation(0.8f, -0.4f, -2.0f);
    far_view.camera_to_world = Matrix4::translation(0.0f, 0.0f, 6.0f);
    const std::pair<Camera, RenderSettings> frames[] = {
        {pinhole(), st}, {near_view, st}, {far_view, st}, {pinhole(), other_size}, {near_view, st}};
    for (const auto& [camera, settings] : frames) {
        const Film again = render(kept, camera, settings);
        const Film reference = render(fresh, camera, settings);
        for (const FilmChannelInfo& info : film_channels())
            EXPECT_EQ(again[info.channel], reference[info.channel]) << info.key;
        EXPECT_EQ(again.cryptomatte, reference.cryptomatte);
        EXPECT_EQ(again.stats.samples, reference.stats.samples);
        // (What the tiles sum is there: ids with weights, and pixels that adaptive sampling stopped early.)
        const FloatBuffer& ids = reference.cryptomatte[std::size_t(CryptomatteType::Object)];
        float weights = 0.0f;
        for (std::size_t k = 1; k < ids.size(); k += 2) weights += ids[k];
        EXPECT_GT(weights, 0.0f);
        const FloatBuffer& counts = reference[FilmChannel::SampleCount];
        EXPECT_LT(*std::min_element(counts.begin(), counts.end()), float(settings.samples));
    }
    EXPECT_EQ(fresh.kept_frame_buffer_bytes(), 0u);
    kept.set_keep_frame_buffers(false);
    EXPECT_EQ(kept.kept_frame_buffer_bytes(), 0u);
}
