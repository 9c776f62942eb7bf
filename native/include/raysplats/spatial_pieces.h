// Splitting a splat scene into spatially compact pieces of at most a given size, so that
// edits run at interactive speed: a big scene imported as polygons becomes one Blender object per piece, because
// Blender re-evaluates a whole edited object after every edit in Rendered or Material Preview shading (it converts the
// edit mesh to add the original coordinates those shadings request, DerivedMesh.cc editbmesh_calc_modifiers), so the
// cost of moving a few splats follows the size of the object they are in, not of the scene.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace raysplats {

struct SpatialPieces {
    // A permutation of 0..count-1: piece p holds order[starts[p] .. starts[p + 1]), in increasing index order (the
    // file's order) within the piece.
    std::vector<std::uint32_t> order;
    // piece_count + 1 offsets into `order`; starts.front() == 0, starts.back() == count.
    std::vector<std::uint64_t> starts;
};

// A k-d split of the centres (3 floats each): a set above max_per_piece is cut at the plane normal to the longest
// side of its bounding box that divides it in proportion to the pieces each side needs (the median when their number
// is even), so there are ceil(count / max_per_piece) pieces of nearly equal size, each a compact box of space.
// Deterministic (ties by index). Non-finite centres go with the lowest side of every cut. count == 0 gives no piece;
// max_per_piece == 0 throws InvalidArgument.
SpatialPieces split_into_spatial_pieces(const float* positions, std::size_t count, std::size_t max_per_piece);

}  // namespace raysplats
