// Gaussians mapped by an affine map, exactly: what an object transform does to the Gaussians of a compact splat
// object (one point per Gaussian) when it is exported, baked or turned into polygons.
#pragma once

#include "raysplats/gaussian_cloud.h"

namespace raysplats {

// Maps every Gaussian of `cloud` by x -> A x + t (`matrix`: 4x4 row-major, last row 0 0 0 1; A invertible):
//   centre'  = A c + t
//   Σ'       = A Σ Aᵀ (Σ = R diag(s)² Rᵀ), decomposed again: R' diag(s')² R'ᵀ. For a similarity A = k Q (rotation or
//              reflection times a uniform scale, e.g. any object rotation with a uniform scale) R' = Q R and
//              s' = k s, so each axis keeps its scale; otherwise R', s' are Σ''s eigenvectors and roots of its
//              eigenvalues.
//   SH'      = the colour function turned by Q, the orthogonal factor of A's polar decomposition A = Q P
//              (Higham 1986, Newton iteration): view-dependent colour turns with the Gaussian, and a mirror image
//              (det A < 0) gets its colour mirrored.
//   opacity unchanged.
// The identity returns the cloud bit for bit. Multi-threaded. Throws InvalidArgument for a singular or non-finite
// matrix.
GaussianCloud transform_gaussians(const GaussianCloud& cloud, const double matrix[16]);

}  // namespace raysplats
