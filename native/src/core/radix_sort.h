// Sorting 64-bit keys whose low 32 bits are the elements' indices in ascending order (key = value << 32 | index):
// a stable sort by the high word alone then equals sorting the whole keys, with a handful of linear passes instead of
// a comparison sort.
#pragma once
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "raysplats/default_init_allocator.h"

namespace raysplats {

// Sorts `keys` ascending. Precondition: their low words ascend in the given order (each key's low word is its
// element's index, and the keys were made in index order, perhaps with some removed), so that the high words' stable
// order is the keys' order. Least significant digit first, 11 bits per pass (three passes for 32 bits), one pass
// skipped when all its digits are equal.
template <typename Allocator>
void sort_by_high_word(std::vector<std::uint64_t, Allocator>& keys) {
    constexpr int kBits = 11;
    constexpr std::size_t kBuckets = std::size_t(1) << kBits;
    const std::size_t n = keys.size();
    if (n < 2) return;
    std::vector<std::uint64_t, DefaultInitAllocator<std::uint64_t>> other(n);
    std::uint64_t* from = keys.data();
    std::uint64_t* to = other.data();
    std::vector<std::size_t> count(kBuckets);
    for (int shift = 32; shift < 64; shift += kBits) {
        std::fill(count.begin(), count.end(), 0);
        for (std::size_t i = 0; i < n; ++i) ++count[(from[i] >> shift) & (kBuckets - 1)];
        if (count[(from[0] >> shift) & (kBuckets - 1)] == n) continue;  // one digit throughout: already in order
        std::size_t at = 0;
        for (std::size_t& c : count) {
            const std::size_t k = c;
            c = at;
            at += k;
        }
        for (std::size_t i = 0; i < n; ++i) to[count[(from[i] >> shift) & (kBuckets - 1)]++] = from[i];
        std::swap(from, to);
    }
    if (from != keys.data()) std::copy(from, from + n, keys.data());
}

}  // namespace raysplats
