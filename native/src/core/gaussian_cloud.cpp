#include "raysplats/gaussian_cloud.h"

#include <algorithm>
#include <cmath>

#include "raysplats/errors.h"

namespace raysplats {

void GaussianCloud::resize(std::size_t n, int degree) {
    if (degree < 0 || degree > 3) throw InvalidArgument("SH degree must be 0..3, got " + std::to_string(degree));
    sh_degree = degree;
    positions.assign(3 * n, 0.0f);
    rotations.assign(4 * n, 0.0f);
    for (std::size_t i = 0; i < n; ++i) rotations[4 * i] = 1.0f;
    scales.assign(3 * n, 0.0f);
    opacities.assign(n, 0.0f);
    sh.assign(n * sh_coeff_count(degree) * 3, 0.0f);
}

void GaussianCloud::check_consistent() const {
    const std::size_t n = size();
    if (sh_degree < 0 || sh_degree > 3) throw InvalidArgument("SH degree must be 0..3, got " + std::to_string(sh_degree));
    auto expect = [&](const std::vector<float>& a, std::size_t want, const char* name) {
        if (a.size() != want)
            throw InvalidArgument(std::string("Gaussian array '") + name + "' has " + std::to_string(a.size()) +
                                  " values, expected " + std::to_string(want) + " for " + std::to_string(n) +
                                  " Gaussians");
    };
    expect(positions, 3 * n, "positions");
    expect(rotations, 4 * n, "rotations");
    expect(scales, 3 * n, "scales");
    expect(sh, n * sh_coeff_count(sh_degree) * 3, "sh");
}

void GaussianCloud::check_values(const std::string& name, std::size_t begin, std::size_t end) const {
    end = std::min(end, size());
    const std::size_t k = std::size_t(coeffs_per_channel()) * 3;
    for (std::size_t i = begin; i < end; ++i) {
        bool ok = std::isfinite(opacities[i]);
        for (int j = 0; j < 3; ++j) ok = ok && std::isfinite(positions[3 * i + j]) && std::isfinite(scales[3 * i + j]);
        for (int j = 0; j < 4; ++j) ok = ok && std::isfinite(rotations[4 * i + j]);
        for (std::size_t j = 0; j < k; ++j) ok = ok && std::isfinite(sh[i * k + j]);
        if (!ok) throw InvalidArgument(name + ": Gaussian " + std::to_string(i) + " has a NaN or Inf value");
        if (scales[3 * i] < 0 || scales[3 * i + 1] < 0 || scales[3 * i + 2] < 0)
            throw InvalidArgument(name + ": Gaussian " + std::to_string(i) + " has a negative scale (scales are linear)");
    }
}

void GaussianCloud::assign_rows(const GaussianCloud& values, const std::uint32_t* rows, const std::string& name) {
    values.check_consistent();
    if (values.sh_degree != sh_degree)
        throw InvalidArgument(name + ": the new Gaussians have SH degree " + std::to_string(values.sh_degree) +
                              ", the cloud " + std::to_string(sh_degree));
    values.check_values(name + " (new values)");
    for (std::size_t j = 0; j < values.size(); ++j)
        if (rows[j] >= size())
            throw InvalidArgument(name + ": Gaussian " + std::to_string(rows[j]) + " of " + std::to_string(size()) +
                                  " does not exist");
    const std::size_t k = std::size_t(coeffs_per_channel()) * 3;
    for (std::size_t j = 0; j < values.size(); ++j) {
        const std::size_t i = rows[j];
        std::copy_n(&values.positions[3 * j], 3, &positions[3 * i]);
        std::copy_n(&values.rotations[4 * j], 4, &rotations[4 * i]);
        std::copy_n(&values.scales[3 * j], 3, &scales[3 * i]);
        opacities[i] = values.opacities[j];
        std::copy_n(&values.sh[k * j], k, &sh[k * i]);
    }
}

}  // namespace raysplats
