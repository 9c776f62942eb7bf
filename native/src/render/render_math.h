// Small math shared by the render sources (internal): glm conversions, random numbers, frames; colour is
// core/color_math.h.
#pragma once

#include <cmath>
#include <cstdint>

#include <glm/glm.hpp>

#include "core/color_math.h"
#include "raysplats/render/transform.h"

namespace raysplats {

constexpr float kPi = 3.14159265358979323846f;
constexpr float kInvPi = 0.31830988618379067154f;

// Affine part of a Matrix4 as glm (column-major) types.
inline glm::mat3 linear_part(const Matrix4& m) {
    glm::mat3 a;
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) a[c][r] = m(r, c);
    return a;
}
inline glm::vec3 translation_part(const Matrix4& m) { return {m(0, 3), m(1, 3), m(2, 3)}; }

// Integer hashes (Jarzynski & Olano 2020, "Hash Functions for GPU Rendering": pcg / pcg3d-style mixing).
inline std::uint32_t hash_u32(std::uint32_t v) {
    std::uint32_t state = v * 747796405u + 2891336453u;
    std::uint32_t word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}
inline std::uint32_t hash_combine(std::uint32_t a, std::uint32_t b) { return hash_u32(a ^ (b + 0x9e3779b9u + (a << 6) + (a >> 2))); }
inline float u32_to_unit_float(std::uint32_t x) { return float(x >> 8) * (1.0f / 16777216.0f); }

// Per pixel-sample random stream: deterministic from (seed, pixel, sample), independent of threads.
struct Sampler {
    std::uint32_t state = 0;
    Sampler() = default;  // a placeholder: only a seeded sampler's numbers are used
    Sampler(std::uint32_t seed, std::uint64_t pixel, std::uint32_t sample)
        : state(hash_combine(hash_combine(hash_u32(seed), std::uint32_t(pixel) ^ hash_u32(std::uint32_t(pixel >> 32))),
                             hash_u32(sample * 0x68bc21ebu + 0x2545f491u))) {}
    std::uint32_t next_u32() {
        state = state * 747796405u + 2891336453u;
        std::uint32_t word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
        return (word >> 22u) ^ word;
    }
    float next() { return u32_to_unit_float(next_u32()); }
};

// Orthonormal basis around a unit normal (Duff et al. 2017, "Building an Orthonormal Basis, Revisited").
inline void make_frame(const glm::vec3& n, glm::vec3& t, glm::vec3& b) {
    const float s = std::copysign(1.0f, n.z);
    const float a = -1.0f / (s + n.z);
    const float bb = n.x * n.y * a;
    t = glm::vec3(1.0f + s * n.x * n.x * a, s * bb, -s * n.x);
    b = glm::vec3(bb, s + n.y * n.y * a, -n.y);
}

inline float luminance(const glm::vec3& c) { return 0.2126f * c.x + 0.7152f * c.y + 0.0722f * c.z; }

}  // namespace raysplats
