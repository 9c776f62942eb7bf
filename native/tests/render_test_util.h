// Scene builders shared by the render tests (constructed in code; no file readers needed).
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <random>
#include <vector>

#include "raysplats/gaussian_cloud.h"
#include "raysplats/render/renderer.h"
#include "raysplats/spherical_harmonics.h"

namespace raysplats::testing {

// SH DC coefficient giving display colour c (c = 0.5 + C0 * dc).
inline float dc_for(float c) { return (c - 0.5f) / float(kShC0); }

inline double srgb_to_linear_ref(double c) { return c <= 0.04045 ? c / 12.92 : std::pow((c + 0.055) / 1.055, 2.4); }
inline double linear_to_srgb_ref(double c) { return c <= 0.0031308 ? 12.92 * c : 1.055 * std::pow(c, 1.0 / 2.4) - 0.055; }

// Appends a degree-0 Gaussian.
inline void add_gaussian(GaussianCloud& cloud, const float pos[3], const float quat_wxyz[4], const float scale[3],
                         float opacity, const float rgb[3]) {
    const std::size_t i = cloud.size();
    cloud.positions.insert(cloud.positions.end(), pos, pos + 3);
    cloud.rotations.insert(cloud.rotations.end(), quat_wxyz, quat_wxyz + 4);
    cloud.scales.insert(cloud.scales.end(), scale, scale + 3);
    cloud.opacities.push_back(opacity);
    const int k = cloud.coeffs_per_channel();
    cloud.sh.resize((i + 1) * k * 3, 0.0f);
    for (int c = 0; c < 3; ++c) cloud.sh[i * k * 3 + c] = dc_for(rgb[c]);
}

// A mesh that owns its arrays (vertices padded by one float so Embree shares them).
struct TestMesh {
    std::vector<float> vertices;
    std::vector<std::uint32_t> indices;
    std::vector<float> normals;
    std::uint32_t material = 0;
    Matrix4 object_to_world;

    std::size_t vertex_count() const { return (vertices.size() - 1) / 3; }
    MeshDesc desc() const {
        MeshDesc d;
        d.vertices = vertices.data();
        d.vertex_count = vertex_count();
        d.vertices_padded = true;
        d.indices = indices.data();
        d.triangle_count = indices.size() / 3;
        d.material = material;
        d.object_to_world = object_to_world;
        return d;
    }
};

// Axis-aligned rectangle in the plane z = z0, normal +Z (counter-clockwise seen from +Z).
inline TestMesh make_quad_z(float x0, float x1, float y0, float y1, float z0, std::uint32_t material) {
    TestMesh m;
    m.vertices = {x0, y0, z0, x1, y0, z0, x1, y1, z0, x0, y1, z0, 0.0f};
    m.indices = {0, 1, 2, 0, 2, 3};
    m.material = material;
    return m;
}

// Axis-aligned box [lo, hi], outward-facing triangles.
inline TestMesh make_box(const float lo[3], const float hi[3], std::uint32_t material) {
    TestMesh m;
    for (int i = 0; i < 8; ++i) {
        m.vertices.push_back(i & 1 ? hi[0] : lo[0]);
        m.vertices.push_back(i & 2 ? hi[1] : lo[1]);
        m.vertices.push_back(i & 4 ? hi[2] : lo[2]);
    }
    m.vertices.push_back(0.0f);
    // Faces as quads (a, b, c, d) counter-clockwise from outside.
    const std::uint32_t q[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4}, {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
    for (auto& f : q) {
        m.indices.insert(m.indices.end(), {f[0], f[1], f[2], f[0], f[2], f[3]});
    }
    m.material = material;
    return m;
}

inline Material emissive(float r, float g, float b) {
    Material m;
    m.base_color = {0.0f, 0.0f, 0.0f};
    m.specular = 0.0f;
    m.emission_color = {r, g, b};
    m.emission_strength = 1.0f;
    return m;
}

inline World black_world() {
    World w;
    w.color = {0.0f, 0.0f, 0.0f};
    return w;
}

// Random unit quaternion (w x y z).
inline void random_quat(std::mt19937& rng, float q[4]) {
    std::normal_distribution<float> n;
    float s = 0;
    for (int i = 0; i < 4; ++i) {
        q[i] = n(rng);
        s += q[i] * q[i];
    }
    s = std::sqrt(s);
    for (int i = 0; i < 4; ++i) q[i] /= s;
}

inline GaussianCloud random_cloud(std::uint32_t seed, int n, float extent) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(0.0f, 1.0f);
    GaussianCloud cloud;
    cloud.sh_degree = 0;
    for (int i = 0; i < n; ++i) {
        const float p[3] = {extent * (2 * u(rng) - 1), extent * (2 * u(rng) - 1), extent * (2 * u(rng) - 1)};
        float q[4];
        random_quat(rng, q);
        const float s[3] = {0.05f + 0.25f * u(rng), 0.05f + 0.25f * u(rng), 0.02f + 0.2f * u(rng)};
        const float c[3] = {u(rng), u(rng), u(rng)};
        add_gaussian(cloud, p, q, s, 0.1f + 0.85f * u(rng), c);
    }
    return cloud;
}

// Asserts that every film channel but `except` holds the same bits in `a` and `b` (`what` names the comparison).
inline void expect_channels_bit_identical(const Film& a, const Film& b, const char* what,
                                          std::vector<FilmChannel> except = {}) {
    for (std::size_t k = 0; k < kFilmChannelCount; ++k) {
        if (std::find(except.begin(), except.end(), FilmChannel(k)) != except.end()) continue;
        const FloatBuffer &x = a[FilmChannel(k)], &y = b[FilmChannel(k)];
        ASSERT_EQ(x.size(), y.size()) << what << ": " << film_channels()[k].key;
        for (std::size_t i = 0; i < x.size(); ++i)
            ASSERT_EQ(std::memcmp(&x[i], &y[i], sizeof(float)), 0) << what << ": " << film_channels()[k].key << " " << i;
    }
}

}  // namespace raysplats::testing
