// The film's channel table and the tile that combines samples into it.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <set>
#include <string>

#include "raysplats/render/film.h"

using namespace raysplats;

namespace {

SampleRecord sample(float r, float alpha, float depth, float nz) {
    SampleRecord s;
    s.radiance = {r, 2 * r, 3 * r};
    s.alpha = alpha;
    s.depth = depth;
    s.normal = {0.0f, 0.0f, nz};
    return s;
}

}  // namespace

TEST(Film, ChannelTableIsConsistent) {
    std::set<std::string> keys, passes;
    for (const FilmChannelInfo& info : film_channels()) {
        EXPECT_TRUE(keys.insert(info.key).second) << info.key;
        EXPECT_TRUE(passes.insert(info.pass_name).second) << info.pass_name;
        EXPECT_GE(info.component_count(), 1);
        EXPECT_EQ(&film_channel_info(info.channel), &info);
    }
    EXPECT_EQ(film_channel_info(FilmChannel::Combined).component_count(), 4);
    EXPECT_EQ(film_channel_info(FilmChannel::Normal).component_count(), 3);
    Film film;
    film.resize(3, 2);
    for (const FilmChannelInfo& info : film_channels()) {
        ASSERT_EQ(film[info.channel].size(), 6u * info.component_count()) << info.key;
        for (float v : film[info.channel]) EXPECT_EQ(v, info.empty_value) << info.key;
    }
}

TEST(Film, TileAveragesRadianceAndCoverageAndKeepsTheFirstSurface) {
    Film film;
    film.resize(4, 4);
    FilmTile tile(1, 1, 3, 4);  // pixels x 1..2, y 1..3
    tile.add_sample(2, 3, 0, sample(0.5f, 1.0f, 4.0f, 1.0f));
    tile.add_sample(2, 3, 1, sample(0.25f, 0.5f, 9.0f, -1.0f));
    tile.add_sample(1, 1, 0, sample(1.0f, 0.0f, std::numeric_limits<float>::infinity(), 0.0f));
    tile.write_to(film, /*transparent_background=*/true);
    const std::size_t p = 3 * 4 + 2;
    EXPECT_FLOAT_EQ(film.rgba()[4 * p + 0], 0.375f);
    EXPECT_FLOAT_EQ(film.rgba()[4 * p + 1], 0.75f);
    EXPECT_FLOAT_EQ(film.rgba()[4 * p + 2], 1.125f);
    EXPECT_FLOAT_EQ(film.rgba()[4 * p + 3], 0.75f);  // transparent: coverage
    EXPECT_FLOAT_EQ(film.alpha()[p], 0.75f);
    EXPECT_EQ(film.depth()[p], 4.0f);  // the first sample's, not a mean
    EXPECT_EQ(film.normal()[3 * p + 2], 1.0f);
    // A pixel of the tile that no sample reached keeps the empty values; one outside the tile is untouched.
    const std::size_t unsampled = 2 * 4 + 1;
    EXPECT_TRUE(std::isinf(film.depth()[unsampled]));
    EXPECT_EQ(film.alpha()[unsampled], 0.0f);
    film.depth()[0] = 7.0f;
    tile.write_to(film, /*transparent_background=*/false);
    EXPECT_EQ(film.depth()[0], 7.0f);
    EXPECT_EQ(film.rgba()[4 * p + 3], 1.0f);  // opaque background: alpha 1, coverage stays in Alpha
    EXPECT_EQ(film.rgba()[4 * unsampled + 3], 1.0f);
    EXPECT_FLOAT_EQ(film.alpha()[p], 0.75f);
}

// Cycles' noise estimate from the odd half of a pixel's samples, checked with hand-computed cases (radiance r, 2r,
// 3r): r alternating 1 and 0 (means 0.5, 1, 1.5, odd means 0: |I - A| sums to 3, bright, so relative to the
// intensity 3), the same at 0.04 (0.12, dark: relative to sqrt(0.12)), a constant (0); and the per-pixel sample
// counts the film's Debug Sample Count channel shows.
TEST(Film, NoiseEstimateIsCyclesErrorOfTheOddHalf) {
    FilmTile tile(0, 0, 3, 1, /*noise_estimates=*/true);
    for (int s = 0; s < 4; ++s) {
        const float bright = s % 2 == 0 ? 1.0f : 0.0f, dark = s % 2 == 0 ? 0.04f : 0.0f;
        tile.add_sample(0, 0, s, sample(bright, bright, 1.0f, 0.0f));
        tile.add_sample(1, 0, s, sample(dark, dark, 1.0f, 0.0f));
        tile.add_sample(2, 0, s, sample(0.3f, 0.3f, 1.0f, 0.0f));
    }
    tile.add_sample(2, 0, 4, sample(0.3f, 0.3f, 1.0f, 0.0f));  // a fifth sample: odd count, two odd samples
    EXPECT_NEAR(tile.noise_estimate(0, 0), 3.0 / (0.0001 + 3.0), 1e-6);
    EXPECT_NEAR(tile.noise_estimate(1, 0), 0.12 / (0.0001 + std::sqrt(0.12)), 1e-6);
    EXPECT_NEAR(tile.noise_estimate(2, 0), 0.0, 1e-6);
    EXPECT_EQ(tile.sample_count(0, 0), 4);
    EXPECT_EQ(tile.sample_count(2, 0), 5);
    Film film;
    film.resize(3, 1);
    tile.write_to(film, /*transparent_background=*/true);
    EXPECT_EQ(film.sample_count()[0], 4.0f);
    EXPECT_EQ(film.sample_count()[2], 5.0f);
    EXPECT_FLOAT_EQ(film.rgba()[0], 0.5f);  // each pixel divided by its own count
    EXPECT_FLOAT_EQ(film.rgba()[8], 0.3f);
    // One sample has no odd half: no estimate (infinite, never converged).
    FilmTile one(0, 0, 1, 1, true);
    one.add_sample(0, 0, 0, sample(0.5f, 0.5f, 1.0f, 0.0f));
    EXPECT_TRUE(std::isinf(one.noise_estimate(0, 0)));
}

// Display blend space: the estimate compares pixel values combined as the film combines them (SampleRecord:
// linear(mean D + mean T display(mean(T L_behind) / mean T))), not the samples' linear `radiance` (here 0, which
// would call the pixel converged). Even samples see a Gaussian run (D 0.5, T 0.5 over L_behind 0.2), odd ones only
// L_behind 0.2: I = linear(0.25 + 0.75 srgb(0.2)), A = 0.2 in each channel; a pixel whose samples agree: 0.
TEST(Film, NoiseEstimateInDisplayBlendSpaceUsesTheFilmsPixelValue) {
    auto display_sample = [](float d, float t, float behind) {
        SampleRecord s;
        s.display_blend = true;
        s.display_radiance = {d, d, d};
        s.display_transmittance = t;
        s.behind_radiance = {t * behind, t * behind, t * behind};
        s.alpha = 1.0f - t;
        return s;
    };
    FilmTile tile(0, 0, 2, 1, /*noise_estimates=*/true);
    for (int s = 0; s < 4; ++s) {
        tile.add_sample(0, 0, s, s % 2 == 0 ? display_sample(0.5f, 0.5f, 0.2f) : display_sample(0.0f, 1.0f, 0.2f));
        tile.add_sample(1, 0, s, display_sample(0.5f, 0.5f, 0.2f));
    }
    auto srgb = [](double l) { return l <= 0.0031308 ? 12.92 * l : 1.055 * std::pow(l, 1.0 / 2.4) - 0.055; };
    auto linear = [](double v) { return v <= 0.04045 ? v / 12.92 : std::pow((v + 0.055) / 1.055, 2.4); };
    const double i = linear(0.25 + 0.75 * srgb(0.2)), a = 0.2;
    EXPECT_NEAR(tile.noise_estimate(0, 0), 3.0 * (i - a) / (0.0001 + 3.0 * i), 2e-3);
    EXPECT_NEAR(tile.noise_estimate(1, 0), 0.0, 1e-6);
    // The same value the film holds.
    Film film;
    film.resize(2, 1);
    tile.write_to(film, /*transparent_background=*/true);
    EXPECT_NEAR(film.rgba()[0], i, 2e-3);
}
