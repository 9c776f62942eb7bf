// The renderer's output: named film channels (render passes), each a float buffer a binding can expose to numpy
// without copies. What a channel holds is one function of the per-sample record the path integrator returns
// (SampleRecord), so a new pass is one field there and one row of film_channels(); the bindings, the Blender
// engine's pass registration and its result writer all iterate that table (pbrt-v4's VisibleSurface -> film).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "raysplats/default_init_allocator.h"
#include "raysplats/render/cryptomatte.h"
#include "raysplats/render/render_settings.h"

namespace raysplats {

// The renderer writes every pixel of the film from its tiles, in parallel (DefaultInitAllocator), so a film costs
// no serial zeroing and page faults before the first ray.
using FloatBuffer = std::vector<float, DefaultInitAllocator<float>>;

// SampleRecord::light's rows, in the order of their film channels (FilmChannel::Emission onwards).
enum class LightPass : std::uint8_t {
    Emission, DiffuseDirect, DiffuseIndirect, DiffuseColor, GlossyDirect, GlossyIndirect, GlossyColor,
    TransmissionDirect, TransmissionIndirect, TransmissionColor
};
constexpr std::size_t kLightPassCount = 10;

// What one camera sample contributes to its pixel. Produced by the path integrator for every sample.
struct SampleRecord {
    std::array<float, 3> radiance{0.0f, 0.0f, 0.0f};  // linear
    // RenderSettings::blend_space Display: the camera ray's first run of Gaussians, composited in display space
    // (D = sum T_i a_i c_i, display colours; T its transmittance) and the linear radiance behind it times T. The film
    // combines them per pixel from their means over the samples (FilmTile::write_to):
    //     rgb = mean(radiance) + linear(mean(D) + mean(T) display(mean(T L_behind) / mean(T))),
    // which is linear(D + T display(L_behind)) for one ray, and to which stochastic compositing (one display colour
    // c_i with probability T_i a_i, else D = 0, T = 1 and what lies behind) converges as samples grow. `radiance` is
    // then only the area lights seen inside that run. Unused (false, zeros) in linear blend space.
    bool display_blend = false;
    std::array<float, 3> display_radiance{0.0f, 0.0f, 0.0f};
    float display_transmittance = 0.0f;
    std::array<float, 3> behind_radiance{0.0f, 0.0f, 0.0f};
    float alpha = 0.0f;    // coverage: 1 - transmittance of the primary segment (1 where an opaque surface was hit)
    // Distance along the camera ray to the first surface where the accumulated opacity reaches 0.5; +inf where
    // there is none.
    float depth = std::numeric_limits<float>::infinity();
    std::array<float, 3> normal{0.0f, 0.0f, 0.0f};  // world-space normal at that surface, 0 where none
    // The data passes of Blender's compositor, taken at that surface too (Cycles, kernel/film/data_passes.h, takes
    // them at the first surface a camera ray meets whose alpha reaches its pass alpha threshold, 0.5): its world
    // position (the camera ray's point at `depth`), its object's pass index and its material's (a Gaussian's: those
    // its cloud was given, Scene::set_gaussian_pass_indices); 0 where there is none (the world), as in Cycles.
    std::array<float, 3> position{0.0f, 0.0f, 0.0f};
    float object_index = 0.0f;
    float material_index = 0.0f;
    // Mist (Cycles' film_write_data_passes): 1 - sum_i w_i (1 - mist(d_i)) over everything the camera ray composited
    // or stopped on, w_i its weight in the pixel (the transmittance in front of it times its alpha; a mesh it stopped
    // on, or the Gaussian that terminated compositing, takes all the transmittance left), d_i its distance from the
    // camera (src/render/mist.h). 1 where the ray sees only the world, and everywhere without
    // RenderSettings::mist_pass (nothing is computed for it then).
    float mist = 1.0f;
    // The denoiser's guides (RenderSettings::denoising_data; 0 without it), as Cycles' Denoising Albedo and Normal
    // (kernel/film/denoising_passes.h): the surface colour and the normal the camera ray sees, each weighted as the
    // pixel weighs what the ray composited: sum_i T_i a_i x_i over the camera segment's Gaussians (a Gaussian that
    // ends compositing takes the transmittance left, as for mist), plus T x_mesh at the mesh the ray stops on, plus
    // T x_world where it escapes. x is the albedo: a Gaussian's linear colour (BAKED: the colour it shows; LIT: its
    // albedo), the mesh material's base colour (metals and glass too), the world's colour (0 with a transparent
    // background), each clamped to [0, 1]; or the world-space normal facing the camera: a flat Gaussian's plane
    // normal, a volumetric one's -ray direction (as the Normal pass), the mesh's shading normal, 0 for the world.
    std::array<float, 3> denoising_albedo{0.0f, 0.0f, 0.0f};
    std::array<float, 3> denoising_normal{0.0f, 0.0f, 0.0f};
    // The light passes (RenderSettings::light_passes; all 0 and `light_passes` false without it), Cycles' split of
    // the radiance (kernel/film/light_passes.h), linear, premultiplied like `radiance`, indexed by LightPass:
    // Emission: light emitted towards the camera by what it sees before the path's first scattering (mesh emission,
    // area lights, BAKED Gaussians' radiance), times the transmittance in front of it. In display blend space the
    // camera ray's first run of Gaussians adds its own part at the film, and what lies behind it is attenuated as the
    // display blend attenuates it: with the pixel's means, the light behind, B = mean(T L_behind), is seen as
    // linear(mean T display(B / mean T)) = s B (s <= 1 per channel), so every pass behind is scaled by s and Emission
    // gains linear(mean D + mean T display(B / mean T)) - s B >= 0 (FilmTile::write_to).
    // Direct: next-event estimation at the first scattering surface (a mesh, or LIT and BAKED_SHADOWED Gaussians),
    // and what is emitted towards it (meshes, lights, the world, BAKED Gaussians) one bounce later; Indirect: every
    // later contribution. Each goes to the diffuse, glossy or transmission lobe of that first surface, in the shares
    // of the BSDF evaluation that carried it (Cycles' pass_diffuse_weight and pass_glossy_weight).
    // Color: the lobes' albedos at every surface met before the first scattering, times the throughput there
    // (Cycles' film_write_data_passes). The film divides Direct and Indirect by Color (Cycles'
    // safe_divide_even_color), as Blender receives them from Cycles, so that
    //     sum over lobes of (Direct + Indirect) Color + Emission + (the world seen directly) = Combined.
    // The world seen before the first scattering is in none of them (Cycles' Environment pass).
    bool light_passes = false;
    std::array<std::array<float, 3>, kLightPassCount> light{};
    // Display blend space: the part of light[Emission] in front of the camera ray's first run (area lights seen
    // there); the film attenuates the rest as the display blend attenuates what lies behind the run.
    std::array<float, 3> front_emission{0.0f, 0.0f, 0.0f};
    // The Vector pass (Cycles' motion pass, kernel/geom/primitive.h): the motion on the image, in pixels with y
    // growing up, of the point at `depth` from the previous frame and to the next, (pre.x, pre.y, post.x, post.y) =
    // (raster(previous) - raster(now), raster(now) - raster(next)); 0 where there is no surface, or where the camera
    // has no frame motion (Camera::frame_motion) or is panoramic (src/render/motion_vectors.h).
    std::array<float, 4> vector{0.0f, 0.0f, 0.0f, 0.0f};
    // Blender's Holdout (MeshDesc::holdout, Scene::set_gaussian_holdout), as Cycles' film_write_holdout: the fraction
    // of the camera ray held out, sum of the transmittance in front of each held-out surface times its alpha (a
    // held-out mesh takes all that is left; a terminating Gaussian too, as for mist). Combined's alpha is the
    // coverage less it (1 less it with an opaque background), so a held-out object leaves alpha 0 and no colour
    // where it is seen; the Alpha pass stays the coverage.
    float holdout = 0.0f;
    // The Environment pass (Cycles' PASS_BACKGROUND): the world's colour times the camera ray's transmittance where it
    // escapes (through Gaussians and transparent meshes), whether or not the background is transparent; 0 where it
    // stops on a surface.
    std::array<float, 3> environment{0.0f, 0.0f, 0.0f};
    // The Shadow Catcher pass (MeshDesc::shadow_catcher): 1 - T (1 - r) where the camera ray meets a shadow catcher
    // through transmittance T, r the ratio of the lights' direct light there with visibility to that without; 1
    // elsewhere. Multiplying a photograph by it darkens it where the scene's objects shadow the catcher.
    std::array<float, 3> shadow_catcher{1.0f, 1.0f, 1.0f};
    // Gaussians the camera segment composited (sorted) or accepted (stochastic: 0 or 1 per segment) before it
    // ended; a debug measure of how much each pixel costs.
    float gaussian_count = 0.0f;
    // The Cryptomatte passes (RenderSettings::cryptomatte_*; empty without them): the weight of each thing the camera
    // ray composited, weighted as mist weighs it (w_i above), by its ids (raysplats/render/cryptomatte.h).
    CryptomatteCoverage cryptomatte;
};

enum class FilmChannel : std::uint8_t {
    Combined, Depth, Normal, Alpha, GaussianCount, SampleCount, Mist, Position, ObjectIndex, MaterialIndex,
    DenoisingAlbedo, DenoisingNormal,
    Emission, DiffuseDirect, DiffuseIndirect, DiffuseColor, GlossyDirect, GlossyIndirect, GlossyColor,
    TransmissionDirect, TransmissionIndirect, TransmissionColor, Vector, Environment, ShadowCatcher
};
constexpr std::size_t kFilmChannelCount = 25;


// How a channel combines the samples of a pixel.
enum class SampleCombination : std::uint8_t {
    Mean,         // average over every sample (radiance, coverage)
    FirstSample,  // the pixel's first sample (depth and normal: an average of two depths is no surface's depth)
    Sum,          // the sum over the samples, not divided (counts: the samples a pixel received)
};

struct FilmChannelInfo {
    FilmChannel channel;
    const char* key;        // the channel's name in the bindings' result dict and on the command line
    const char* pass_name;  // the render pass it fills (Blender's name where Blender has the pass)
    // One letter per component as render passes name them ("RGBA", "Z", "XYZ", "A"); its length is the count.
    const char* components;
    const char* kind;       // "COLOR", "VALUE" or "VECTOR"
    SampleCombination combination;
    float empty_value;      // what a pixel holds where no sample wrote it (cleared and cancelled tiles)
    const char* description;
    // The channel's values of one sample (`components` floats).
    void (*from_sample)(const SampleRecord& sample, float* out);
    int component_count() const;
};

// Every channel of the film, in FilmChannel order.
const std::array<FilmChannelInfo, kFilmChannelCount>& film_channels();
const FilmChannelInfo& film_channel_info(FilmChannel channel);

// Which channels a film holds, indexed by FilmChannel.
using FilmChannelSet = std::array<bool, kFilmChannelCount>;
// Every channel.
FilmChannelSet all_film_channels();
// The channels a render with `settings` computes: a channel whose pass needs a setting (the denoiser's guides
// denoising_data, the light passes light_passes) is left out without it, so that it costs neither memory nor work
// (at 3840 x 2160 the light passes alone are 1 GB of film and as much again in its tiles).
FilmChannelSet computed_film_channels(const RenderSettings& settings);

struct RenderStats {
    double render_seconds = 0.0;
    // Camera samples taken (one per pixel and sample, each a primary ray unless the camera has none there, outside a
    // fisheye's circle). Divided by the rendered pixels: the mean samples per pixel, which adaptive sampling lowers.
    std::uint64_t camera_rays = 0;
    std::uint64_t traced_rays = 0;       // every rtcIntersect1/rtcOccluded1 call, including re-traces
    std::uint64_t gaussian_hits = 0;     // Gaussians composited (sorted) or accepted candidates (stochastic)
    // Gaussian intersection tests run by the traversals, and the groups of Gaussians (Embree primitives) they belong
    // to; with camera-ray splatting, also the footprint tests of camera samples and the tile-list entries read.
    std::uint64_t gaussian_candidates = 0;
    std::uint64_t gaussian_group_candidates = 0;
    // Samples per pixel the film holds: the settings' samples for a finished render; for a cancelled one the
    // sample passes every tile completed (a tile may hold one more, see render()); for a snapshot the passes done.
    // With adaptive sampling, the most any pixel holds (the sample_count channel has each pixel's).
    int samples = 0;
    bool cancelled = false;
    // RenderSettings::camera_ray_splatting: whether it drew this render's camera rays (not for a camera or scene it
    // does not apply to), the time of its pre-pass, and what the pre-pass holds: splats (Gaussians in view), tile list
    // entries, and the bytes of both.
    bool camera_ray_splatting = false;
    // With the setting on, why it did not draw them (CameraSplatting::traced_reason: "needs a perspective camera",
    // "needs a camera without depth of field", "needs every Gaussian object Baked", "needs no Gaussian object held
    // out"); empty when it did or was off.
    std::string camera_rays_traced_reason;
    double splat_prepass_seconds = 0.0;
    std::uint64_t splats = 0;
    std::uint64_t splat_tile_entries = 0;
    std::uint64_t splat_bytes = 0;
    // Where render_seconds went, in wall seconds and in the process's CPU seconds (every thread's, so what other
    // threads of the process do meanwhile counts too): the scene's build when render() had to do it, the camera-ray
    // splatting pre-pass, the sample passes (adaptive sampling's checks included) and writing the film.
    double build_seconds = 0.0, build_cpu_seconds = 0.0;
    double splat_prepass_cpu_seconds = 0.0;
    double sample_seconds = 0.0, sample_cpu_seconds = 0.0;
    double film_seconds = 0.0, film_cpu_seconds = 0.0;
};

// Rows are stored top to bottom (row 0 is the top of the image), pixels left to right; a channel with C components
// holds width * height * C floats.
struct Film {
    int width = 0;
    int height = 0;
    std::array<FloatBuffer, kFilmChannelCount> channels;
    // The Cryptomatte passes the render filled (by CryptomatteType; empty for the others): per pixel `ranks` (id,
    // coverage) pairs sorted by coverage, largest first, i.e. the passes' RGBA layers one after the other
    // (raysplats/render/cryptomatte.h has the layout).
    std::array<FloatBuffer, kCryptomatteTypes> cryptomatte;
    int cryptomatte_ranks = 0;
    RenderStats stats;

    FloatBuffer& operator[](FilmChannel c) { return channels[std::size_t(c)]; }
    const FloatBuffer& operator[](FilmChannel c) const { return channels[std::size_t(c)]; }
    // The channels by name. rgba: linear, premultiplied (see RenderSettings::transparent_background); alpha is
    // coverage whether or not the background is transparent.
    FloatBuffer& rgba() { return (*this)[FilmChannel::Combined]; }
    const FloatBuffer& rgba() const { return (*this)[FilmChannel::Combined]; }
    FloatBuffer& depth() { return (*this)[FilmChannel::Depth]; }
    const FloatBuffer& depth() const { return (*this)[FilmChannel::Depth]; }
    FloatBuffer& normal() { return (*this)[FilmChannel::Normal]; }
    const FloatBuffer& normal() const { return (*this)[FilmChannel::Normal]; }
    FloatBuffer& alpha() { return (*this)[FilmChannel::Alpha]; }
    const FloatBuffer& alpha() const { return (*this)[FilmChannel::Alpha]; }
    FloatBuffer& gaussian_count() { return (*this)[FilmChannel::GaussianCount]; }
    const FloatBuffer& gaussian_count() const { return (*this)[FilmChannel::GaussianCount]; }
    FloatBuffer& sample_count() { return (*this)[FilmChannel::SampleCount]; }
    const FloatBuffer& sample_count() const { return (*this)[FilmChannel::SampleCount]; }

    // An empty film: every channel at its empty value.
    void resize(int width, int height);
    // Sizes the buffers of `channels` without writing them (their contents are unspecified until written), and
    // leaves the others empty: for writers that write every pixel, such as the renderer.
    void allocate(int width, int height, const FilmChannelSet& channels = all_film_channels());
    // Sizes the Cryptomatte buffers of `layout`'s types (unwritten, as allocate()); the others are emptied.
    void allocate_cryptomatte(const CryptomatteLayout& layout);
    // Writes the empty values into pixels [x0, x1) x [y0, y1) of every channel it holds (Cryptomatte: no ids).
    void clear(int x0, int y0, int x1, int y1);
    std::size_t pixel_count() const { return std::size_t(width) * std::size_t(height); }
    const float* pixel(int x, int y) const { return &rgba()[4 * (std::size_t(y) * width + x)]; }

    // Writers: PNG is 8-bit sRGB (the linear buffer clamped and encoded), PFM is the float RGB buffer.
    // Both write atomically (temporary file, then rename); failures throw raysplats::Error.
    void write_png(const std::string& path) const;
    void write_pfm(const std::string& path) const;
};

// One tile's samples, combined channel by channel (SampleCombination) and then written into the film. The
// renderer keeps one per tile so that tiles run in parallel without sharing sums. Each pixel counts its own
// samples (adaptive sampling gives pixels different counts).
class FilmTile {
public:
    // Pixels [x0, x1) x [y0, y1) of the film. With `noise_estimates`, the tile also sums each pixel's odd samples'
    // radiance (Cycles' adaptive auxiliary buffer), for noise_estimate(). With a `cryptomatte` layout that is on, it
    // keeps each pixel's ids and their summed weights for those passes (raysplats/render/cryptomatte.h). Only
    // `channels` are summed (the film written to holds at least those).
    FilmTile(int x0, int y0, int x1, int y1, bool noise_estimates = false, const CryptomatteLayout& cryptomatte = {},
             const FilmChannelSet& channels = all_film_channels());
    // Back to what the constructor made, keeping the memory: a scene that keeps its frame buffers
    // (Scene::set_keep_frame_buffers) starts its next render in the tiles of the last, same pixels, same arguments.
    void restart();
    // Whether the constructor was given these arguments.
    bool made_for(int x0, int y0, int x1, int y1, bool noise_estimates, const CryptomatteLayout& cryptomatte,
                  const FilmChannelSet& channels) const;
    // Bytes its sums hold.
    std::size_t capacity_bytes() const;
    // Sample number `sample` of film pixel (x, y): the pixel's samples so far, sample_count(x, y).
    void add_sample(int x, int y, int sample, const SampleRecord& record);
    // A sample of film pixel (x, y) whose camera ray does not exist (jittered outside a fisheye's circle): it counts,
    // contributing nothing, so that the pixel's mean fades at the circle's rim.
    void add_empty_sample(int x, int y) { ++counts_[index(x, y)]; }
    // Samples film pixel (x, y) has received.
    int sample_count(int x, int y) const { return int(counts_[index(x, y)]); }
    // Cycles' per-pixel noise estimate (film_adaptive_sampling_convergence_check; Dammertz et al. 2010, "A
    // hierarchical automatic stopping condition for Monte Carlo global illumination", section 2.1): with I the
    // pixel's linear RGB from its n samples and A that from its odd-numbered ones, each combined as write_to()
    // combines them (the mean radiance; in display blend space plus linear(mean D + mean T display(...)) of the
    // samples' display parts, see SampleRecord),
    //   error = (|I.r - A.r| + |I.g - A.g| + |I.b - A.b|) / (0.0001 + N),  N = sqrt(s) if s < 1 else s,
    //   s = I.r + I.g + I.b.
    // |I - A| is half the difference of the even and odd halves' means (to first order where the display
    // combination bends them), so about the standard error of I: the
    // estimate falls as 1 / sqrt(n). Relative to sqrt(s) in the dark (where the eye sees noise more), to s where
    // bright. Needs `noise_estimates` and n >= 2.
    float noise_estimate(int x, int y) const;
    // Writes the tile's pixels into `film`, each as the mean of its own samples (a pixel without any: the empty
    // values). Combined's alpha is coverage with a transparent background (RenderSettings::transparent_background)
    // and 1 otherwise, each less the held-out fraction (SampleRecord::holdout). With light passes, Emission gets the
    // display blend's own part and the Direct and Indirect passes are divided by their Color (SampleRecord::light).
    // The Cryptomatte passes go to the film's buffers of the tile's layout (Film::allocate_cryptomatte).
    void write_to(Film& film, bool transparent_background) const;
    // Pixels [x0, x1) x [y0, y1) of the film.
    int x0() const { return x0_; }
    int y0() const { return y0_; }
    int x1() const { return x1_; }
    int y1() const { return y1_; }

private:
    void complete_light_passes(Film& film) const;
    std::size_t index(int x, int y) const { return std::size_t(y - y0_) * std::size_t(x1_ - x0_) + std::size_t(x - x0_); }
    int x0_, y0_, x1_, y1_;
    bool noise_estimates_;
    FilmChannelSet channels_;
    std::array<std::vector<float>, kFilmChannelCount> values_;  // sums (Mean, Sum) or first samples (FirstSample)
    std::vector<std::uint32_t> counts_;  // samples per pixel
    std::vector<float> odd_radiance_;    // RGB sums of the odd-numbered samples (noise_estimates only)
    // Display blend space: per pixel the sums of D (3), T (1) and T L_behind (3) and the count of samples that had
    // them (SampleRecord); empty until a sample has them. odd_display_sums_: the same over the odd-numbered samples
    // (noise_estimates only), so that noise_estimate() compares pixel values combined as write_to() combines them.
    std::vector<float> display_sums_;
    std::vector<float> odd_display_sums_;
    // A sample carried the light passes (SampleRecord::light_passes): write_to() completes them. In display blend
    // space, per pixel the sums of SampleRecord::front_emission (3; empty until a sample has them).
    bool light_passes_ = false;
    std::vector<float> front_emission_sums_;
    // Cryptomatte: per pixel, per type of the layout in CryptomatteType order, `ranks` slots (id, summed weight) in
    // the order their ids first appeared (id 0: free). Empty without Cryptomatte passes.
    void add_cryptomatte(std::size_t pixel, const CryptomatteCoverage& coverage);
    void write_cryptomatte(Film& film) const;
    CryptomatteLayout cryptomatte_layout_;
    int cryptomatte_types_ = 0;  // types the layout has
    std::vector<float> cryptomatte_;
};

}  // namespace raysplats
