#include "raysplats/render/film.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <string>
#include <vector>

#define STB_IMAGE_WRITE_IMPLEMENTATION
#define STB_IMAGE_WRITE_STATIC
#include <stb/stb_image_write.h>

#include "core/os_files.h"
#include "raysplats/errors.h"
#include "render_math.h"

namespace raysplats {
namespace {

// Writes the encoded file through a temporary file in the same folder that then replaces `path`
// (core/os_files.h), so a failed write never leaves a half-written file in place of a good one.
void write_atomically(const std::string& path, const std::vector<unsigned char>& encoded) {
    try {
        os::write_file_atomically(path, encoded.data(), encoded.size());
    } catch (const os::Error& e) {
        throw Error("cannot write '" + path + "': " + e.what());
    }
}

void append_bytes(void* context, void* data, int size) {
    auto* out = static_cast<std::vector<unsigned char>*>(context);
    out->insert(out->end(), static_cast<unsigned char*>(data), static_cast<unsigned char*>(data) + size);
}

}  // namespace

namespace {

// FilmTile::display_sums_ per pixel: D (3), T, T L_behind (3), samples.
constexpr std::size_t kDisplaySums = 8;

void add_display_parts(float* sums, const SampleRecord& record) {
    for (int k = 0; k < 3; ++k) {
        sums[k] += record.display_radiance[k];
        sums[4 + k] += record.behind_radiance[k];
    }
    sums[3] += record.display_transmittance;
    sums[7] += 1.0f;
}

// What a pixel's display parts add to its linear RGB (SampleRecord): linear(mean D + mean T display(mean(T L_behind)
// / mean T)) in channel k. Where no sample met a Gaussian (D = 0, T = 1) that is mean L_behind, taken as it is.
// sums[7] > 0.
inline float display_part(const float* sums, int k) {
    const float n = sums[7], t = sums[3] / n;
    const bool gaussians = sums[3] != n || sums[0] != 0.0f || sums[1] != 0.0f || sums[2] != 0.0f;
    const float behind = sums[4 + k] / n;
    return !gaussians  ? behind
           : t > 0.0f ? srgb_to_linear_tabulated(sums[k] / n + t * linear_to_srgb(behind / t))
                      : srgb_to_linear_tabulated(sums[k] / n);
}

void radiance_and_coverage(const SampleRecord& s, float* out) {
    out[0] = s.radiance[0], out[1] = s.radiance[1], out[2] = s.radiance[2], out[3] = s.alpha - s.holdout;
}
void depth_of(const SampleRecord& s, float* out) { out[0] = s.depth; }
void normal_of(const SampleRecord& s, float* out) { out[0] = s.normal[0], out[1] = s.normal[1], out[2] = s.normal[2]; }
void coverage_of(const SampleRecord& s, float* out) { out[0] = s.alpha; }
void gaussian_count_of(const SampleRecord& s, float* out) { out[0] = s.gaussian_count; }
void one_sample(const SampleRecord&, float* out) { out[0] = 1.0f; }
void mist_of(const SampleRecord& s, float* out) { out[0] = s.mist; }
void position_of(const SampleRecord& s, float* out) {
    out[0] = s.position[0], out[1] = s.position[1], out[2] = s.position[2];
}
void object_index_of(const SampleRecord& s, float* out) { out[0] = s.object_index; }
void material_index_of(const SampleRecord& s, float* out) { out[0] = s.material_index; }
void denoising_albedo_of(const SampleRecord& s, float* out) {
    out[0] = s.denoising_albedo[0], out[1] = s.denoising_albedo[1], out[2] = s.denoising_albedo[2];
}
void denoising_normal_of(const SampleRecord& s, float* out) {
    out[0] = s.denoising_normal[0], out[1] = s.denoising_normal[1], out[2] = s.denoising_normal[2];
}
void environment_of(const SampleRecord& s, float* out) {
    out[0] = s.environment[0], out[1] = s.environment[1], out[2] = s.environment[2];
}
void shadow_catcher_of(const SampleRecord& s, float* out) {
    out[0] = s.shadow_catcher[0], out[1] = s.shadow_catcher[1], out[2] = s.shadow_catcher[2];
}

constexpr float kNoSurface = std::numeric_limits<float>::infinity();

constexpr std::array<FilmChannelInfo, kFilmChannelCount> kChannels = {{
    {FilmChannel::Combined, "rgba", "Combined", "RGBA", "COLOR", SampleCombination::Mean, 0.0f,
     "Linear radiance, premultiplied by coverage with a transparent background", radiance_and_coverage},
    {FilmChannel::Depth, "depth", "Depth", "Z", "VALUE", SampleCombination::FirstSample, kNoSurface,
     "Distance along the camera ray to where the opacity reaches 0.5 (first sample; +inf: none)", depth_of},
    {FilmChannel::Normal, "normal", "Normal", "XYZ", "VECTOR", SampleCombination::FirstSample, 0.0f,
     "World-space normal at the depth's surface (first sample; 0: none)", normal_of},
    {FilmChannel::Alpha, "alpha", "Alpha", "A", "VALUE", SampleCombination::Mean, 0.0f,
     "Coverage: 1 - the camera segment's final transmittance", coverage_of},
    {FilmChannel::GaussianCount, "gaussian_count", "Gaussian Count", "X", "VALUE", SampleCombination::Mean, 0.0f,
     "Debug: Gaussians the camera ray composited (sorted) or accepted (stochastic), mean over samples",
     gaussian_count_of},
    // Cycles' name for the same debug pass; Cycles divides by the render's samples, this is the count itself.
    {FilmChannel::SampleCount, "sample_count", "Debug Sample Count", "X", "VALUE", SampleCombination::Sum, 0.0f,
     "Debug: samples the pixel received (fewer where adaptive sampling found it converged)", one_sample},
    // Blender's names and layouts (Cycles' addon engine.py, list_render_passes; Blender 5.0 renamed IndexOB and IndexMA,
    // which the add-on maps). Cycles averages mist over the samples and writes the others from the first sample only
    // (kernel/film/data_passes.h).
    {FilmChannel::Mist, "mist", "Mist", "Z", "VALUE", SampleCombination::Mean, 0.0f,
     "Mist: 1 - the coverage-weighted sum of 1 - mist(distance) along the camera ray (the World's mist settings; "
     "1: only the world)", mist_of},
    {FilmChannel::Position, "position", "Position", "XYZ", "VECTOR", SampleCombination::FirstSample, 0.0f,
     "World-space position where the opacity reaches 0.5, the depth's point (first sample; 0: none)", position_of},
    {FilmChannel::ObjectIndex, "object_index", "IndexOB", "X", "VALUE", SampleCombination::FirstSample, 0.0f,
     "Pass index of the object at the depth's point (first sample; 0: none)", object_index_of},
    {FilmChannel::MaterialIndex, "material_index", "IndexMA", "X", "VALUE", SampleCombination::FirstSample, 0.0f,
     "Pass index of the material at the depth's point (Gaussians: their object's first material; first sample; "
     "0: none)", material_index_of},
    // Cycles' names and layouts for its Denoising Data passes; averaged over the samples as Cycles averages them.
    {FilmChannel::DenoisingAlbedo, "denoising_albedo", "Denoising Albedo", "RGB", "COLOR", SampleCombination::Mean,
     0.0f, "Denoiser guide: the colour the camera ray sees, weighted as composited (needs denoising_data; else 0)",
     denoising_albedo_of},
    {FilmChannel::DenoisingNormal, "denoising_normal", "Denoising Normal", "XYZ", "VECTOR", SampleCombination::Mean,
     0.0f, "Denoiser guide: world-space normal the camera ray sees, weighted as composited (needs denoising_data; "
     "else 0)", denoising_normal_of},
    // Blender's Env pass (ViewLayer.use_pass_environment), Cycles' layout; averaged as Cycles averages it.
    {FilmChannel::Environment, "environment", "Env", "RGB", "COLOR", SampleCombination::Mean, 0.0f,
     "The world's colour where the camera ray escapes, times its transmittance (0 where it stops on a surface)",
     environment_of},
    // Cycles' Shadow Catcher pass (its layout; the check box is Cycles' view_layer.cycles.use_pass_shadow_catcher):
    // the plate's multiplier, 1 where no shadow catcher is seen.
    {FilmChannel::ShadowCatcher, "shadow_catcher", "Shadow Catcher", "RGB", "COLOR", SampleCombination::Mean, 0.0f,
     "Shadow catchers: the lights' direct light with shadows over that without, seen through what is in front "
     "(1: no shadow catcher)", shadow_catcher_of},
}};

// Rows in FilmChannel order; a Mean or Sum channel's empty value is 0, what a tile's sums hold for a pixel no sample
// reached.
constexpr bool table_is_consistent() {
    for (std::size_t i = 0; i < kChannels.size(); ++i) {
        if (std::size_t(kChannels[i].channel) != i) return false;
        if (kChannels[i].combination != SampleCombination::FirstSample && kChannels[i].empty_value != 0.0f) return false;
    }
    return true;
}
static_assert(table_is_consistent(),
              "film_channels(): rows out of FilmChannel order, or a Mean or Sum channel not empty at 0");

}  // namespace

int FilmChannelInfo::component_count() const { return int(std::char_traits<char>::length(components)); }

const std::array<FilmChannelInfo, kFilmChannelCount>& film_channels() { return kChannels; }

const FilmChannelInfo& film_channel_info(FilmChannel channel) { return film_channels()[std::size_t(channel)]; }

void Film::resize(int w, int h) {
    allocate(w, h);
    clear(0, 0, w, h);
}

void Film::allocate(int w, int h) {
    width = w;
    height = h;
    for (const FilmChannelInfo& info : film_channels())
        (*this)[info.channel].resize(std::size_t(info.component_count()) * pixel_count());
}

void Film::clear(int x0, int y0, int x1, int y1) {
    for (const FilmChannelInfo& info : film_channels()) {
        FloatBuffer& buffer = (*this)[info.channel];
        const std::size_t c = std::size_t(info.component_count());
        for (int y = y0; y < y1; ++y) {
            const std::size_t begin = std::size_t(y) * width + x0, end = std::size_t(y) * width + x1;
            std::fill(buffer.begin() + c * begin, buffer.begin() + c * end, info.empty_value);
        }
    }
}

FilmTile::FilmTile(int x0, int y0, int x1, int y1, bool noise_estimates) : x0_(x0), y0_(y0), x1_(x1), y1_(y1) {
    const std::size_t pixels = std::size_t(x1 - x0) * std::size_t(y1 - y0);
    // Sums start at 0; first samples at the empty value, which pixels no camera ray reaches keep (outside a
    // fisheye's circle, for example).
    for (const FilmChannelInfo& info : film_channels())
        values_[std::size_t(info.channel)].assign(
            std::size_t(info.component_count()) * pixels,
            info.combination == SampleCombination::FirstSample ? info.empty_value : 0.0f);
    counts_.assign(pixels, 0u);
    if (noise_estimates) odd_radiance_.assign(3 * pixels, 0.0f);
}

float FilmTile::noise_estimate(int x, int y) const {
    const std::size_t pixel = index(x, y);
    const std::uint32_t n = counts_[pixel], odd = n / 2;
    if (odd_radiance_.empty() || odd == 0) return std::numeric_limits<float>::infinity();
    const float* sum = values_[std::size_t(FilmChannel::Combined)].data() + 4 * pixel;
    const float* odd_sum = odd_radiance_.data() + 3 * pixel;
    // Display blend space: both pixel values as write_to() combines them, from all samples' display parts and from
    // the odd ones' (a half whose samples all missed the camera has none: its value is its radiance alone).
    const float* display = display_sums_.empty() ? nullptr : display_sums_.data() + kDisplaySums * pixel;
    const float* odd_display = odd_display_sums_.empty() ? nullptr : odd_display_sums_.data() + kDisplaySums * pixel;
    if (display && display[7] == 0.0f) display = nullptr;
    if (odd_display && odd_display[7] == 0.0f) odd_display = nullptr;
    float difference = 0.0f, intensity = 0.0f;
    for (int c = 0; c < 3; ++c) {
        float mean = sum[c] / float(n), odd_mean = odd_sum[c] / float(odd);
        if (display) mean += display_part(display, c);
        if (odd_display) odd_mean += display_part(odd_display, c);
        difference += std::fabs(mean - odd_mean);
        intensity += mean;
    }
    const float normalize = intensity < 1.0f ? std::sqrt(std::max(intensity, 0.0f)) : intensity;
    return difference / (0.0001f + normalize);
}

void FilmTile::add_sample(int x, int y, int sample, const SampleRecord& record) {
    const std::size_t pixel = index(x, y);
    ++counts_[pixel];
    if (!odd_radiance_.empty() && (sample & 1))
        for (int c = 0; c < 3; ++c) odd_radiance_[3 * pixel + std::size_t(c)] += record.radiance[std::size_t(c)];
    float values[8];
    for (const FilmChannelInfo& info : film_channels()) {
        const int c = info.component_count();
        float* out = values_[std::size_t(info.channel)].data() + std::size_t(c) * pixel;
        if (info.combination == SampleCombination::FirstSample) {
            if (sample == 0) info.from_sample(record, out);
            continue;
        }
        info.from_sample(record, values);
        for (int k = 0; k < c; ++k) out[k] += values[k];
    }
    if (record.display_blend) {
        const std::size_t pixels = std::size_t(x1_ - x0_) * std::size_t(y1_ - y0_);
        if (display_sums_.empty()) {
            display_sums_.assign(kDisplaySums * pixels, 0.0f);
            if (!odd_radiance_.empty()) odd_display_sums_.assign(kDisplaySums * pixels, 0.0f);
        }
        add_display_parts(display_sums_.data() + kDisplaySums * pixel, record);
        if (!odd_display_sums_.empty() && (sample & 1))
            add_display_parts(odd_display_sums_.data() + kDisplaySums * pixel, record);
    }
}

void FilmTile::write_to(Film& film, bool transparent_background) const {
    for (const FilmChannelInfo& info : film_channels()) {
        const std::size_t c = std::size_t(info.component_count());
        const std::vector<float>& values = values_[std::size_t(info.channel)];
        FloatBuffer& buffer = film[info.channel];
        const bool mean = info.combination == SampleCombination::Mean;
        for (int y = y0_; y < y1_; ++y)
            for (int x = x0_; x < x1_; ++x) {
                const std::size_t pixel = index(x, y);
                const float* v = values.data() + c * pixel;
                float* out = buffer.data() + c * (std::size_t(y) * film.width + x);
                // A pixel without samples: its sums are 0, the empty value of a Mean channel.
                const float inv = counts_[pixel] > 0 ? 1.0f / float(counts_[pixel]) : 0.0f;
                for (std::size_t k = 0; k < c; ++k) out[k] = mean ? v[k] * inv : v[k];
            }
    }
    if (!display_sums_.empty()) {
        // SampleRecord: rgb += linear(mean D + mean T display(mean(T L_behind) / mean T)) (display_part).
        FloatBuffer& rgba = film.rgba();
        for (int y = y0_; y < y1_; ++y)
            for (int x = x0_; x < x1_; ++x) {
                const float* sums = display_sums_.data() + kDisplaySums * index(x, y);
                if (sums[7] == 0.0f) continue;
                float* out = rgba.data() + 4 * (std::size_t(y) * film.width + x);
                for (int k = 0; k < 3; ++k) out[k] += display_part(sums, k);
            }
    }
    if (transparent_background) return;
    // An opaque background covers every pixel: alpha 1 less the held-out fraction, which is the coverage (the Alpha
    // channel) less Combined's alpha, both means of the same samples (exactly 1 where nothing is held out).
    FloatBuffer& rgba = film.rgba();
    const FloatBuffer& coverage = film.alpha();
    for (int y = y0_; y < y1_; ++y)
        for (int x = x0_; x < x1_; ++x) {
            const std::size_t pixel = std::size_t(y) * film.width + x;
            rgba[4 * pixel + 3] = 1.0f - (coverage[pixel] - rgba[4 * pixel + 3]);
        }
}

void Film::write_png(const std::string& path) const {
    std::vector<unsigned char> bytes(4 * pixel_count());
    for (std::size_t i = 0; i < pixel_count(); ++i) {
        const float a = rgba()[4 * i + 3];
        for (int c = 0; c < 3; ++c) {
            // Un-premultiply for PNG's straight alpha.
            float v = a > 0.0f ? rgba()[4 * i + c] / a : 0.0f;
            v = linear_to_srgb(std::clamp(v, 0.0f, 1.0f));
            bytes[4 * i + c] = (unsigned char)std::lround(255.0f * v);
        }
        bytes[4 * i + 3] = (unsigned char)std::lround(255.0f * std::clamp(a, 0.0f, 1.0f));
    }
    std::vector<unsigned char> encoded;
    if (!stbi_write_png_to_func(append_bytes, &encoded, width, height, 4, bytes.data(), 4 * width))
        throw Error("cannot write '" + path + "': PNG encoding failed");
    write_atomically(path, encoded);
}

void Film::write_pfm(const std::string& path) const {
    // PFM: a text header, then rows bottom to top of little-endian floats (the negative scale says so).
    const std::string header = "PF\n" + std::to_string(width) + " " + std::to_string(height) + "\n-1.0\n";
    std::vector<unsigned char> encoded(header.begin(), header.end());
    std::vector<float> row(3 * std::size_t(width));
    for (int y = height - 1; y >= 0; --y) {
        for (int x = 0; x < width; ++x)
            for (int c = 0; c < 3; ++c) row[3 * x + c] = rgba()[4 * (std::size_t(y) * width + x) + c];
        const auto* bytes = reinterpret_cast<const unsigned char*>(row.data());
        encoded.insert(encoded.end(), bytes, bytes + row.size() * sizeof(float));
    }
    write_atomically(path, encoded);
}

}  // namespace raysplats
