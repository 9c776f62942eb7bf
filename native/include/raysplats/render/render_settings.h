// What a render is asked for (docs/design.md §6): image size, samples, bounces, how Gaussians are composited, and the
// names by which every front end sets these (the add-on's settings dict, the JSON tool's "render" object and its
// command-line options): one table, render_setting_parameters(), so a setting is spelt the same everywhere.
#pragma once

#include <cstdint>

#include "raysplats/render/parameters.h"
#include "raysplats/render/scene.h"

namespace raysplats {

enum class Compositing {
    Sorted,      // exact front-to-back order: k-nearest buffer per ray, re-traced until the segment is done
    Stochastic,  // one traversal per sample, each candidate accepted with probability alpha, nearest kept
};

// The colour space in which Gaussian colours along a ray are composited (docs/design.md §4). Colours from SH are
// display (sRGB) values, and scenes are trained, and every splat viewer draws them, by compositing those values as they
// are (C = sum T_i a_i c_i, then shown as is): Display reproduces that, converting the composite to linear where it
// meets meshes, lights and the film, so an unedited scene under Blender's Standard view transform looks as in its
// viewer. Linear composites the decoded (linear) colours, physically additive light; it makes every semi-transparent
// pixel (haze, floaters, soft edges) brighter than the scene was trained to be (2.8-4.5x on real scenes).
enum class BlendSpace {
    Display,  // as trained and as splat viewers draw (the default)
    Linear,   // linear light
};

// The pixel filter: how camera samples spread around their pixel's centre (Cycles' Film > Pixel Filter; see
// src/render/pixel_filter.h for the shapes and what their widths mean).
enum class PixelFilter {
    Box,             // uniform over the width (width 1: the pixel's own square)
    Gaussian,        // exp(-8 x^2 / w^2)
    BlackmanHarris,  // Cycles' default, at width 1.5
};

struct RenderSettings {
    int width = 640;
    int height = 480;
    int samples = 16;        // per pixel, 1 .. 1 << 20
    int max_bounces = 4;     // 0 = direct light only, up to 1024
    std::uint32_t seed = 0;  // the image is a function of the seed only (not of thread scheduling)
    Compositing compositing = Compositing::Sorted;
    BlendSpace blend_space = BlendSpace::Display;
    float transmittance_threshold = 1e-3f;  // stop compositing when T drops below this, in [0, 1)
    GaussianMode gaussian_mode = GaussianMode::Flat;
    // Gaussians carry baked radiance; with this their colour is scaled by the lights' visibility from the
    // Gaussian centre (meshes only occlude), so meshes cast shadows on splats.
    bool meshes_shadow_gaussians = false;
    // How Gaussians' colours are produced (BAKED: as trained; LIT: shaded by the lights and world; BAKED_SHADOWED:
    // baked times the lights' visibility), for every Gaussian cloud without its own (Scene::set_gaussian_shading).
    // meshes_shadow_gaussians applies to BAKED clouds only.
    GaussianShading gaussian_shading = GaussianShading::Baked;
    int tile_size = 32;
    // k of the per-ray k-nearest buffer (1 .. 128). Any k gives the same image; it trades re-traces against
    // culling. The buffer is also cut where the transmittance falls below the threshold. 96 covers the ~34
    // Gaussians an indoor ray composites (showroom_1.5M) with room for the out-of-order arrivals of a traversal, so
    // rays are rarely re-traced; larger k gained nothing (bench_render; docs/benchmarks.md has the CPU time per ray
    // for each k).
    int gather_buffer_size = 96;
    // Samples spread around the pixel centre by the pixel filter; when false every sample goes through the centre.
    bool jitter = true;
    // The default, a box of one pixel, is the plain jitter inside the pixel that images had before filters existed.
    PixelFilter pixel_filter = PixelFilter::Box;
    float filter_width = 1.0f;  // in pixels, 0.01 .. 10 (Cycles' range)
    // true: camera rays that escape show nothing (rgba is premultiplied by coverage, Blender's Film >
    // Transparent). false: they show the world, and rgba alpha is 1. The alpha buffer is coverage either way.
    bool transparent_background = false;
    // Cycles' "Caustics" (Render > Light Paths > Caustics, defaults on): when off, a path whose last bounce was
    // diffuse gets no glossy/specular reflection (refraction) lobes at its next surface, so it cannot make
    // reflective (refractive) caustics; a surface left without lobes (a mirror, a metal) absorbs such paths.
    bool caustics_reflective = true;
    bool caustics_refractive = true;
    // Sorted mode: camera rays first traverse the scene only up to a little beyond where their neighbours' (or,
    // after the first sample, their own previous) camera segments ended, and go on from there when that was too
    // early: the traversal then skips what lies behind the first opaque layer. The image is the same either way (the
    // same Gaussians composited in the same order); off is for tests and measurements.
    bool speculative_ends = true;
    // Camera-ray splatting (src/render/camera_splatting.h): a perspective camera's rays draw the Gaussians in front of
    // their first mesh hit as splat viewers do (each Gaussian's EWA footprint, composited in the order of centre
    // depth, one sort per frame) instead of tracing them, so an unedited scene matches its viewer where large or thin
    // Gaussians make the two models differ; then they go on to that mesh or the world as traced rays do. Every other
    // ray is traced. Needs every Gaussian cloud BAKED: with LIT or BAKED_SHADOWED ones, camera rays stay traced.
    bool camera_ray_splatting = false;
    // The Denoising Albedo and Denoising Normal film channels (SampleRecord::denoising_albedo): the denoiser's
    // guides. Off, they stay 0 and nothing is computed for them.
    bool denoising_data = false;
    // The light passes' film channels (SampleRecord::light: Emission, and Diffuse, Glossy and Transmission Direct,
    // Indirect and Color). Off, they stay 0 and nothing is computed for them; on or off, the other channels are the
    // same.
    bool light_passes = false;
    // The Mist film channel (SampleRecord::mist). Off, nothing is computed for it and it holds 1 (only the world).
    bool mist_pass = false;
    // The Cryptomatte passes (raysplats/render/cryptomatte.h): which kinds of id the film ranks per pixel, and
    // Blender's Levels (ranks per pixel, 1 .. 16, rounded up to even). All off, nothing is computed for them.
    bool cryptomatte_object = false;
    bool cryptomatte_material = false;
    bool cryptomatte_asset = false;
    int cryptomatte_levels = 6;
    // The Shadow Catcher pass is written (MeshDesc::shadow_catcher): as in Cycles, Combined then leaves shadow
    // catchers transparent, their shadow being in the pass, with or without a transparent background; without the
    // pass, Combined carries the shadow (as alpha, or over the world's colour).
    bool shadow_catcher_pass = false;

    // Adaptive sampling (Cycles' Sampling > Noise Threshold): once a pixel's estimated noise is below the threshold
    // it receives no more samples, so the samples go where the image is still noisy (edges, soft shadows). The
    // estimate is Cycles' (film.h, FilmTile::noise_estimate), checked every kAdaptiveStep samples once a pixel has
    // the minimum; a pixel next to a noisy one keeps sampling. Each pixel's image is then its render at its own
    // sample count (the same seeds). Off renders every pixel `samples` times, bit for bit as before.
    bool adaptive_sampling = false;
    // Noise level at which a pixel stops, in Cycles' units (typical 0.1 .. 0.001); 0: automatic,
    // max(0.001, 1 / samples) (Cycles' rule).
    float adaptive_threshold = 0.01f;
    // Samples every pixel gets before it may stop; 0: automatic, ceil(16 / threshold^0.3) (Cycles' rule: 0.1 -> 32,
    // 0.01 -> 64, 0.001 -> 128); at least 4 either way.
    int adaptive_min_samples = 0;

    // The render region (Blender's Render Region / border): only pixels [region_x, region_x + region_width) x
    // [region_y, region_y + region_height) are rendered, in film pixels (row 0 at the top); the film keeps the full
    // image size and the pixels outside hold the channels' empty values. A pixel inside is the same as in the whole
    // image's render (its samples' seeds depend on its place in the whole image). Width or height 0: the whole image.
    int region_x = 0;
    int region_y = 0;
    int region_width = 0;
    int region_height = 0;

    // Throws InvalidArgument with the offending setting.
    void validate() const;
};

// Samples between two noise checks of adaptive sampling (Cycles' adaptive_step); even, so that the odd samples are
// half of a pixel's samples at each check.
constexpr int kAdaptiveStep = 16;

// The threshold and minimum sample count adaptive sampling uses (the automatic rules applied); threshold 0 when
// settings.adaptive_sampling is off. The threshold is in Cycles' units before its internal factor 5.
struct AdaptiveSampling {
    float threshold = 0.0f;
    int min_samples = 0;
    bool on() const { return threshold > 0.0f; }
};
AdaptiveSampling adaptive_sampling_of(const RenderSettings& settings);

// The rendered rectangle [x0, x1) x [y0, y1) of the film: the region, or the whole image.
struct PixelRect {
    int x0, y0, x1, y1;
    int width() const { return x1 - x0; }
    int height() const { return y1 - y0; }
};
PixelRect render_region_of(const RenderSettings& settings);

// The names of the enums above and of GaussianMode ("SORTED", "FLAT", ...).
const NameTable<Compositing>& compositing_names();
const NameTable<BlendSpace>& blend_space_names();
const NameTable<GaussianMode>& gaussian_mode_names();
const NameTable<PixelFilter>& pixel_filter_names();
const NameTable<GaussianShading>& gaussian_shading_names();

// Every field of RenderSettings by name (the field's own name), with its type and what it sets.
const ParameterTable<RenderSettings>& render_setting_parameters();

}  // namespace raysplats
