#include "raysplats/up_axis.h"

#include <tbb/blocked_range.h>
#include <tbb/combinable.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "core/linear_algebra.h"

namespace raysplats {
namespace {

constexpr std::size_t kGrain = 8192;
constexpr std::size_t kMaxHeightSamples = 1000000;
constexpr double kFlatRatio = 0.25;        // smallest scale below this fraction of the middle one: a flat Gaussian
constexpr double kMinOpacity = 0.5;        // only fairly opaque Gaussians draw surfaces
constexpr double kCosNormalAngle = 0.906;  // cos 25°: a normal this close to an axis counts for it
constexpr double kLowPercentile = 0.01, kHighPercentile = 0.99;
constexpr double kSlab = 0.1;              // the lowest tenth of the scene's height

// The q-quantile of `values` (modified: partially sorted).
double quantile(std::vector<float>& values, double q) {
    const std::size_t k = std::min(values.size() - 1, std::size_t(q * double(values.size() - 1) + 0.5));
    std::nth_element(values.begin(), values.begin() + std::ptrdiff_t(k), values.end());
    return values[k];
}

}  // namespace

UpAxisEstimate estimate_up_axis(const GaussianCloud& cloud) {
    cloud.check_consistent();
    UpAxisEstimate estimate;
    const std::size_t n = cloud.size();
    if (n == 0) return estimate;

    // Per axis, the height range [lo, hi] between the 1st and 99th percentile (floaters ignored) and the slabs:
    // along +axis the lowest tenth [lo, lo + 0.1 (hi - lo)), along -axis the highest tenth.
    double low_slab_end[3], high_slab_start[3];
    const std::size_t stride = std::max<std::size_t>(1, n / kMaxHeightSamples);
    std::vector<float> heights;
    heights.reserve(n / stride + 1);
    for (int a = 0; a < 3; ++a) {
        heights.clear();
        for (std::size_t i = 0; i < n; i += stride) heights.push_back(cloud.positions[3 * i + std::size_t(a)]);
        const double lo = quantile(heights, kLowPercentile), hi = quantile(heights, kHighPercentile);
        low_slab_end[a] = lo + kSlab * (hi - lo);
        high_slab_start[a] = hi - kSlab * (hi - lo);
    }

    struct Sums {
        std::array<double, 6> support{};
        double flat_area = 0.0;
        std::size_t flat = 0;
    };
    tbb::combinable<Sums> sums;
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, kGrain), [&](const tbb::blocked_range<std::size_t>& r) {
        Sums& s = sums.local();
        for (std::size_t i = r.begin(); i != r.end(); ++i) {
            const double opacity = cloud.opacities[i];
            if (!(opacity >= kMinOpacity)) continue;
            const float* sc = &cloud.scales[3 * i];
            int order[3] = {0, 1, 2};
            std::sort(order, order + 3, [sc](int a, int b) { return sc[a] < sc[b]; });
            const double s_min = sc[order[0]], s_mid = sc[order[1]], s_max = sc[order[2]];
            if (!(s_min < kFlatRatio * s_mid)) continue;
            const double area = opacity * s_mid * s_max;
            if (!std::isfinite(area)) continue;
            s.flat_area += area;
            ++s.flat;
            const float* q = &cloud.rotations[4 * i];
            const std::array<double, 9> rot = la::quaternion_to_rotation<double>(q[0], q[1], q[2], q[3]);
            const int c = order[0];  // the normal is the rotation's column of the smallest scale
            const double normal[3] = {rot[std::size_t(c)], rot[std::size_t(3 + c)], rot[std::size_t(6 + c)]};
            for (int a = 0; a < 3; ++a) {
                if (std::fabs(normal[a]) < kCosNormalAngle) continue;
                const double h = cloud.positions[3 * i + std::size_t(a)];
                if (h < low_slab_end[a]) s.support[std::size_t(2 * a)] += area;
                if (h > high_slab_start[a]) s.support[std::size_t(2 * a + 1)] += area;
            }
        }
    });
    Sums total;
    sums.combine_each([&](const Sums& s) {
        for (std::size_t k = 0; k < 6; ++k) total.support[k] += s.support[k];
        total.flat_area += s.flat_area;
        total.flat += s.flat;
    });
    estimate.flat_gaussians = total.flat;
    if (!(total.flat_area > 0.0)) return estimate;
    for (std::size_t k = 0; k < 6; ++k) estimate.scores[k] = total.support[k] / total.flat_area;
    const auto& scores = estimate.scores;
    const std::size_t best = std::size_t(std::max_element(scores.begin(), scores.end()) - scores.begin());
    double second = 0.0;
    for (std::size_t k = 0; k < 6; ++k)
        if (k != best) second = std::max(second, scores[k]);
    estimate.best = int(best);
    const double b = estimate.scores[best];
    estimate.margin = b > 0.0 ? (b - second) / b : 0.0;
    estimate.decided = estimate.margin >= kUpAxisMinMargin && b >= kUpAxisMinSupport;
    return estimate;
}

}  // namespace raysplats
