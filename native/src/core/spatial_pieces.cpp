#include "raysplats/spatial_pieces.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

#include "raysplats/errors.h"

namespace raysplats {
namespace {

struct Splitter {
    const float* positions;
    std::size_t max_per_piece;
    std::vector<std::uint64_t>* starts;

    float coordinate(std::uint32_t i, int axis) const {
        const float v = positions[3 * std::size_t(i) + std::size_t(axis)];
        return std::isfinite(v) ? v : -std::numeric_limits<float>::infinity();
    }

    // Splits [begin, end) of the order in place; appends the end of each piece to `starts`, left to right.
    void split(std::uint32_t* begin, std::uint32_t* end) {
        const std::size_t n = std::size_t(end - begin);
        const std::size_t pieces = (n + max_per_piece - 1) / max_per_piece;
        if (pieces <= 1) {
            starts->push_back(starts->back() + n);
            return;
        }
        float lo[3], hi[3];
        for (int a = 0; a < 3; ++a) {
            lo[a] = std::numeric_limits<float>::infinity();
            hi[a] = -std::numeric_limits<float>::infinity();
        }
        for (const std::uint32_t* it = begin; it != end; ++it)
            for (int a = 0; a < 3; ++a) {
                const float v = positions[3 * std::size_t(*it) + std::size_t(a)];
                if (!std::isfinite(v)) continue;
                lo[a] = std::min(lo[a], v);
                hi[a] = std::max(hi[a], v);
            }
        int axis = 0;
        for (int a = 1; a < 3; ++a)
            if (hi[a] - lo[a] > hi[axis] - lo[axis]) axis = a;
        // The left side gets floor(pieces / 2) full shares: every piece then holds n / pieces Gaussians (± 1).
        const std::size_t left = n * (pieces / 2) / pieces;
        std::nth_element(begin, begin + left, end, [&](std::uint32_t a, std::uint32_t b) {
            const float ca = coordinate(a, axis), cb = coordinate(b, axis);
            return ca < cb || (ca == cb && a < b);
        });
        split(begin, begin + left);
        split(begin + left, end);
    }
};

}  // namespace

SpatialPieces split_into_spatial_pieces(const float* positions, std::size_t count, std::size_t max_per_piece) {
    if (max_per_piece == 0) throw InvalidArgument("split_into_spatial_pieces: max_per_piece must be at least 1");
    if (count > std::numeric_limits<std::uint32_t>::max())
        throw InvalidArgument("split_into_spatial_pieces: more than 2^32 - 1 Gaussians");
    SpatialPieces pieces;
    pieces.order.resize(count);
    std::iota(pieces.order.begin(), pieces.order.end(), std::uint32_t(0));
    pieces.starts.push_back(0);
    if (count == 0) return pieces;
    Splitter{positions, max_per_piece, &pieces.starts}.split(pieces.order.data(), pieces.order.data() + count);
    // Each piece back in file order: a counting sort by piece (O(n), where sorting each piece was a third of the
    // split's time on showroom_1.5M.ply).
    std::vector<std::uint32_t> piece_of(count);
    for (std::size_t p = 0; p + 1 < pieces.starts.size(); ++p)
        for (std::uint64_t i = pieces.starts[p]; i < pieces.starts[p + 1]; ++i) piece_of[pieces.order[i]] = std::uint32_t(p);
    std::vector<std::uint64_t> next(pieces.starts.begin(), pieces.starts.end() - 1);
    for (std::uint32_t i = 0; i < count; ++i) pieces.order[next[piece_of[i]]++] = i;
    return pieces;
}

}  // namespace raysplats
