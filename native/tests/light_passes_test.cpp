// The light passes (film.h, SampleRecord::light; RenderSettings::light_passes): in a scene of every kind of light the
// model has (a diffuse floor, a glossy metal, glass, an emissive box, a point light and an area light the camera
// sees, the world's light, and semi-transparent flat Gaussians in front), the passes recombine to Combined as
// Blender's compositor recombines Cycles' passes,
//     sum over lobes of (Direct + Indirect) Color + Emission = Combined
// (a transparent background: the world seen directly is in none of them), for every Gaussian shading, in both blend
// spaces and both Principled versions; an opaque BAKED Gaussian's Emission is its colour; and with the setting off the
// passes are 0 and every other channel is bit for bit the same as with it on.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>

#include "raysplats/render/renderer.h"
#include "render_test_util.h"

using namespace raysplats;
using namespace raysplats::testing;

namespace {

constexpr int kWidth = 48, kHeight = 36;
constexpr float kDisplayColor[3] = {0.8f, 0.35f, 0.2f};

struct LightScene {
    Scene scene;
    TestMesh floor = make_quad_z(-8.0f, 8.0f, -8.0f, 8.0f, 0.0f, 0);
    TestMesh metal, glass, lamp;
    GaussianCloud cloud;
    Camera camera;

    LightScene(PrincipledVersion version, float opacity) {
        Material diffuse, gold, clear;
        diffuse.base_color = {0.6f, 0.5f, 0.4f};
        gold.base_color = {0.9f, 0.7f, 0.3f};
        gold.metallic = 1.0f;
        gold.roughness = 0.3f;
        clear.base_color = {0.9f, 1.0f, 0.95f};
        clear.transmission = 1.0f;
        clear.roughness = 0.0f;
        for (Material* m : {&diffuse, &gold, &clear}) {
            m->principled_version = version;
            scene.add_material(*m);
        }
        scene.add_material(emissive(2.0f, 1.5f, 0.5f));
        const float metal_lo[3] = {-2.5f, -1.5f, 0.0f}, metal_hi[3] = {-1.0f, 0.0f, 1.0f};
        const float glass_lo[3] = {1.0f, -1.5f, 0.0f}, glass_hi[3] = {2.5f, 0.0f, 1.5f};
        const float lamp_lo[3] = {-0.5f, 1.0f, 0.0f}, lamp_hi[3] = {0.5f, 2.0f, 0.5f};
        metal = make_box(metal_lo, metal_hi, 1);
        glass = make_box(glass_lo, glass_hi, 2);
        lamp = make_box(lamp_lo, lamp_hi, 3);
        for (const TestMesh* m : {&floor, &metal, &glass, &lamp}) scene.add_mesh(m->desc());
        // Flat Gaussians over the metal, the glass and the floor, semi-transparent at their rims.
        const float q[4] = {1, 0, 0, 0}, s[3] = {0.8f, 0.8f, 1e-4f};
        for (float x : {-1.8f, 0.0f, 1.8f}) {
            const float pos[3] = {x, -0.7f, 2.5f};
            add_gaussian(cloud, pos, q, s, opacity, kDisplayColor);
        }
        scene.add_gaussians(cloud);
        Light point;
        point.power = 400.0f;
        point.light_to_world = Matrix4::translation(2.0f, -3.0f, 5.0f);
        scene.add_light(point);
        Light area;
        area.type = LightType::AreaRectangle;
        area.power = 200.0f;
        area.size_x = area.size_y = 1.0f;
        area.light_to_world = Matrix4::look_at({-3.0f, 2.0f, 3.0f}, {0.0f, 0.0f, 0.0f}, {0.0f, 0.0f, 1.0f});
        scene.add_light(area);
        World w;
        w.color = {0.2f, 0.25f, 0.3f};
        scene.set_world(w);
        camera.focal_length_mm = 24.0f;
        camera.camera_to_world = Matrix4::look_at({0.0f, -7.0f, 7.0f}, {0.0f, 0.0f, 0.5f}, {0.0f, 0.0f, 1.0f});
    }
};

RenderSettings light_settings(GaussianShading shading, BlendSpace blend, bool light_passes = true) {
    RenderSettings s;
    s.width = kWidth, s.height = kHeight, s.samples = 4;
    s.max_bounces = 4;
    s.gaussian_shading = shading;
    s.blend_space = blend;
    s.transparent_background = true;
    s.light_passes = light_passes;
    return s;
}

const float* channel(const Film& film, FilmChannel c, std::size_t pixel) { return &film[c][3 * pixel]; }

// The largest |recombined - Combined| over the pixels and channels, relative to max(1, |Combined|); accumulates
// how much each kind of pass holds.
double recombination_error(const Film& film, double sums[4]) {
    const FilmChannel lobes[3][3] = {
        {FilmChannel::DiffuseDirect, FilmChannel::DiffuseIndirect, FilmChannel::DiffuseColor},
        {FilmChannel::GlossyDirect, FilmChannel::GlossyIndirect, FilmChannel::GlossyColor},
        {FilmChannel::TransmissionDirect, FilmChannel::TransmissionIndirect, FilmChannel::TransmissionColor}};
    double worst = 0.0;
    for (std::size_t p = 0; p < film.pixel_count(); ++p)
        for (int k = 0; k < 3; ++k) {
            double sum = channel(film, FilmChannel::Emission, p)[k];
            sums[0] += sum;
            for (int lobe = 0; lobe < 3; ++lobe) {
                const double light = double(channel(film, lobes[lobe][0], p)[k]) + channel(film, lobes[lobe][1], p)[k];
                sum += light * channel(film, lobes[lobe][2], p)[k];
                sums[1 + lobe] += light * channel(film, lobes[lobe][2], p)[k];
            }
            const double combined = film.rgba()[4 * p + std::size_t(k)];
            worst = std::max(worst, std::abs(sum - combined) / std::max(1.0, std::abs(combined)));
        }
    return worst;
}

}  // namespace

TEST(LightPasses, RecombineToCombinedInEveryShadingAndBlendSpace) {
    for (PrincipledVersion version : {PrincipledVersion::V1, PrincipledVersion::V2})
        for (GaussianShading shading : {GaussianShading::Baked, GaussianShading::Lit, GaussianShading::BakedShadowed})
            for (BlendSpace blend : {BlendSpace::Display, BlendSpace::Linear}) {
                SCOPED_TRACE(::testing::Message() << "Principled v" << (version == PrincipledVersion::V1 ? 1 : 2)
                                                  << ", shading " << int(shading) << ", blend " << int(blend));
                LightScene s(version, 0.7f);
                const Film film = render(s.scene, s.camera, light_settings(shading, blend));
                double sums[4] = {0, 0, 0, 0};
                // Measured: at most 2.6e-7 (float rounding of the division by Color and the display blend's parts).
                EXPECT_LT(recombination_error(film, sums), 1e-5);
                // Every kind of light is there: emission, and each lobe's.
                for (double v : sums) EXPECT_GT(v, 1.0);
            }
}

TEST(LightPasses, EmissionOfAnOpaqueBakedGaussianIsItsColour) {
    // The middle Gaussian, opaque (its alpha clamps at 0.99 at the centre, a second layer under it takes the rest),
    // seen from straight above its centre by an orthographic camera: Emission is its linear colour; Lit, it has none.
    for (GaussianShading shading : {GaussianShading::Baked, GaussianShading::Lit})
        for (BlendSpace blend : {BlendSpace::Display, BlendSpace::Linear}) {
            LightScene s(PrincipledVersion::V1, 1.0f);
            const float q[4] = {1, 0, 0, 0}, sc[3] = {0.8f, 0.8f, 1e-4f}, pos[3] = {0.0f, -0.7f, 2.49f};
            GaussianCloud under;
            add_gaussian(under, pos, q, sc, 1.0f, kDisplayColor);
            s.scene.add_gaussians(under);
            s.camera.type = CameraType::Orthographic;
            s.camera.ortho_scale = 0.2f;
            s.camera.camera_to_world = Matrix4::translation(0.0f, -0.7f, 9.0f);
            RenderSettings st = light_settings(shading, blend);
            st.width = st.height = 4;
            const Film film = render(s.scene, s.camera, st);
            for (std::size_t p = 0; p < film.pixel_count(); ++p)
                for (int k = 0; k < 3; ++k) {
                    const double expected =
                        shading == GaussianShading::Baked ? srgb_to_linear_ref(kDisplayColor[k]) : 0.0;
                    EXPECT_NEAR(channel(film, FilmChannel::Emission, p)[k], expected, 2e-3) << p << " " << k;
                }
        }
}

TEST(LightPasses, OffByDefaultAndChangesNothingElse) {
    EXPECT_FALSE(RenderSettings{}.light_passes);
    for (GaussianShading shading : {GaussianShading::Baked, GaussianShading::Lit})
        for (BlendSpace blend : {BlendSpace::Display, BlendSpace::Linear}) {
            LightScene s(PrincipledVersion::V2, 0.7f);
            const Film off = render(s.scene, s.camera, light_settings(shading, blend, false));
            const Film on = render(s.scene, s.camera, light_settings(shading, blend, true));
            double on_sum = 0.0;
            for (std::size_t k = 0; k < kFilmChannelCount; ++k) {
                const auto c = FilmChannel(k);
                const FloatBuffer &a = off[c], &b = on[c];
                if (k >= std::size_t(FilmChannel::Emission) &&
                    k <= std::size_t(FilmChannel::TransmissionColor)) {
                    // Without the setting the film does not hold them at all (computed_film_channels).
                    ASSERT_TRUE(a.empty()) << film_channels()[k].key;
                    ASSERT_EQ(b.size(), 3 * on.pixel_count()) << film_channels()[k].key;
                    for (float v : b) on_sum += v;
                    continue;
                }
                ASSERT_EQ(a.size(), b.size());
                for (std::size_t i = 0; i < a.size(); ++i)
                    ASSERT_EQ(std::memcmp(&a[i], &b[i], sizeof(float)), 0) << film_channels()[k].key << " " << i;
            }
            EXPECT_GT(on_sum, 1.0);
        }
}
