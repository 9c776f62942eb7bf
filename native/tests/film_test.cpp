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
    tile.write_to(film, 2, /*transparent_background=*/true);
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
    tile.write_to(film, 2, /*transparent_background=*/false);
    EXPECT_EQ(film.depth()[0], 7.0f);
    EXPECT_EQ(film.rgba()[4 * p + 3], 1.0f);  // opaque background: alpha 1, coverage stays in Alpha
    EXPECT_EQ(film.rgba()[4 * unsampled + 3], 1.0f);
    EXPECT_FLOAT_EQ(film.alpha()[p], 0.75f);
}
