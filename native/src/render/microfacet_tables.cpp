#include "microfacet_tables.h"

#include <algorithm>
#include <cmath>
#include <utility>
#include <vector>

#include <tbb/parallel_for.h>

#include "bsdf.h"

namespace raysplats {

struct MicrofacetTables {
    static constexpr int kE = 32, kS = 16;
    std::vector<float> E;          // [mu][roughness], kE x kE
    std::vector<float> E_avg;      // [roughness], kE
    std::vector<float> ior_s;      // [z][mu][roughness], kS^3
    std::vector<float> schlick_s;  // [mu][roughness], kS x kS
};

namespace {

constexpr int kSamples = 1024;

float radical_inverse_base2(unsigned i) {
    i = (i << 16u) | (i >> 16u);
    i = ((i & 0x55555555u) << 1u) | ((i & 0xAAAAAAAAu) >> 1u);
    i = ((i & 0x33333333u) << 2u) | ((i & 0xCCCCCCCCu) >> 2u);
    i = ((i & 0x0F0F0F0Fu) << 4u) | ((i & 0xF0F0F0F0u) >> 4u);
    i = ((i & 0x00FF00FFu) << 8u) | ((i & 0xFF00FF00u) >> 8u);
    return float(i) * 2.3283064365386963e-10f;
}

float smith_lambda(float alpha2, float cos_n) {
    // Heitz 2014, "Understanding the Masking-Shadowing Function", eq. 72 (Cycles bsdf_lambda for GGX).
    const float c2 = std::max(cos_n * cos_n, 1e-12f);
    return 0.5f * (std::sqrt(1.0f + alpha2 * std::max(1.0f / c2 - 1.0f, 0.0f)) - 1.0f);
}

// Averages over GGX reflection seen at cos mu, in Cycles' estimator: visible normals H sampled (Heitz 2018,
// "Sampling the GGX Distribution of Visible Normals"), weight G2 / G1 = (1 + L_i) / (1 + L_i + L_o), zero when the
// reflected ray is below the surface. Returns (sum of weight * fresnel(cos_HI), sum of weight) / samples.
template <typename Fresnel>
std::pair<double, double> vndf_average(float roughness, float mu, Fresnel fresnel) {
    const float alpha = roughness * roughness, alpha2 = alpha * alpha;
    const glm::vec3 wi(std::sqrt(std::max(0.0f, 1.0f - mu * mu)), 0.0f, mu);
    const glm::vec3 wi_s = glm::normalize(glm::vec3(alpha * wi.x, alpha * wi.y, wi.z));
    const float lensq = wi_s.x * wi_s.x + wi_s.y * wi_s.y;
    const glm::vec3 t1 = lensq > 1e-7f ? glm::vec3(-wi_s.y, wi_s.x, 0.0f) / std::sqrt(lensq) : glm::vec3(1, 0, 0);
    const glm::vec3 t2 = glm::cross(wi_s, t1);
    const float lambda_i = smith_lambda(alpha2, mu);
    double sum_f = 0.0, sum = 0.0;
    for (int k = 0; k < kSamples; ++k) {
        const float u1 = (k + 0.5f) / kSamples, u2 = radical_inverse_base2(unsigned(k));
        const float r = std::sqrt(u1), phi = 2.0f * kPi * u2;
        float tx = r * std::cos(phi), ty = r * std::sin(phi);
        const float s = 0.5f * (1.0f + wi_s.z);
        ty = (1.0f - s) * std::sqrt(std::max(0.0f, 1.0f - tx * tx)) + s * ty;
        const glm::vec3 h_s = tx * t1 + ty * t2 + std::sqrt(std::max(0.0f, 1.0f - tx * tx - ty * ty)) * wi_s;
        const glm::vec3 h = glm::normalize(glm::vec3(alpha * h_s.x, alpha * h_s.y, std::max(0.0f, h_s.z)));
        const float cos_hi = glm::dot(h, wi);
        const glm::vec3 wo = 2.0f * cos_hi * h - wi;
        if (wo.z <= 0.0f) continue;
        const double w = (1.0 + lambda_i) / (1.0 + lambda_i + smith_lambda(alpha2, wo.z));
        sum += w;
        sum_f += w * fresnel(cos_hi);
    }
    return {sum_f / kSamples, sum / kSamples};
}

float grid(int i, int n) { return std::clamp(float(i) / float(n - 1), 1e-4f, 1.0f); }

// Cycles' IOR parametrization of the table axis z: eta = ior_from_F0(z^4), z clamped to [1e-4, 0.99].
float ior_from_z(int i, int n) {
    const float z = std::clamp(float(i) / float(n - 1), 1e-4f, 0.99f);
    const float sqrt_f0 = std::sqrt(std::clamp(z * z * z * z, 0.0f, 0.99f));
    return (1.0f + sqrt_f0) / (1.0f - sqrt_f0);
}

MicrofacetTables build() {
    MicrofacetTables t;
    constexpr int nE = MicrofacetTables::kE, nS = MicrofacetTables::kS;
    auto one = [](float) { return 1.0; };
    t.E.resize(nE * nE);
    tbb::parallel_for(0, nE * nE, [&](int i) {
        t.E[i] = std::min(1.0f, float(vndf_average(grid(i % nE, nE), grid(i / nE, nE), one).second));
    });
    // E_avg = integral_0^1 2 mu E(mu) dmu by the midpoint rule over 64 values of mu.
    t.E_avg.resize(nE);
    tbb::parallel_for(0, nE, [&](int x) {
        double sum = 0.0;
        for (int k = 0; k < 64; ++k) {
            const float mu = (k + 0.5f) / 64.0f;
            sum += 2.0 * mu * vndf_average(grid(x, nE), mu, one).second / 64.0;
        }
        t.E_avg[x] = std::min(1.0f, float(sum));
    });
    // Cycles precompute_ggx_gen_schlick_s: the ratio of the Fresnel-weighted to the plain average.
    t.ior_s.resize(nS * nS * nS);
    tbb::parallel_for(0, nS * nS * nS, [&](int i) {
        const float eta = ior_from_z(i / (nS * nS), nS);
        const float f0 = (eta - 1.0f) * (eta - 1.0f) / ((eta + 1.0f) * (eta + 1.0f));
        const auto avg = vndf_average(grid(i % nS, nS), grid((i / nS) % nS, nS), [&](float c) {
            float cos_t;
            return double(std::clamp((fresnel_dielectric(c, eta, cos_t) - f0) / (1.0f - f0), 0.0f, 1.0f));
        });
        t.ior_s[i] = std::clamp(float(avg.first / std::max(avg.second, 1e-12)), 0.0f, 1.0f);
    });
    t.schlick_s.resize(nS * nS);
    tbb::parallel_for(0, nS * nS, [&](int i) {
        float s = 0.0f;
        for (float exponent : {40.0f / 7.0f, 35.0f / 8.0f}) {
            const auto avg = vndf_average(grid(i % nS, nS), grid(i / nS, nS),
                                          [&](float c) { return double(std::pow(std::max(0.0f, 1.0f - c), exponent)); });
            s += 0.5f * std::clamp(float(avg.first / std::max(avg.second, 1e-12)), 0.0f, 1.0f);
        }
        t.schlick_s[i] = s;
    });
    return t;
}

// Cycles lookup_table_read: position x in [0, 1] on an axis of n entries -> (index, next index, fraction).
struct Axis {
    int i0, i1;
    float t;
    Axis(float x, int n) {
        x = std::clamp(x, 0.0f, 1.0f) * float(n - 1);
        i0 = std::min(int(x), n - 1);
        i1 = std::min(i0 + 1, n - 1);
        t = x - float(i0);
    }
};

float lerp(float a, float b, float t) { return (1.0f - t) * a + t * b; }

float read_2d(const float* table, int n, float x, float y) {
    const Axis ax(x, n), ay(y, n);
    auto row = [&](int j) { return lerp(table[j * n + ax.i0], table[j * n + ax.i1], ax.t); };
    return lerp(row(ay.i0), row(ay.i1), ay.t);
}

}  // namespace

const MicrofacetTables& microfacet_tables() {
    static const MicrofacetTables tables = build();
    return tables;
}

float ggx_E(float roughness, float mu) {
    return read_2d(microfacet_tables().E.data(), MicrofacetTables::kE, roughness, mu);
}

float ggx_E_avg(float roughness) {
    const Axis a(roughness, MicrofacetTables::kE);
    const auto& t = microfacet_tables().E_avg;
    return lerp(t[a.i0], t[a.i1], a.t);
}

float ggx_gen_schlick_ior_s(float roughness, float mu, float eta) {
    constexpr int n = MicrofacetTables::kS;
    const float z = std::sqrt(std::abs((eta - 1.0f) / (eta + 1.0f)));
    const Axis az(z, n);
    const float* t = microfacet_tables().ior_s.data();
    return lerp(read_2d(t + az.i0 * n * n, n, roughness, mu), read_2d(t + az.i1 * n * n, n, roughness, mu), az.t);
}

float ggx_schlick_s(float roughness, float mu) {
    return read_2d(microfacet_tables().schlick_s.data(), MicrofacetTables::kS, roughness, mu);
}

float fresnel_dielectric_Fss(float eta) {
    if (eta < 1.0f) return 0.997118f + eta * (0.1014f - eta * (0.965241f + eta * 0.130607f));
    return (eta - 1.0f) / (4.08567f + 1.00071f * eta);
}

}  // namespace raysplats
