// Principled BSDF v2 (Cycles 4.x) of bsdf.h: F82-tint metal Fresnel, the layering of the dielectric specular layer
// over the diffuse base, multiple-scattering energy compensation, and the GGX albedo tables it reads.
#include <gtest/gtest.h>

#include <cmath>

#include "render/bsdf.h"
#include "render/microfacet_tables.h"

using namespace raysplats;

namespace {

constexpr double kPiD = 3.14159265358979323846;

Material principled_v2() {
    Material m;
    m.principled_version = PrincipledVersion::V2;
    m.diffuse_model = DiffuseModel::Lambert;
    m.ior = 1.5f;
    return m;
}

glm::vec3 view(float mu) { return {std::sqrt(1.0f - mu * mu), 0.0f, mu}; }

// Directional albedo of a BSDF seen from wo: the mean sample weight (absorbed samples count as zero).
glm::vec3 albedo(const Bsdf& bsdf, const glm::vec3& wo, int samples) {
    glm::dvec3 sum(0.0);
    for (int i = 0; i < samples; ++i) {
        Sampler rng(7, std::uint64_t(i), 0);
        BsdfSample s;
        if (bsdf.sample(wo, rng, s)) sum += glm::dvec3(s.weight);
    }
    return glm::vec3(sum / double(samples));
}

}  // namespace

// F82-tint (Cycles fresnel_f82 with fresnel_f82tint_B): F(1) = F0 = base colour, and at cos = 1/7 the value is
// Schlick's F0 + (1 - F0)(6/7)^5 times the Specular Tint. Without tint it is Schlick's curve at every angle.
TEST(PrincipledV2, MetalFresnelIsF82Tint) {
    Material m = principled_v2();
    m.metallic = 1.0f;
    m.base_color = {0.9f, 0.6f, 0.2f};
    m.specular_tint = {0.5f, 0.8f, 1.0f};
    const glm::vec3 n(0, 0, 1), base(0.9f, 0.6f, 0.2f);
    const Bsdf tinted(m, base, n, view(0.7f), true);
    const double s5 = std::pow(6.0 / 7.0, 5.0);
    for (int c = 0; c < 3; ++c) {
        EXPECT_NEAR(tinted.spec_fresnel(1.0f)[c], base[c], 1e-6);
        EXPECT_NEAR(tinted.spec_fresnel(1.0f / 7.0f)[c], (base[c] + (1.0 - base[c]) * s5) * m.specular_tint[c], 1e-5);
    }
    m.specular_tint = {1.0f, 1.0f, 1.0f};
    const Bsdf plain(m, base, n, view(0.7f), true);
    for (float cos : {0.05f, 0.3f, 0.9f})
        for (int c = 0; c < 3; ++c)
            EXPECT_NEAR(plain.spec_fresnel(cos)[c], base[c] + (1.0 - base[c]) * std::pow(1.0 - cos, 5.0), 1e-5);
}

// A smooth dielectric seen head-on reflects F0 = ((ior - 1) / (ior + 1))^2 * 2 * level, and the diffuse base keeps
// the rest (Cycles closure_layering_weight): 1 - 0.04 for IOR 1.5 at level 0.5, 1 - 0.08 at level 1, all of it at
// level 0 (no specular layer). With reflective caustics filtered out the layer is absent and the base keeps 1.
TEST(PrincipledV2, DiffuseBaseKeepsWhatTheSpecularLayerDoesNotReflect) {
    Material m = principled_v2();
    m.roughness = 0.01f;
    const glm::vec3 n(0, 0, 1), white(1.0f);
    for (auto [level, f0] : {std::pair{0.5f, 0.04f}, std::pair{1.0f, 0.08f}, std::pair{0.0f, 0.0f}}) {
        m.specular = level;
        const Bsdf bsdf(m, white, n, view(1.0f), true);
        EXPECT_NEAR(bsdf.w_diffuse, 1.0f - f0, 1e-3) << "level " << level;
    }
    m.specular = 0.5f;
    LobeFilter no_reflection;
    no_reflection.reflective = false;
    EXPECT_EQ(Bsdf(m, white, n, view(1.0f), true, no_reflection).w_diffuse, 1.0f);
    // Grazing views reflect more, so the base gets less.
    m.roughness = 0.5f;
    EXPECT_LT(Bsdf(m, white, n, view(0.2f), true).w_diffuse, Bsdf(m, white, n, view(1.0f), true).w_diffuse - 0.02f);
}

// White furnace: a white metal (F = 1) with Multiscatter GGX reflects everything, at any roughness and view
// (Cycles microfacet_ggx_preserve_energy scales single scattering by 1 / E). With single-scattering GGX it loses
// 1 - E(roughness, mu), a clear loss at roughness 1. 200 000 samples: Monte Carlo error below 0.5 %; tolerance 1.5 %.
TEST(PrincipledV2, MultiscatterWhiteMetalConservesEnergy) {
    Material m = principled_v2();
    m.metallic = 1.0f;
    m.base_color = {1.0f, 1.0f, 1.0f};
    const glm::vec3 n(0, 0, 1), white(1.0f);
    for (float roughness : {0.4f, 0.7f, 1.0f})
        for (float mu : {0.3f, 0.9f}) {
            m.roughness = roughness;
            m.multiscatter = true;
            const glm::vec3 a = albedo(Bsdf(m, white, n, view(mu), true), view(mu), 200000);
            EXPECT_NEAR(a.x, 1.0, 0.015) << "roughness " << roughness << ", mu " << mu;
            m.multiscatter = false;
            const glm::vec3 single = albedo(Bsdf(m, white, n, view(mu), true), view(mu), 200000);
            EXPECT_NEAR(single.x, ggx_E(roughness, mu), 0.015) << "roughness " << roughness << ", mu " << mu;
        }
    m.roughness = 1.0f;
    m.multiscatter = false;
    EXPECT_LT(albedo(Bsdf(m, white, n, view(0.3f), true), view(0.3f), 100000).x, 0.85f);
}

// The table E(roughness, mu) against an independent integration of the height-correlated GGX BRDF
// f cos = D G2 / (4 cos_o) over the hemisphere (midpoint rule in cos(theta) and phi, 1200 x 600 cells), at grid
// nodes of the table (no interpolation). Tolerance 3e-3 (the table's quadrature error is below 1e-3). Roughness 1 is
// extreme: half of the reflected directions leave below the horizon, and E is higher at grazing views.
TEST(PrincipledV2, GgxAlbedoTableMatchesDirectIntegration) {
    for (int ir : {10, 20, 31})
        for (int im : {8, 20, 31}) {
            const double rough = ir / 31.0, mu = im / 31.0, a2 = std::pow(rough, 4.0);
            const glm::dvec3 wo(std::sqrt(1.0 - mu * mu), 0.0, mu);
            auto lambda = [a2](double c) { return 0.5 * (std::sqrt(1.0 + a2 * (1.0 / (c * c) - 1.0)) - 1.0); };
            const int nt = 1200, np = 600;
            double e = 0.0;
            for (int i = 0; i < nt; ++i) {
                const double ci = (i + 0.5) / nt, si = std::sqrt(1.0 - ci * ci);
                for (int j = 0; j < np; ++j) {
                    const double phi = 2.0 * kPiD * (j + 0.5) / np;
                    const glm::dvec3 wi(si * std::cos(phi), si * std::sin(phi), ci);
                    const glm::dvec3 h = glm::normalize(wi + wo);
                    const double d = a2 / (kPiD * std::pow(h.z * h.z * (a2 - 1.0) + 1.0, 2.0));
                    const double g2 = 1.0 / (1.0 + lambda(ci) + lambda(mu));
                    e += d * g2 / (4.0 * mu) * (2.0 * kPiD / (double(nt) * np));
                }
            }
            EXPECT_NEAR(ggx_E(float(rough), float(mu)), e, 3e-3) << "roughness " << rough << ", mu " << mu;
        }
    // At roughness 1 (alpha = 1, D = 1/pi) seen head-on, G2 = 2c / (1 + c) and E = 1 - ln 2 exactly.
    EXPECT_NEAR(ggx_E(1.0f, 1.0f), 1.0 - std::log(2.0), 2e-3);
    // E_avg = integral_0^1 2 mu E(mu) dmu, here from the E table (its linear interpolation limits the tolerance).
    for (float rough : {0.3f, 0.6f, 1.0f}) {
        double avg = 0.0;
        for (int k = 0; k < 400; ++k) {
            const float mu = (k + 0.5f) / 400.0f;
            avg += 2.0 * mu * ggx_E(rough, mu) / 400.0;
        }
        EXPECT_NEAR(ggx_E_avg(rough), avg, 5e-3) << "roughness " << rough;
    }
}

// A Principled v1 material is unaffected by the V2 fields.
TEST(PrincipledV2, VersionOneIgnoresTheNewInputs) {
    Material m;
    m.metallic = 0.3f;
    m.roughness = 0.4f;
    Material tinted = m;
    tinted.specular_tint = {0.2f, 0.3f, 0.4f};
    tinted.multiscatter = true;
    const glm::vec3 n(0, 0, 1), base(0.5f, 0.4f, 0.3f), wo = view(0.6f), wi = glm::normalize(glm::vec3(-0.3f, 0.2f, 0.9f));
    float pdf_a, pdf_b;
    const glm::vec3 fa = Bsdf(m, base, n, wo, true).eval(wo, wi, pdf_a);
    const glm::vec3 fb = Bsdf(tinted, base, n, wo, true).eval(wo, wi, pdf_b);
    EXPECT_EQ(fa, fb);
    EXPECT_EQ(pdf_a, pdf_b);
}
