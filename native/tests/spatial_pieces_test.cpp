#include "raysplats/spatial_pieces.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "raysplats/errors.h"

namespace raysplats {
namespace {

std::vector<float> random_centres(std::size_t n, unsigned seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> x(-10.0f, 10.0f), y(-2.0f, 2.0f), z(0.0f, 5.0f);
    std::vector<float> p;
    for (std::size_t i = 0; i < n; ++i) p.insert(p.end(), {x(rng), y(rng), z(rng)});
    return p;
}

TEST(SpatialPieces, IsAPermutationInEqualPiecesSortedWithin) {
    const std::size_t n = 10007, max = 1000;
    const std::vector<float> p = random_centres(n, 3);
    const SpatialPieces pieces = split_into_spatial_pieces(p.data(), n, max);
    ASSERT_EQ(pieces.starts.size(), 11u + 1u);  // ceil(10007 / 1000) = 11 pieces
    EXPECT_EQ(pieces.starts.front(), 0u);
    EXPECT_EQ(pieces.starts.back(), n);
    std::vector<std::uint32_t> sorted = pieces.order;
    std::sort(sorted.begin(), sorted.end());
    for (std::size_t i = 0; i < n; ++i) ASSERT_EQ(sorted[i], i);
    for (std::size_t k = 0; k + 1 < pieces.starts.size(); ++k) {
        const std::size_t size = pieces.starts[k + 1] - pieces.starts[k];
        EXPECT_LE(size, max);
        EXPECT_GE(size, n / 11 - 1);
        EXPECT_TRUE(std::is_sorted(pieces.order.begin() + std::ptrdiff_t(pieces.starts[k]),
                                   pieces.order.begin() + std::ptrdiff_t(pieces.starts[k + 1])));
    }
}

// Pieces are boxes of space: their bounding boxes do not overlap (a cut separates any two), and the first cut is
// across the longest side (x here, 20 long against 4 and 5).
TEST(SpatialPieces, PiecesAreDisjointBoxesCutAcrossTheLongestSide) {
    const std::size_t n = 4000;
    const std::vector<float> p = random_centres(n, 5);
    const SpatialPieces pieces = split_into_spatial_pieces(p.data(), n, 1000);
    ASSERT_EQ(pieces.starts.size(), 5u);
    struct Box { float lo[3], hi[3]; };
    std::vector<Box> boxes;
    for (std::size_t k = 0; k + 1 < pieces.starts.size(); ++k) {
        Box b{{1e30f, 1e30f, 1e30f}, {-1e30f, -1e30f, -1e30f}};
        for (std::size_t i = pieces.starts[k]; i < pieces.starts[k + 1]; ++i)
            for (int a = 0; a < 3; ++a) {
                b.lo[a] = std::min(b.lo[a], p[3 * pieces.order[i] + std::size_t(a)]);
                b.hi[a] = std::max(b.hi[a], p[3 * pieces.order[i] + std::size_t(a)]);
            }
        boxes.push_back(b);
    }
    for (std::size_t i = 0; i < boxes.size(); ++i)
        for (std::size_t j = i + 1; j < boxes.size(); ++j) {
            bool separated = false;
            for (int a = 0; a < 3; ++a)
                separated = separated || boxes[i].hi[a] < boxes[j].lo[a] || boxes[j].hi[a] < boxes[i].lo[a];
            EXPECT_TRUE(separated) << "pieces " << i << " and " << j << " overlap";
        }
    EXPECT_LT(boxes[1].hi[0], boxes[2].lo[0]);  // the first cut: pieces 0-1 left of 2-3 in x
}

TEST(SpatialPieces, SmallSetsEmptySetsAndNonFiniteCentres) {
    const std::vector<float> p = random_centres(10, 1);
    const SpatialPieces one = split_into_spatial_pieces(p.data(), 10, 10);
    EXPECT_EQ(one.starts, (std::vector<std::uint64_t>{0, 10}));
    EXPECT_EQ(split_into_spatial_pieces(nullptr, 0, 5).starts, (std::vector<std::uint64_t>{0}));
    EXPECT_THROW(split_into_spatial_pieces(p.data(), 10, 0), InvalidArgument);
    std::vector<float> bad = p;
    bad[0] = std::numeric_limits<float>::quiet_NaN();
    bad[4] = std::numeric_limits<float>::infinity();
    const SpatialPieces pieces = split_into_spatial_pieces(bad.data(), 10, 3);
    ASSERT_EQ(pieces.starts.back(), 10u);
    std::vector<std::uint32_t> sorted = pieces.order;
    std::sort(sorted.begin(), sorted.end());
    for (std::uint32_t i = 0; i < 10; ++i) EXPECT_EQ(sorted[i], i);
}

}  // namespace
}  // namespace raysplats
