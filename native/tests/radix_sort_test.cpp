// sort_by_high_word against std::sort: keys made in index order (some removed), with repeated and equal high words,
// and high words that differ only in one 11-bit digit, so that every pass and the skipped pass are exercised.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <cstdint>
#include <random>
#include <vector>

#include "core/radix_sort.h"

namespace raysplats {
namespace {

std::vector<std::uint64_t> keys_in_index_order(std::size_t n, std::uint32_t high_mask, unsigned seed) {
    std::mt19937 rng(seed);
    std::vector<std::uint64_t> keys;
    for (std::uint32_t i = 0; i < n; ++i) {
        if (rng() % 5 == 0) continue;  // culled: the indices ascend with gaps
        keys.push_back(std::uint64_t(rng() & high_mask) << 32 | i);
    }
    return keys;
}

TEST(RadixSort, EqualsAComparisonSortOfTheWholeKeys) {
    for (const std::uint32_t mask : {0xffffffffu, 0x000007ffu, 0x003ff800u, 0xffe00000u, 0x0000000fu, 0u}) {
        for (const std::size_t n : {std::size_t(0), std::size_t(1), std::size_t(2), std::size_t(1000), std::size_t(100000)}) {
            std::vector<std::uint64_t> keys = keys_in_index_order(n, mask, unsigned(n) ^ mask);
            std::vector<std::uint64_t> expected = keys;
            std::sort(expected.begin(), expected.end());
            sort_by_high_word(keys);
            EXPECT_EQ(keys, expected) << "mask " << mask << ", " << n << " keys";
        }
    }
}

TEST(RadixSort, AKeptScratchBufferSortsAsAFreshOne) {
    // The pre-pass keeps its keys and the other buffer between frames; a sort may leave them swapped, and the next
    // frame has more or fewer keys.
    std::vector<std::uint64_t> keys, scratch;
    for (const std::size_t n : {std::size_t(100000), std::size_t(1000), std::size_t(50000), std::size_t(2)}) {
        for (const std::uint32_t mask : {0xffffffffu, 0x003ff800u}) {
            keys = keys_in_index_order(n, mask, unsigned(n) + mask);
            std::vector<std::uint64_t> expected = keys;
            std::sort(expected.begin(), expected.end());
            sort_by_high_word(keys, scratch);
            EXPECT_EQ(keys, expected) << "mask " << mask << ", " << n << " keys";
        }
    }
}

TEST(RadixSort, PositiveFloatDepthsSortAsTheirBitPatterns) {
    // The camera pre-pass's keys: a positive float's bits above the index.
    std::mt19937 rng(7);
    std::uniform_real_distribution<float> depth(0.01f, 1000.0f);
    std::vector<std::uint64_t> keys;
    std::vector<float> depths;
    for (std::uint32_t i = 0; i < 50000; ++i) {
        const float d = i % 7 == 0 ? 2.5f : depth(rng);  // ties: kept in index order
        std::uint32_t bits;
        std::memcpy(&bits, &d, sizeof bits);
        keys.push_back(std::uint64_t(bits) << 32 | i);
        depths.push_back(d);
    }
    sort_by_high_word(keys);
    for (std::size_t k = 1; k < keys.size(); ++k) {
        const float a = depths[keys[k - 1] & 0xffffffffu], b = depths[keys[k] & 0xffffffffu];
        ASSERT_TRUE(a < b || (a == b && (keys[k - 1] & 0xffffffffu) < (keys[k] & 0xffffffffu))) << "at " << k;
    }
}

}  // namespace
}  // namespace raysplats
