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
// With `own` false, the Gaussians' own colours left out (D = 0): what they let through of the light behind.
inline float display_part(const float* sums, int k, bool own = true) {
    const float n = sums[7], t = sums[3] / n;
    const bool gaussians = sums[3] != n || sums[0] != 0.0f || sums[1] != 0.0f || sums[2] != 0.0f;
    const float behind = sums[4 + k] / n, d = own ? sums[k] / n : 0.0f;
    return !gaussians  ? behind
           : t > 0.0f ? srgb_to_linear_tabulated(d + t * linear_to_srgb(behind / t))
                      : srgb_to_linear_tabulated(d);
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
void vector_of(const SampleRecord& s, float* out) {
    out[0] = s.vector[0], out[1] = s.vector[1], out[2] = s.vector[2], out[3] = s.vector[3];
}

bool is_light_pass(FilmChannel c) {
    return std::size_t(c) >= std::size_t(FilmChannel::Emission) &&
           std::size_t(c) < std::size_t(FilmChannel::Emission) + kLightPassCount;
}

template <LightPass pass>
void light_of(const SampleRecord& s, float* out) {
    const std::array<float, 3>& v = s.light[std::size_t(pass)];
    out[0] = v[0], out[1] = v[1], out[2] = v[2];
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
     "1: only the world; needs mist_pass, else 1)", mist_of},
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
    // Cycles' light passes (Blender's names before 5.0, which renamed them: the add-on maps them), each RGB averaged
    // over the samples; Direct and Indirect divided by their Color when written (SampleRecord::light).
    {FilmChannel::Emission, "emission", "Emit", "RGB", "COLOR", SampleCombination::Mean, 0.0f,
     "Light emitted towards the camera by what it sees directly: meshes, lights, Baked Gaussians (needs "
     "light_passes; else 0)", light_of<LightPass::Emission>},
    {FilmChannel::DiffuseDirect, "diffuse_direct", "DiffDir", "RGB", "COLOR", SampleCombination::Mean, 0.0f,
     "Direct light of the first surface's diffuse lobe, divided by Diffuse Color (needs light_passes; else 0)",
     light_of<LightPass::DiffuseDirect>},
    {FilmChannel::DiffuseIndirect, "diffuse_indirect", "DiffInd", "RGB", "COLOR", SampleCombination::Mean, 0.0f,
     "Indirect light of the first surface's diffuse lobe, divided by Diffuse Color (needs light_passes; else 0)",
     light_of<LightPass::DiffuseIndirect>},
    {FilmChannel::DiffuseColor, "diffuse_color", "DiffCol", "RGB", "COLOR", SampleCombination::Mean, 0.0f,
     "Diffuse albedo of the surfaces the camera sees (needs light_passes; else 0)", light_of<LightPass::DiffuseColor>},
    {FilmChannel::GlossyDirect, "glossy_direct", "GlossDir", "RGB", "COLOR", SampleCombination::Mean, 0.0f,
     "Direct light of the first surface's glossy lobe, divided by Glossy Color (needs light_passes; else 0)",
     light_of<LightPass::GlossyDirect>},
    {FilmChannel::GlossyIndirect, "glossy_indirect", "GlossInd", "RGB", "COLOR", SampleCombination::Mean, 0.0f,
     "Indirect light of the first surface's glossy lobe, divided by Glossy Color (needs light_passes; else 0)",
     light_of<LightPass::GlossyIndirect>},
    {FilmChannel::GlossyColor, "glossy_color", "GlossCol", "RGB", "COLOR", SampleCombination::Mean, 0.0f,
     "Glossy albedo of the surfaces the camera sees (needs light_passes; else 0)", light_of<LightPass::GlossyColor>},
    {FilmChannel::TransmissionDirect, "transmission_direct", "TransDir", "RGB", "COLOR", SampleCombination::Mean,
     0.0f, "Direct light of the first surface's transmission lobe, divided by Transmission Color (needs "
     "light_passes; else 0)", light_of<LightPass::TransmissionDirect>},
    {FilmChannel::TransmissionIndirect, "transmission_indirect", "TransInd", "RGB", "COLOR", SampleCombination::Mean,
     0.0f, "Indirect light of the first surface's transmission lobe, divided by Transmission Color (needs "
     "light_passes; else 0)", light_of<LightPass::TransmissionIndirect>},
    {FilmChannel::TransmissionColor, "transmission_color", "TransCol", "RGB", "COLOR", SampleCombination::Mean, 0.0f,
     "Transmission albedo of the surfaces the camera sees (needs light_passes; else 0)",
     light_of<LightPass::TransmissionColor>},
    // Cycles' name and layout (XYZW: to the previous frame, then from the next), from the first sample as Position.
    {FilmChannel::Vector, "vector", "Vector", "XYZW", "VECTOR", SampleCombination::FirstSample, 0.0f,
     "Motion of the depth's point on the image to the previous frame (XY) and from the next (ZW), pixels, y up "
     "(first sample; 0: none, or no camera frame motion)", vector_of},
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
    // The light passes are consecutive channels from Emission, in LightPass order (is_light_pass, light_of).
    return std::size_t(FilmChannel::TransmissionColor) - std::size_t(FilmChannel::Emission) + 1 == kLightPassCount &&
           std::size_t(LightPass::TransmissionColor) + 1 == kLightPassCount;
}
static_assert(table_is_consistent(),
              "film_channels(): rows out of FilmChannel order, or a Mean or Sum channel not empty at 0");

}  // namespace

int FilmChannelInfo::component_count() const { return int(std::char_traits<char>::length(components)); }

const std::array<FilmChannelInfo, kFilmChannelCount>& film_channels() { return kChannels; }

const FilmChannelInfo& film_channel_info(FilmChannel channel) { return film_channels()[std::size_t(channel)]; }

FilmChannelSet all_film_channels() {
    FilmChannelSet set;
    set.fill(true);
    return set;
}

FilmChannelSet computed_film_channels(const RenderSettings& settings) {
    FilmChannelSet set = all_film_channels();
    set[std::size_t(FilmChannel::DenoisingAlbedo)] = set[std::size_t(FilmChannel::DenoisingNormal)] =
        settings.denoising_data;
    for (std::size_t k = 0; k < kLightPassCount; ++k)
        set[std::size_t(FilmChannel::Emission) + k] = settings.light_passes;
    return set;
}

void Film::resize(int w, int h) {
    allocate(w, h);
    clear(0, 0, w, h);
}

void Film::allocate(int w, int h, const FilmChannelSet& channels) {
    width = w;
    height = h;
    for (const FilmChannelInfo& info : film_channels()) {
        FloatBuffer& buffer = (*this)[info.channel];
        if (channels[std::size_t(info.channel)]) {
            buffer.resize(std::size_t(info.component_count()) * pixel_count());
        } else {
            buffer.clear();
            buffer.shrink_to_fit();
        }
    }
}

void Film::allocate_cryptomatte(const CryptomatteLayout& layout) {
    cryptomatte_ranks = layout.ranks;
    for (std::size_t t = 0; t < kCryptomatteTypes; ++t) {
        FloatBuffer& buffer = cryptomatte[t];
        if (layout.on() && layout.types[t]) buffer.resize(2 * std::size_t(layout.ranks) * pixel_count());
        else FloatBuffer().swap(buffer);
    }
}

void Film::clear(int x0, int y0, int x1, int y1) {
    auto fill = [&](FloatBuffer& buffer, std::size_t c, float value) {
        for (int y = y0; y < y1; ++y) {
            const std::size_t begin = std::size_t(y) * width + x0, end = std::size_t(y) * width + x1;
            std::fill(buffer.begin() + c * begin, buffer.begin() + c * end, value);
        }
    };
    for (const FilmChannelInfo& info : film_channels())
        if (!(*this)[info.channel].empty())
            fill((*this)[info.channel], std::size_t(info.component_count()), info.empty_value);
    for (FloatBuffer& buffer : cryptomatte)
        if (!buffer.empty()) fill(buffer, 2 * std::size_t(cryptomatte_ranks), 0.0f);
}

FilmTile::FilmTile(int x0, int y0, int x1, int y1, bool noise_estimates, const CryptomatteLayout& cryptomatte,
                   const FilmChannelSet& channels)
    : x0_(x0), y0_(y0), x1_(x1), y1_(y1), noise_estimates_(noise_estimates), channels_(channels),
      cryptomatte_layout_(cryptomatte) {
    restart();
}

void FilmTile::restart() {
    const std::size_t pixels = std::size_t(x1_ - x0_) * std::size_t(y1_ - y0_);
    // Sums start at 0; first samples at the empty value, which pixels no camera ray reaches keep (outside a
    // fisheye's circle, for example). A channel left out stays empty, and add_sample and write_to skip it. (assign
    // keeps a vector's memory when it is big enough: a restarted tile writes into the pages it had.)
    for (const FilmChannelInfo& info : film_channels()) {
        std::vector<float>& values = values_[std::size_t(info.channel)];
        if (channels_[std::size_t(info.channel)])
            values.assign(std::size_t(info.component_count()) * pixels,
                          info.combination == SampleCombination::FirstSample ? info.empty_value : 0.0f);
        else
            values.clear();
    }
    counts_.assign(pixels, 0u);
    if (noise_estimates_) odd_radiance_.assign(3 * pixels, 0.0f);
    else odd_radiance_.clear();
    // (Made by the first sample that has them.)
    display_sums_.clear();
    odd_display_sums_.clear();
    light_passes_ = false;
    front_emission_sums_.clear();
    cryptomatte_types_ = 0;
    if (cryptomatte_layout_.on()) {
        for (bool on : cryptomatte_layout_.types) cryptomatte_types_ += on ? 1 : 0;
        cryptomatte_.assign(pixels * std::size_t(cryptomatte_types_) * 2 * std::size_t(cryptomatte_layout_.ranks), 0.0f);
    } else {
        cryptomatte_.clear();
    }
}

bool FilmTile::made_for(int x0, int y0, int x1, int y1, bool noise_estimates, const CryptomatteLayout& cryptomatte,
                        const FilmChannelSet& channels) const {
    return x0 == x0_ && y0 == y0_ && x1 == x1_ && y1 == y1_ && noise_estimates == noise_estimates_ &&
           channels == channels_ && cryptomatte.types == cryptomatte_layout_.types &&
           cryptomatte.ranks == cryptomatte_layout_.ranks;
}

std::size_t FilmTile::capacity_bytes() const {
    std::size_t floats = odd_radiance_.capacity() + display_sums_.capacity() + odd_display_sums_.capacity() +
                         front_emission_sums_.capacity() + cryptomatte_.capacity();
    for (const std::vector<float>& values : values_) floats += values.capacity();
    return sizeof(float) * floats + sizeof(std::uint32_t) * counts_.capacity();
}

// Cycles' film_write_cryptomatte_slots, per type: an id already held gains the weight, a new one takes the first free
// slot; with none free it is dropped (cryptomatte.h says why).
void FilmTile::add_cryptomatte(std::size_t pixel, const CryptomatteCoverage& coverage) {
    const std::size_t ranks = std::size_t(cryptomatte_layout_.ranks);
    float* const pixel_slots = cryptomatte_.data() + pixel * std::size_t(cryptomatte_types_) * 2 * ranks;
    for (int e = 0; e < coverage.size(); ++e) {
        const CryptomatteCoverage::Entry& entry = coverage[e];
        float* slots = pixel_slots;
        for (std::size_t t = 0; t < kCryptomatteTypes; ++t) {
            if (!cryptomatte_layout_.types[t]) continue;
            const float id = entry.ids[t];
            if (id != 0.0f)
                for (std::size_t r = 0; r < ranks; ++r) {
                    if (slots[2 * r] == id) {
                        slots[2 * r + 1] += entry.weight;
                        break;
                    }
                    if (slots[2 * r] == 0.0f) {
                        slots[2 * r] = id;
                        slots[2 * r + 1] = entry.weight;
                        break;
                    }
                }
            slots += 2 * ranks;
        }
    }
}

// Each pixel's slots sorted by weight, largest first (Cycles' film_sort_cryptomatte_slots: an insertion sort, which
// keeps equal weights in the order their ids appeared), the weights divided by the pixel's samples.
void FilmTile::write_cryptomatte(Film& film) const {
    const std::size_t ranks = std::size_t(cryptomatte_layout_.ranks);
    std::size_t k = 0;  // the type's place among the layout's types
    for (std::size_t t = 0; t < kCryptomatteTypes; ++t) {
        if (!cryptomatte_layout_.types[t]) continue;
        FloatBuffer& buffer = film.cryptomatte[t];
        for (int y = y0_; y < y1_; ++y)
            for (int x = x0_; x < x1_; ++x) {
                const std::size_t pixel = index(x, y);
                const float* slots = cryptomatte_.data() + (pixel * std::size_t(cryptomatte_types_) + k) * 2 * ranks;
                float* out = buffer.data() + (std::size_t(y) * film.width + x) * 2 * ranks;
                std::copy(slots, slots + 2 * ranks, out);
                for (std::size_t r = 1; r < ranks && out[2 * r] != 0.0f; ++r)
                    for (std::size_t i = r; i > 0 && out[2 * i + 1] > out[2 * i - 1]; --i) {
                        std::swap(out[2 * i], out[2 * i - 2]);
                        std::swap(out[2 * i + 1], out[2 * i - 1]);
                    }
                const float inv = counts_[pixel] > 0 ? 1.0f / float(counts_[pixel]) : 0.0f;
                for (std::size_t r = 0; r < ranks; ++r) out[2 * r + 1] *= inv;
            }
        ++k;
    }
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
    light_passes_ = light_passes_ || record.light_passes;
    if (record.light_passes && record.display_blend) {
        if (front_emission_sums_.empty()) front_emission_sums_.assign(3 * counts_.size(), 0.0f);
        for (int k = 0; k < 3; ++k) front_emission_sums_[3 * pixel + std::size_t(k)] += record.front_emission[std::size_t(k)];
    }
    if (!odd_radiance_.empty() && (sample & 1))
        for (int c = 0; c < 3; ++c) odd_radiance_[3 * pixel + std::size_t(c)] += record.radiance[std::size_t(c)];
    float values[8];
    for (const FilmChannelInfo& info : film_channels()) {
        // Without light passes their sums stay 0: nothing to add. A channel the tile leaves out has no sums.
        std::vector<float>& sums = values_[std::size_t(info.channel)];
        if ((!record.light_passes && is_light_pass(info.channel)) || sums.empty()) continue;
        const int c = info.component_count();
        float* out = sums.data() + std::size_t(c) * pixel;
        if (info.combination == SampleCombination::FirstSample) {
            if (sample == 0) info.from_sample(record, out);
            continue;
        }
        info.from_sample(record, values);
        for (int k = 0; k < c; ++k) out[k] += values[k];
    }
    if (!cryptomatte_.empty()) add_cryptomatte(pixel, record.cryptomatte);
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
        if (values.empty()) continue;  // (a channel the render leaves out)
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
    if (light_passes_) complete_light_passes(film);
    if (!cryptomatte_.empty()) write_cryptomatte(film);
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

namespace {

// Cycles, util/color.h safe_divide_even_color: a / b per channel, and where b is 0 in a channel the mean of the
// other channels' quotients (0 where b is 0 in all three), so a colourless light keeps its grey.
void divide_even_color(float* a, const float* b) {
    float q[3];
    for (int k = 0; k < 3; ++k) q[k] = b[k] != 0.0f ? a[k] / b[k] : 0.0f;
    const bool z0 = b[0] == 0.0f, z1 = b[1] == 0.0f, z2 = b[2] == 0.0f;
    if (z0 && z1) q[0] = q[1] = q[2];
    else if (z0 && z2) q[0] = q[2] = q[1];
    else if (z1 && z2) q[1] = q[2] = q[0];
    else if (z0) q[0] = 0.5f * (q[1] + q[2]);
    else if (z1) q[1] = 0.5f * (q[0] + q[2]);
    else if (z2) q[2] = 0.5f * (q[0] + q[1]);
    a[0] = q[0], a[1] = q[1], a[2] = q[2];
}

}  // namespace

void FilmTile::complete_light_passes(Film& film) const {
    // Display blend space (SampleRecord::light): the light behind the camera ray's first run of Gaussians, scaled by
    // s = linear(mean T display(B / mean T)) / B; the run's own part, the light Baked Gaussians show, is emission in
    // this model.
    if (!display_sums_.empty() && !front_emission_sums_.empty()) {
        for (int y = y0_; y < y1_; ++y)
            for (int x = x0_; x < x1_; ++x) {
                const std::size_t pixel = index(x, y), at = 3 * (std::size_t(y) * film.width + x);
                const float* sums = display_sums_.data() + kDisplaySums * pixel;
                if (sums[7] == 0.0f) continue;
                for (int k = 0; k < 3; ++k) {
                    const float behind = sums[4 + k] / sums[7], through = display_part(sums, k, false);
                    const float s = behind != 0.0f ? through / behind : 0.0f;
                    for (std::size_t pass = 1; pass < kLightPassCount; ++pass)
                        if (pass != std::size_t(LightPass::DiffuseColor) && pass != std::size_t(LightPass::GlossyColor) &&
                            pass != std::size_t(LightPass::TransmissionColor))
                            film[FilmChannel(std::size_t(FilmChannel::Emission) + pass)][at + std::size_t(k)] *= s;
                    float& emission = film[FilmChannel::Emission][at + std::size_t(k)];
                    const float front = front_emission_sums_[3 * pixel + std::size_t(k)] / float(counts_[pixel]);
                    emission = front + s * (emission - front) + (display_part(sums, k) - through);
                }
            }
    }
    // Blender receives Cycles' Direct and Indirect passes divided by their Color (Cycles' pass accessor,
    // film_get_pass_pixel_divide_even_color); its compositor multiplies them back.
    constexpr FilmChannel lobes[3][3] = {
        {FilmChannel::DiffuseDirect, FilmChannel::DiffuseIndirect, FilmChannel::DiffuseColor},
        {FilmChannel::GlossyDirect, FilmChannel::GlossyIndirect, FilmChannel::GlossyColor},
        {FilmChannel::TransmissionDirect, FilmChannel::TransmissionIndirect, FilmChannel::TransmissionColor}};
    for (const auto& lobe : lobes) {
        FloatBuffer &direct = film[lobe[0]], &indirect = film[lobe[1]];
        const FloatBuffer& color = film[lobe[2]];
        for (int y = y0_; y < y1_; ++y)
            for (int x = x0_; x < x1_; ++x) {
                const std::size_t at = 3 * (std::size_t(y) * film.width + x);
                divide_even_color(direct.data() + at, color.data() + at);
                divide_even_color(indirect.data() + at, color.data() + at);
            }
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
