#include "raysplats/splat_selection.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "raysplats/errors.h"

namespace raysplats {
namespace {

// Mean distance to the k nearest other points by brute force: what the k-d tree must reproduce.
std::vector<double> brute_force_mean_distances(const std::vector<float>& p, int k) {
    const std::size_t n = p.size() / 3;
    std::vector<double> out(n);
    for (std::size_t i = 0; i < n; ++i) {
        std::vector<double> d;
        for (std::size_t j = 0; j < n; ++j) {
            if (j == i) continue;
            const double dx = double(p[3 * j]) - p[3 * i], dy = double(p[3 * j + 1]) - p[3 * i + 1],
                         dz = double(p[3 * j + 2]) - p[3 * i + 2];
            d.push_back(std::sqrt(dx * dx + dy * dy + dz * dz));
        }
        std::partial_sort(d.begin(), d.begin() + k, d.end());
        double sum = 0;
        for (int m = 0; m < k; ++m) sum += d[std::size_t(m)];
        out[i] = sum / k;
    }
    return out;
}

TEST(SplatSelection, FloatersMatchBruteForceNeighbours) {
    std::mt19937 rng(7);
    std::normal_distribution<float> cluster(0.0f, 1.0f);
    std::uniform_real_distribution<float> far(-40.0f, 40.0f);
    std::vector<float> points;
    for (int i = 0; i < 2000; ++i) points.insert(points.end(), {cluster(rng), cluster(rng), cluster(rng)});
    for (int i = 0; i < 20; ++i) points.insert(points.end(), {far(rng), far(rng), 30.0f + far(rng)});
    points.insert(points.end(), {1.0f, 1.0f, 1.0f, 1.0f, 1.0f, 1.0f});  // coincident pair: distance 0 to each other
    const std::size_t n = points.size() / 3;
    const int k = 8;
    std::vector<float> distances(n);
    const SelectionMask mask = select_floaters(points.data(), n, k, 2.0, distances.data());
    const std::vector<double> expected = brute_force_mean_distances(points, k);
    double mean = 0, var = 0;
    for (double d : expected) mean += d / double(n);
    for (double d : expected) var += (d - mean) * (d - mean) / double(n);
    const double threshold = mean + 2.0 * std::sqrt(var);
    std::size_t far_selected = 0, selected = 0;
    for (std::size_t i = 0; i < n; ++i) {
        ASSERT_NEAR(distances[i], expected[i], 1e-5 * (1 + expected[i])) << i;
        EXPECT_EQ(mask[i], expected[i] > threshold ? 1 : 0) << i;
        selected += mask[i];
        far_selected += (i >= 2000 && i < 2020) ? mask[i] : 0;
    }
    EXPECT_EQ(far_selected, 20u);  // every far point is a floater
    EXPECT_EQ(selected, 20u);      // and nothing of the cluster
}

TEST(SplatSelection, FloatersIgnoreNonFiniteAndSmallClouds) {
    std::vector<float> points = {0, 0, 0, 1, 0, 0, NAN, 0, 0, 0, 1, 0};
    std::vector<float> d(4);
    const SelectionMask mask = select_floaters(points.data(), 4, 2, 0.0, d.data());
    EXPECT_EQ(mask[2], 0);
    EXPECT_TRUE(std::isnan(d[2]));
    EXPECT_NEAR(d[0], 1.0, 1e-6);  // neighbours (1,0,0) and (0,1,0)
    EXPECT_EQ(select_floaters(points.data(), 2, 2, 0.0), SelectionMask(2, 0));
    EXPECT_THROW(select_floaters(points.data(), 4, 0, 1.0), InvalidArgument);
}

TEST(SplatSelection, RangesColourAndBox) {
    const float opacity[4] = {0.1f, 0.5f, NAN, 0.9f};
    EXPECT_EQ(select_by_value_range(opacity, 4, 0.1f, 0.5f), (SelectionMask{1, 1, 0, 0}));
    const float scales[6] = {0.1f, 2.0f, 0.3f, 0.5f, 0.4f, 0.45f};
    EXPECT_EQ(select_by_largest_scale(scales, 2, 1.0f, 3.0f), (SelectionMask{1, 0}));
    // f_dc = 0 is display grey 0.5; f_dc = 1.7725 (≈ 0.5 / SH_C0) is white, clamped.
    const float dc[6] = {0, 0, 0, 10, 10, 10};
    const float grey[3] = {0.5f, 0.5f, 0.5f}, white[3] = {1, 1, 1};
    EXPECT_EQ(select_by_color_distance(dc, 2, grey, 0.01f), (SelectionMask{1, 0}));
    EXPECT_EQ(select_by_color_distance(dc, 2, white, 0.01f), (SelectionMask{0, 1}));
    // Box scaled by 2 about the origin: world points within ±2 are inside the unit box.
    const double world_to_box[16] = {0.5, 0, 0, 0, 0, 0.5, 0, 0, 0, 0, 0.5, 0, 0, 0, 0, 1};
    const float points[9] = {1.9f, 0, 0, 2.1f, 0, 0, NAN, 0, 0};
    const float lo[3] = {-1, -1, -1}, hi[3] = {1, 1, 1};
    EXPECT_EQ(select_in_box(points, 3, world_to_box, lo, hi, true), (SelectionMask{1, 0, 0}));
    EXPECT_EQ(select_in_box(points, 3, world_to_box, lo, hi, false), (SelectionMask{0, 1, 0}));
}

TEST(SplatSelection, FaceElementsFollowTheFaces) {
    // Two triangles sharing the edge (1, 2): vertices 0 1 2 and 2 1 3, edges 0:(0,1) 1:(1,2) 2:(2,0) 3:(1,3) 4:(3,2).
    const std::int32_t starts[2] = {0, 3}, counts[2] = {3, 3};
    const std::int32_t corner_vertices[6] = {0, 1, 2, 2, 1, 3}, corner_edges[6] = {0, 1, 2, 1, 3, 4};
    const std::uint8_t faces[2] = {0, 1};
    const MeshElementSelection s = select_face_elements(faces, 2, starts, counts, corner_vertices, corner_edges, 6, 4, 5);
    EXPECT_EQ(s.vertices, (SelectionMask{0, 1, 1, 1}));
    EXPECT_EQ(s.edges, (SelectionMask{0, 1, 0, 1, 1}));
    const std::int32_t bad_edges[6] = {0, 1, 2, 1, 3, 9};
    EXPECT_THROW(select_face_elements(faces, 2, starts, counts, corner_vertices, bad_edges, 6, 4, 5), InvalidArgument);
}

}  // namespace
}  // namespace raysplats
