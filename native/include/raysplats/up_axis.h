// Which way is up in a Gaussian scene, estimated from the Gaussians alone (no cameras, no file convention).
//
// The cue is the supporting plane: the ground of an outdoor capture, the floor of an interior, the table or plate an
// object stands on. It is the up-direction cue of point-cloud processing, where the ground is found as the dominant
// plane (RANSAC plane segmentation, Fischler & Bolles 1981; Open3D's segment_plane) and up is its normal oriented
// towards the rest of the scene, and of upright orientation of objects, where the object rests on a flat supporting
// base at its bottom (Fu, Cohen-Or, Dror & Sheffer, "Upright Orientation of Man-Made Objects", SIGGRAPH 2008).
// A trained 3DGS scene draws such a plane with flat Gaussians (one scale much smaller than the other two; the axis of
// the smallest scale is the surface normal). Files are written in one of a few conventions, so the candidates are
// the six signed coordinate axes u; each scores
//   score(u) = sum over flat, fairly opaque Gaussians whose normal is within 25° of u and whose centre lies in the
//              lowest tenth of the scene along u (heights between the 1st and 99th percentile)
//              of opacity * s_mid * s_max (the area of the flat Gaussian, so large surface pieces count most),
// divided by that sum over all flat Gaussians. Up is the best-scoring axis; the estimate is decided only when the
// best clearly beats the second (margin = (best - second) / best >= kUpAxisMinMargin) and the plane holds a
// noticeable part of the flat area (best >= kUpAxisMinSupport). A scene without such a plane (a person captured
// standing in the air, a sparse early checkpoint) stays undecided, and the caller keeps its format's convention.
#pragma once

#include <array>
#include <string>

#include "raysplats/gaussian_cloud.h"

namespace raysplats {

// Thresholds of UpAxisEstimate::decided, chosen on the real scenes of shared/data (up_axis_test.cpp's ground truth):
// decided scenes had margins of 0.48 or more, undecided ones 0.03 (no supporting plane) or a best score of 0.0025
// (sparse).
constexpr double kUpAxisMinMargin = 0.35;
constexpr double kUpAxisMinSupport = 0.005;

struct UpAxisEstimate {
    // The six candidates in this order, named as the add-on's up-axis settings name them.
    static constexpr std::array<const char*, 6> kAxisNames{"X", "-X", "Y", "-Y", "Z", "-Z"};
    std::array<double, 6> scores{};  // score(u) of each candidate (see the file comment), in [0, 1]
    int best = 0;                    // index into kAxisNames of the best score
    double margin = 0.0;             // (best - second best) / best; 0 when no Gaussian is flat
    std::size_t flat_gaussians = 0;  // how many Gaussians counted as flat
    bool decided = false;            // margin >= kUpAxisMinMargin and scores[best] >= kUpAxisMinSupport

    const char* axis() const { return kAxisNames[std::size_t(best)]; }
};

// The estimate for `cloud` (any axes; positions, unit rotations, linear scales, linear opacities). Per-Gaussian work
// runs in parallel; the height percentiles use at most a million evenly spaced Gaussians.
UpAxisEstimate estimate_up_axis(const GaussianCloud& cloud);

}  // namespace raysplats
