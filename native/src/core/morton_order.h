// Morton (Z-order) of Gaussian centres: consecutive Gaussians in this order are near each other in space. Used by the
// renderer to group Gaussians into BVH primitives and by the compressed PLY writer to fill its chunks of 256.
#pragma once

#include <cstdint>
#include <vector>

#include "raysplats/gaussian_cloud.h"

namespace raysplats {

// Indices of the cloud's Gaussians in Morton order (10 bits per axis over the bounding box of the centres); ties
// keep the cloud's order. Deterministic.
std::vector<std::uint32_t> morton_order(const GaussianCloud& c);

}  // namespace raysplats
