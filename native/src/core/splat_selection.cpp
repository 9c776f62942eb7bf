#include "raysplats/splat_selection.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <string>

#include "core/color_math.h"
#include "raysplats/errors.h"

namespace raysplats {
namespace {

constexpr std::size_t kGrain = 4096;

template <class Predicate>
SelectionMask mask_where(std::size_t count, Predicate selected) {
    SelectionMask mask(count);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, count, kGrain), [&](const auto& range) {
        for (std::size_t i = range.begin(); i != range.end(); ++i) mask[i] = selected(i) ? 1 : 0;
    });
    return mask;
}

// A k-d tree over points (indices into `points`), split at the median of the widest axis; leaves hold at most
// kLeafSize points. Nodes are implicit: the subtree of [begin, end) splits at mid = (begin + end) / 2.
class PointTree {
public:
    static constexpr std::size_t kLeafSize = 12;

    PointTree(const float* points, std::vector<std::uint32_t> indices) : points_(points), order_(std::move(indices)) {
        split_axis_.assign(order_.size(), 0);
        build(0, order_.size());
    }

    // The k nearest points to point `self` other than itself: their squared distances, ascending, in `best`
    // (resized to at most k).
    void nearest(std::uint32_t self, int k, std::vector<double>& best) const {
        best.clear();
        const float* q = &points_[3 * std::size_t(self)];
        search(0, order_.size(), q, self, std::size_t(k), best);
    }

private:
    double coordinate(std::uint32_t point, int axis) const { return points_[3 * std::size_t(point) + axis]; }

    void build(std::size_t begin, std::size_t end) {
        if (end - begin <= kLeafSize) return;
        double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
        for (std::size_t i = begin; i < end; ++i)
            for (int a = 0; a < 3; ++a) {
                const double c = coordinate(order_[i], a);
                lo[a] = std::min(lo[a], c), hi[a] = std::max(hi[a], c);
            }
        int axis = 0;
        for (int a = 1; a < 3; ++a)
            if (hi[a] - lo[a] > hi[axis] - lo[axis]) axis = a;
        const std::size_t mid = (begin + end) / 2;
        std::nth_element(order_.begin() + std::ptrdiff_t(begin), order_.begin() + std::ptrdiff_t(mid),
                         order_.begin() + std::ptrdiff_t(end),
                         [&](std::uint32_t a, std::uint32_t b) { return coordinate(a, axis) < coordinate(b, axis); });
        split_axis_[mid] = std::uint8_t(axis);
        build(begin, mid);
        build(mid + 1, end);
    }

    // Keeps `best` a sorted list of the k smallest squared distances seen.
    static void offer(std::vector<double>& best, std::size_t k, double d2) {
        if (best.size() == k && d2 >= best.back()) return;
        best.insert(std::upper_bound(best.begin(), best.end(), d2), d2);
        if (best.size() > k) best.pop_back();
    }

    double squared_distance(const float* q, std::uint32_t point) const {
        const float* p = &points_[3 * std::size_t(point)];
        const double dx = double(p[0]) - q[0], dy = double(p[1]) - q[1], dz = double(p[2]) - q[2];
        return dx * dx + dy * dy + dz * dz;
    }

    void search(std::size_t begin, std::size_t end, const float* q, std::uint32_t self, std::size_t k,
                std::vector<double>& best) const {
        if (end - begin <= kLeafSize) {
            for (std::size_t i = begin; i < end; ++i)
                if (order_[i] != self) offer(best, k, squared_distance(q, order_[i]));
            return;
        }
        const std::size_t mid = (begin + end) / 2;
        const int axis = split_axis_[mid];
        const std::uint32_t pivot = order_[mid];
        if (pivot != self) offer(best, k, squared_distance(q, pivot));
        const double delta = double(q[axis]) - coordinate(pivot, axis);
        const bool left_first = delta < 0;
        if (left_first) search(begin, mid, q, self, k, best); else search(mid + 1, end, q, self, k, best);
        if (best.size() < k || delta * delta < best.back()) {
            if (left_first) search(mid + 1, end, q, self, k, best); else search(begin, mid, q, self, k, best);
        }
    }

    const float* points_;
    std::vector<std::uint32_t> order_;
    std::vector<std::uint8_t> split_axis_;  // at the median position of each inner node's range
};

bool finite3(const float* p) { return std::isfinite(p[0]) && std::isfinite(p[1]) && std::isfinite(p[2]); }

}  // namespace

SelectionMask select_by_value_range(const float* values, std::size_t count, float min_value, float max_value) {
    return mask_where(count, [&](std::size_t i) { return values[i] >= min_value && values[i] <= max_value; });
}

SelectionMask select_by_largest_scale(const float* scales, std::size_t count, float min_scale, float max_scale) {
    return mask_where(count, [&](std::size_t i) {
        const float* s = &scales[3 * i];
        const float largest = std::max(s[0], std::max(s[1], s[2]));
        return largest >= min_scale && largest <= max_scale;
    });
}

SelectionMask select_by_color_distance(const float* sh_dc, std::size_t count, const float target_display_rgb[3],
                                       float max_distance) {
    const double limit = double(max_distance) * double(max_distance);
    return mask_where(count, [&](std::size_t i) {
        double d2 = 0.0;
        for (int c = 0; c < 3; ++c) {
            const double display = std::min(1.0, std::max(0.0, sh_dc_to_display(sh_dc[3 * i + c])));
            const double d = display - target_display_rgb[c];
            d2 += d * d;
        }
        return d2 <= limit;  // false for NaN
    });
}

SelectionMask select_floaters(const float* positions, std::size_t count, int k, double std_ratio,
                              float* mean_neighbor_distances) {
    if (k < 1) throw InvalidArgument("floaters: the number of neighbours must be at least 1 (got " +
                                     std::to_string(k) + ")");
    if (!std::isfinite(std_ratio)) throw InvalidArgument("floaters: the threshold must be a finite number");
    std::vector<std::uint32_t> finite;
    finite.reserve(count);
    for (std::size_t i = 0; i < count; ++i)
        if (finite3(&positions[3 * i])) finite.push_back(std::uint32_t(i));
    std::vector<double> distances(count, NAN);
    SelectionMask mask(count, 0);
    if (finite.size() > std::size_t(k)) {
        const PointTree tree(positions, finite);
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, finite.size(), 1024), [&](const auto& range) {
            std::vector<double> best;
            best.reserve(std::size_t(k) + 1);
            for (std::size_t j = range.begin(); j != range.end(); ++j) {
                tree.nearest(finite[j], k, best);
                double sum = 0.0;
                for (double d2 : best) sum += std::sqrt(d2);
                distances[finite[j]] = sum / double(best.size());
            }
        });
        double sum = 0.0, sum2 = 0.0;
        for (std::uint32_t i : finite) sum += distances[i];
        const double mean = sum / double(finite.size());
        for (std::uint32_t i : finite) sum2 += (distances[i] - mean) * (distances[i] - mean);
        const double threshold = mean + std_ratio * std::sqrt(sum2 / double(finite.size()));
        for (std::uint32_t i : finite) mask[i] = distances[i] > threshold ? 1 : 0;
    }
    if (mean_neighbor_distances)
        for (std::size_t i = 0; i < count; ++i) mean_neighbor_distances[i] = float(distances[i]);
    return mask;
}

SelectionMask select_in_box(const float* positions, std::size_t count, const double world_to_box[16],
                            const float box_min[3], const float box_max[3], bool inside) {
    for (int i = 0; i < 16; ++i)
        if (!std::isfinite(world_to_box[i]))
            throw InvalidArgument("crop box: its transform contains NaN or infinite values");
    const double* m = world_to_box;
    return mask_where(count, [&](std::size_t i) {
        const float* p = &positions[3 * i];
        bool in = finite3(p);
        for (int a = 0; a < 3 && in; ++a) {
            const double local = m[4 * a] * p[0] + m[4 * a + 1] * p[1] + m[4 * a + 2] * p[2] + m[4 * a + 3];
            in = local >= box_min[a] && local <= box_max[a];
        }
        return in == inside && finite3(p);
    });
}

MeshElementSelection select_face_elements(const std::uint8_t* face_mask, std::size_t face_count,
                                          const std::int32_t* face_corner_start, const std::int32_t* face_corner_count,
                                          const std::int32_t* corner_vertices, const std::int32_t* corner_edges,
                                          std::size_t corner_count, std::size_t vertex_count, std::size_t edge_count) {
    MeshElementSelection out{SelectionMask(vertex_count, 0), SelectionMask(edge_count, 0)};
    for (std::size_t f = 0; f < face_count; ++f) {
        if (!face_mask[f]) continue;
        const std::int64_t start = face_corner_start[f], n = face_corner_count[f];
        if (start < 0 || n < 0 || std::size_t(start + n) > corner_count)
            throw InvalidArgument("face " + std::to_string(f) + " has corners outside the mesh's " +
                                  std::to_string(corner_count));
        for (std::int64_t c = start; c < start + n; ++c) {
            const std::int32_t v = corner_vertices[c], e = corner_edges[c];
            if (v < 0 || std::size_t(v) >= vertex_count || e < 0 || std::size_t(e) >= edge_count)
                throw InvalidArgument("corner " + std::to_string(c) + " names a vertex or edge the mesh does not have");
            out.vertices[std::size_t(v)] = 1;
            out.edges[std::size_t(e)] = 1;
        }
    }
    return out;
}

}  // namespace raysplats
