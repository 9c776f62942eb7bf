// Morton order of Gaussian centres (core/morton_order.h).
#include "core/morton_order.h"

#include "core/radix_sort.h"
#include "raysplats/default_init_allocator.h"

#include <tbb/parallel_for.h>

#include <glm/glm.hpp>
#include <limits>

namespace raysplats {

std::vector<std::uint32_t> morton_order(const GaussianCloud& c) {
    const std::size_t n = c.size();
    glm::vec3 lo(std::numeric_limits<float>::max()), hi(-std::numeric_limits<float>::max());
    for (std::size_t i = 0; i < n; ++i) {
        const glm::vec3 p(c.positions[3 * i], c.positions[3 * i + 1], c.positions[3 * i + 2]);
        lo = glm::min(lo, p);
        hi = glm::max(hi, p);
    }
    const glm::vec3 extent = glm::max(hi - lo, glm::vec3(1e-30f));
    auto spread = [](std::uint64_t v) {  // 10 bits -> every third bit
        v &= 0x3ff;
        v = (v | (v << 16)) & 0x30000ff;
        v = (v | (v << 8)) & 0x300f00f;
        v = (v | (v << 4)) & 0x30c30c3;
        v = (v | (v << 2)) & 0x9249249;
        return v;
    };
    std::vector<std::uint64_t, DefaultInitAllocator<std::uint64_t>> keyed(n);  // (written in parallel below)
    tbb::parallel_for(std::size_t(0), n, [&](std::size_t i) {
        const glm::vec3 p(c.positions[3 * i], c.positions[3 * i + 1], c.positions[3 * i + 2]);
        const glm::vec3 q = glm::clamp((p - lo) / extent, 0.0f, 1.0f) * 1023.0f;
        const std::uint64_t code = spread(std::uint64_t(q.x)) | (spread(std::uint64_t(q.y)) << 1) | (spread(std::uint64_t(q.z)) << 2);
        keyed[i] = (code << 32) | std::uint64_t(i);
    });
    sort_by_high_word(keyed);  // (the low words are the indices, ascending)
    std::vector<std::uint32_t> order(n);
    for (std::size_t j = 0; j < n; ++j) order[j] = std::uint32_t(keyed[j] & 0xffffffffu);
    return order;
}


}  // namespace raysplats
