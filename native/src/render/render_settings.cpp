// RenderSettings (raysplats/render/render_settings.h): validation and the table of setting names.
#include "raysplats/render/render_settings.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "raysplats/errors.h"

namespace raysplats {

void RenderSettings::validate() const {
    auto require = [](bool ok, const std::string& problem) {
        if (!ok) throw InvalidArgument("render settings: " + problem);
    };
    require(width > 0 && height > 0, "image size must be at least 1 x 1 (got " + std::to_string(width) + " x " +
                                         std::to_string(height) + ")");
    require(width <= 65536 && height <= 65536 && std::int64_t(width) * height <= (std::int64_t(1) << 28),
            "image size " + std::to_string(width) + " x " + std::to_string(height) + " is too large (max 2^28 pixels)");
    require(samples >= 1 && samples <= (1 << 20), "samples per pixel must be in 1 .. 1048576 (got " + std::to_string(samples) + ")");
    require(max_bounces >= 0 && max_bounces <= 1024, "max bounces must be in 0 .. 1024 (got " + std::to_string(max_bounces) + ")");
    require(std::isfinite(transmittance_threshold) && transmittance_threshold >= 0.0f && transmittance_threshold < 1.0f,
            "transmittance threshold must be in [0, 1)");
    require(gather_buffer_size >= 1 && gather_buffer_size <= 128,
            "gather buffer size must be in 1 .. 128 (got " + std::to_string(gather_buffer_size) + ")");
    require(std::isfinite(filter_width) && filter_width >= 0.01f && filter_width <= 10.0f,
            "filter width must be in 0.01 .. 10 pixels (got " + std::to_string(filter_width) + ")");
    require(std::isfinite(adaptive_threshold) && adaptive_threshold >= 0.0f && adaptive_threshold <= 1.0f,
            "adaptive threshold must be in [0, 1] (0: automatic; got " + std::to_string(adaptive_threshold) + ")");
    require(adaptive_min_samples >= 0 && adaptive_min_samples <= (1 << 20),
            "adaptive min samples must be in 0 .. 1048576 (0: automatic; got " + std::to_string(adaptive_min_samples) + ")");
    const bool whole = region_width == 0 || region_height == 0;
    require(whole || (region_width > 0 && region_height > 0 && region_x >= 0 && region_y >= 0 &&
                      std::int64_t(region_x) + region_width <= width && std::int64_t(region_y) + region_height <= height),
            "render region " + std::to_string(region_width) + " x " + std::to_string(region_height) + " at (" +
                std::to_string(region_x) + ", " + std::to_string(region_y) + ") is not inside the " +
                std::to_string(width) + " x " + std::to_string(height) + " image");
    require(cryptomatte_levels >= 1 && cryptomatte_levels <= 16,
            "cryptomatte levels must be in 1 .. 16 (got " + std::to_string(cryptomatte_levels) + ")");
    require(tile_size >= 1 && tile_size <= 4096, "tile size must be in 1 .. 4096 (got " + std::to_string(tile_size) + ")");
}

AdaptiveSampling adaptive_sampling_of(const RenderSettings& settings) {
    AdaptiveSampling a;
    if (!settings.adaptive_sampling) return a;
    // Cycles' Integrator::get_adaptive_sampling (intern/cycles/scene/integrator.cpp).
    a.threshold = settings.adaptive_threshold > 0.0f ? settings.adaptive_threshold
                                                     : std::max(0.001f, 1.0f / float(settings.samples));
    a.min_samples = settings.adaptive_min_samples > 0
                        ? settings.adaptive_min_samples
                        : int(std::ceil(16.0f / std::pow(a.threshold, 0.3f)));
    a.min_samples = std::max(4, a.min_samples);
    return a;
}

PixelRect render_region_of(const RenderSettings& settings) {
    if (settings.region_width == 0 || settings.region_height == 0) return {0, 0, settings.width, settings.height};
    return {settings.region_x, settings.region_y, settings.region_x + settings.region_width,
            settings.region_y + settings.region_height};
}

const NameTable<Compositing>& compositing_names() {
    static const NameTable<Compositing> names{
        "compositing",
        {{"SORTED", Compositing::Sorted, "Gaussians composited in exact depth order (the reference)"},
         {"STOCHASTIC", Compositing::Stochastic,
          "each Gaussian accepted with probability alpha: faster per sample, converges to the sorted image"}}};
    return names;
}

const NameTable<BlendSpace>& blend_space_names() {
    static const NameTable<BlendSpace> names{
        "blend space",
        {{"DISPLAY", BlendSpace::Display,
          "Gaussian colours composited as trained, in display (sRGB) space, then made linear: looks as in splat viewers"},
         {"LINEAR", BlendSpace::Linear,
          "Gaussian colours made linear, then composited: physically additive, brighter where Gaussians are "
          "semi-transparent"}}};
    return names;
}

const NameTable<GaussianMode>& gaussian_mode_names() {
    static const NameTable<GaussianMode> names{
        "Gaussian mode",
        {{"FLAT", GaussianMode::Flat, "a flat disk evaluated where the ray meets its plane"},
         {"VOLUMETRIC", GaussianMode::Volumetric, "an ellipsoid (uses the stored thickness)"}}};
    return names;
}

const NameTable<GaussianShading>& gaussian_shading_names() {
    static const NameTable<GaussianShading> names{
        "Gaussian shading",
        {{"BAKED", GaussianShading::Baked, "the captured light, as trained"},
         {"LIT", GaussianShading::Lit, "surface elements shaded by the scene's lights and world, with shadows"},
         {"BAKED_SHADOWED", GaussianShading::BakedShadowed, "the captured light times the lights' visibility"}}};
    return names;
}

const NameTable<PixelFilter>& pixel_filter_names() {
    static const NameTable<PixelFilter> names{
        "pixel filter",
        {{"BOX", PixelFilter::Box, "uniform over the filter width (width 1: the pixel's square)"},
         {"GAUSSIAN", PixelFilter::Gaussian, "Gaussian, sigma = width / 4"},
         {"BLACKMAN_HARRIS", PixelFilter::BlackmanHarris, "Blackman-Harris window over twice the width (Cycles' default)"}}};
    return names;
}

const ParameterTable<RenderSettings>& render_setting_parameters() {
    using namespace parameter_setters;
    using T = ParameterType;
    using S = RenderSettings;
    static const ParameterTable<RenderSettings> table{
        "render setting",
        {{"width", T::Integer, "image width in pixels", &member<&S::width>, {}},
         {"height", T::Integer, "image height in pixels", &member<&S::height>, {}},
         {"samples", T::Integer, "samples per pixel", &member<&S::samples>, {}},
         {"max_bounces", T::Integer, "reflections and refractions followed per path (0: direct light only)",
          &member<&S::max_bounces>, {}},
         {"seed", T::Integer, "seed of the sampling pattern (0 .. 2^32 - 1)", &member<&S::seed>, {}},
         {"compositing", T::Name, "how Gaussians along a ray are combined", &named<&S::compositing, &compositing_names>,
          compositing_names().names()},
         {"blend_space", T::Name, "colour space Gaussians along a ray are composited in (DISPLAY: as splat viewers)",
          &named<&S::blend_space, &blend_space_names>, blend_space_names().names()},
         {"transmittance_threshold", T::Real, "stop compositing once the transmittance is below this, in [0, 1)",
          &member<&S::transmittance_threshold>, {}},
         {"gaussian_mode", T::Name, "geometry the Gaussians are traced as",
          &named<&S::gaussian_mode, &gaussian_mode_names>, gaussian_mode_names().names()},
         {"meshes_shadow_gaussians", T::Bool, "lights' visibility from each Gaussian's centre darkens it",
          &member<&S::meshes_shadow_gaussians>, {}},
         {"gaussian_shading", T::Name, "how Gaussians' colours are produced (clouds without their own shading)",
          &named<&S::gaussian_shading, &gaussian_shading_names>, gaussian_shading_names().names()},
         {"tile_size", T::Integer, "edge of the square tiles rendered in parallel, in pixels", &member<&S::tile_size>, {}},
         {"gather_buffer_size", T::Integer, "k of the per-ray k-nearest Gaussian buffer (any k gives the same image)",
          &member<&S::gather_buffer_size>, {}},
         {"jitter", T::Bool, "samples spread by the pixel filter (false: through the pixel centre)", &member<&S::jitter>, {}},
         {"pixel_filter", T::Name, "shape of the pixel filter the samples are drawn from",
          &named<&S::pixel_filter, &pixel_filter_names>, pixel_filter_names().names()},
         {"filter_width", T::Real, "width of the pixel filter in pixels (0.01 .. 10)", &member<&S::filter_width>, {}},
         {"transparent_background", T::Bool, "escaping camera rays show nothing (false: the world)",
          &member<&S::transparent_background>, {}},
         {"caustics_reflective", T::Bool, "diffuse paths continue through glossy reflections (Cycles' Caustics)",
          &member<&S::caustics_reflective>, {}},
         {"caustics_refractive", T::Bool, "diffuse paths continue through refraction (Cycles' Caustics)",
          &member<&S::caustics_refractive>, {}},
         {"speculative_ends", T::Bool, "sorted camera rays first traverse up to their neighbours' ends (same image)",
          &member<&S::speculative_ends>, {}},
         {"camera_ray_splatting", T::Bool,
          "camera rays draw Gaussians as splat viewers do (EWA footprints in centre-depth order); BAKED scenes only",
          &member<&S::camera_ray_splatting>, {}},
         {"denoising_data", T::Bool, "fill the Denoising Albedo and Denoising Normal channels (the denoiser's guides)",
          &member<&S::denoising_data>, {}},
         {"light_passes", T::Bool, "fill the light passes' channels (Emission; Diffuse, Glossy and Transmission Direct, "
          "Indirect and Color)", &member<&S::light_passes>, {}},
         {"mist_pass", T::Bool, "fill the Mist channel (off: nothing is computed for it, it holds 1)",
          &member<&S::mist_pass>, {}},
         {"cryptomatte_object", T::Bool, "fill the Cryptomatte Object passes (ids of object names, ranked by coverage)",
          &member<&S::cryptomatte_object>, {}},
         {"cryptomatte_material", T::Bool, "fill the Cryptomatte Material passes (ids of material names)",
          &member<&S::cryptomatte_material>, {}},
         {"cryptomatte_asset", T::Bool, "fill the Cryptomatte Asset passes (ids of the top-level parents' names)",
          &member<&S::cryptomatte_asset>, {}},
         {"cryptomatte_levels", T::Integer, "ids kept per pixel in each Cryptomatte pass (1 .. 16, rounded up to even)",
          &member<&S::cryptomatte_levels>, {}},
         {"shadow_catcher_pass", T::Bool,
          "the Shadow Catcher pass is written: Combined leaves shadow catchers transparent (their shadow is the pass's)",
          &member<&S::shadow_catcher_pass>, {}},
         {"adaptive_sampling", T::Bool, "pixels stop sampling once their noise is below the threshold (Cycles' Noise Threshold)",
          &member<&S::adaptive_sampling>, {}},
         {"adaptive_threshold", T::Real, "noise level at which a pixel stops sampling (0: automatic from samples)",
          &member<&S::adaptive_threshold>, {}},
         {"adaptive_min_samples", T::Integer, "samples every pixel gets before it may stop (0: automatic from the threshold)",
          &member<&S::adaptive_min_samples>, {}},
         {"region_x", T::Integer, "left edge of the render region, in pixels", &member<&S::region_x>, {}},
         {"region_y", T::Integer, "top edge of the render region, in pixels from the top", &member<&S::region_y>, {}},
         {"region_width", T::Integer, "width of the render region in pixels (0: the whole image)",
          &member<&S::region_width>, {}},
         {"region_height", T::Integer, "height of the render region in pixels (0: the whole image)",
          &member<&S::region_height>, {}}}};
    return table;
}

}  // namespace raysplats
