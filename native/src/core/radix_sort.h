// Sorting 64-bit keys whose low 32 bits are the elements' indices in ascending order (key = value << 32 | index):
// a stable sort by the high word alone then equals sorting the whole keys, with a handful of linear passes instead of
// a comparison sort.
#pragma once
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace raysplats {

// Sorts `keys` ascending. Precondition: their low words ascend in the given order (each key's low word is its
// element's index, and the keys were made in index order, perhaps with some removed), so that the high words' stable
// order is the keys' order. Least significant digit first, 11 bits per pass (three passes for 32 bits), the three
// digits' counts taken in one read of the keys, a pass skipped when all its digits are equal. `scratch` is the other
// buffer of the passes; the two may be swapped (a caller that keeps it between sorts allocates nothing).
template <typename Allocator>
void sort_by_high_word(std::vector<std::uint64_t, Allocator>& keys, std::vector<std::uint64_t, Allocator>& scratch) {
    constexpr int kBits = 11, kPasses = 3;
    constexpr std::size_t kBuckets = std::size_t(1) << kBits;
    const std::size_t n = keys.size();
    if (n < 2) return;
    scratch.resize(n);
    std::vector<std::size_t> count(kPasses * kBuckets, 0);
    for (std::size_t i = 0; i < n; ++i) {
        const std::uint64_t high = keys[i] >> 32;
        for (int p = 0; p < kPasses; ++p) ++count[p * kBuckets + ((high >> (p * kBits)) & (kBuckets - 1))];
    }
    std::uint64_t* from = keys.data();
    std::uint64_t* to = scratch.data();
    for (int p = 0; p < kPasses; ++p) {
        const int shift = 32 + p * kBits;
        std::size_t* c = count.data() + p * kBuckets;
        if (c[(from[0] >> shift) & (kBuckets - 1)] == n) continue;  // one digit throughout: already in order
        std::size_t at = 0;
        for (std::size_t d = 0; d < kBuckets; ++d) {
            const std::size_t k = c[d];
            c[d] = at;
            at += k;
        }
        for (std::size_t i = 0; i < n; ++i) to[c[(from[i] >> shift) & (kBuckets - 1)]++] = from[i];
        std::swap(from, to);
    }
    if (from != keys.data()) keys.swap(scratch);
}

template <typename Allocator>
void sort_by_high_word(std::vector<std::uint64_t, Allocator>& keys) {
    std::vector<std::uint64_t, Allocator> scratch;
    sort_by_high_word(keys, scratch);
}

}  // namespace raysplats
