// Base-colour image textures of Material: bilinear lookup with Blender's texel centres and repeat wrapping, sRGB
// decoding after filtering (as Cycles does for 8-bit sRGB images), validation, and a textured quad rendered.
#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "raysplats/errors.h"
#include "raysplats/render/renderer.h"
#include "render/bsdf.h"
#include "render_test_util.h"

using namespace raysplats;
using namespace raysplats::testing;

namespace {

// A W x H texture whose texel (i, j) (j = 0 the bottom row) has channels f(i, j, c).
template <typename F>
std::vector<float> make_pixels(int w, int h, int channels, F f) {
    std::vector<float> p(std::size_t(w) * h * channels);
    for (int j = 0; j < h; ++j)
        for (int i = 0; i < w; ++i)
            for (int c = 0; c < channels; ++c) p[(std::size_t(j) * w + i) * channels + c] = f(i, j, c);
    return p;
}

Material textured(const std::vector<float>& pixels, int w, int h, int channels, bool srgb) {
    Material m;
    m.base_color = {0.3f, 0.3f, 0.3f};  // replaced by the texture
    m.base_color_texture.pixels = pixels.data();
    m.base_color_texture.width = w;
    m.base_color_texture.height = h;
    m.base_color_texture.channels = channels;
    m.base_color_texture.srgb = srgb;
    return m;
}

float texel_value(int i, int j, int c) { return 0.1f * float(1 + i + 3 * j) + 0.01f * float(c); }

}  // namespace

// At texel centres ((i + 0.5) / W, (j + 0.5) / H) the lookup returns the texel exactly; half-way between two
// centres, their mean; a quarter of the way, the 3:1 blend; u + 1 and u - 1 give the same value as u (repeat).
TEST(Material, TextureLookupIsBilinearWithTexelCentresAndRepeat) {
    const int w = 3, h = 2;
    for (int channels : {1, 3, 4}) {
        const std::vector<float> pixels = make_pixels(w, h, channels, texel_value);
        const Material m = textured(pixels, w, h, channels, false);
        auto expect = [&](glm::vec2 uv, auto value, const char* what) {
            const glm::vec3 c = material_base_color(m, uv);
            for (int k = 0; k < 3; ++k)
                EXPECT_NEAR(c[k], value(channels == 1 ? 0 : k), 1e-6) << what << ", " << channels << " channels";
        };
        for (int j = 0; j < h; ++j)
            for (int i = 0; i < w; ++i) {
                const glm::vec2 centre((i + 0.5f) / w, (j + 0.5f) / h);
                auto exact = [&](int c) { return texel_value(i, j, c); };
                expect(centre, exact, "texel centre");
                expect(centre + glm::vec2(1.0f, -1.0f), exact, "texel centre, repeated");
                expect(centre + glm::vec2(-2.0f, 3.0f), exact, "texel centre, repeated twice");
            }
        expect(glm::vec2(1.0f / w, 0.5f / h), [](int c) { return 0.5f * (texel_value(0, 0, c) + texel_value(1, 0, c)); },
               "between two texels");
        expect(glm::vec2(0.5f / w, 0.75f / h), [](int c) { return 0.75f * texel_value(0, 0, c) + 0.25f * texel_value(0, 1, c); },
               "a quarter of the way up");
        // u = 0 lies half-way between the last column and the first (wrapping).
        expect(glm::vec2(0.0f, 0.5f / h), [](int c) { return 0.5f * (texel_value(0, 0, c) + texel_value(w - 1, 0, c)); },
               "across the wrap");
    }
}

// An sRGB texture: 0.5 at a texel centre decodes to ((0.5 + 0.055) / 1.055)^2.4 = 0.21404; between texels 0.2 and
// 0.8 the encoded values are blended first (Cycles' order), giving decode(0.5), not the mean of the decodes.
TEST(Material, SrgbTextureIsDecodedAfterFiltering) {
    const std::vector<float> pixels = {0.2f, 0.2f, 0.2f, 1.0f, 0.8f, 0.5f, 0.04f, 1.0f};  // 2 x 1 RGBA
    const Material m = textured(pixels, 2, 1, 4, true);
    const glm::vec3 left = material_base_color(m, glm::vec2(0.25f, 0.5f));
    EXPECT_NEAR(left.x, srgb_to_linear_ref(0.2), 1e-6);
    const glm::vec3 right = material_base_color(m, glm::vec2(0.75f, 0.5f));
    EXPECT_NEAR(right.x, srgb_to_linear_ref(0.8), 1e-6);
    EXPECT_NEAR(right.y, 0.21404114, 1e-6);
    EXPECT_NEAR(right.z, 0.04 / 12.92, 1e-7);  // the linear segment of the sRGB curve
    const glm::vec3 middle = material_base_color(m, glm::vec2(0.5f, 0.5f));
    EXPECT_NEAR(middle.x, srgb_to_linear_ref(0.5), 1e-6);
}

TEST(Material, BadTexturesAreRejectedWithWhatIsWrong) {
    auto message = [](const Material& m) {
        try {
            m.validate("material 7");
        } catch (const InvalidArgument& e) {
            return std::string(e.what());
        }
        return std::string("accepted");
    };
    std::vector<float> pixels = make_pixels(2, 2, 4, texel_value);
    EXPECT_EQ(message(textured(pixels, 2, 2, 4, false)), "accepted");
    EXPECT_NE(message(textured(pixels, 2, 2, 2, false)).find("channels"), std::string::npos);
    EXPECT_NE(message(textured(pixels, 0, 2, 4, false)).find("size"), std::string::npos);
    pixels[4 * 3 + 1] = std::nanf("");
    const std::string nan = message(textured(pixels, 2, 2, 4, false));
    EXPECT_NE(nan.find("material 7"), std::string::npos) << nan;
    EXPECT_NE(nan.find("texel 3"), std::string::npos) << nan;
}

// A Lambertian quad with a 4 x 4 texture under a uniform white world, seen from above by an orthographic camera
// whose 4 x 4 pixel centres fall on the texel centres. With no bounces each sample is the cosine-sampled world
// seen from the surface, weighted f cos / pdf = albedo exactly, so every pixel is its texel's colour (1e-5).
TEST(Material, TexturedQuadRendersTexelColoursAtTheUVs) {
    const int n = 4;
    for (bool srgb : {false, true}) {
        Scene scene;
        World world;
        world.color = {1.0f, 1.0f, 1.0f};
        world.strength = 1.0f;
        scene.set_world(world);
        const std::vector<float> pixels = make_pixels(n, n, 3, [](int i, int j, int c) {
            return 0.05f + 0.9f * float((i * 7 + j * 5 + c * 3) % 16) / 15.0f;
        });
        Material m = textured(pixels, n, n, 3, srgb);
        m.specular = 0.0f;
        m.roughness = 1.0f;
        scene.add_material(m);
        TestMesh quad = make_quad_z(-1, 1, -1, 1, 0, 0);
        const std::vector<float> uvs = {0, 0, 1, 0, 1, 1, 0, 1};  // u = (x + 1) / 2, v = (y + 1) / 2
        MeshDesc d = quad.desc();
        d.uvs = uvs.data();
        scene.add_mesh(d);
        Camera camera;
        camera.type = CameraType::Orthographic;
        camera.ortho_scale = 2.0f;
        camera.camera_to_world = Matrix4::translation(0, 0, 5);
        RenderSettings settings;
        settings.width = settings.height = n;
        settings.samples = 4;
        settings.jitter = false;
        settings.max_bounces = 0;
        const Film film = render(scene, camera, settings);
        for (int row = 0; row < n; ++row)
            for (int i = 0; i < n; ++i) {
                const int j = n - 1 - row;  // film rows run top to bottom, texture rows bottom to top
                for (int c = 0; c < 3; ++c) {
                    const double texel = pixels[(std::size_t(j) * n + i) * 3 + c];
                    const double expected = srgb ? srgb_to_linear_ref(texel) : texel;
                    ASSERT_NEAR(film.rgba()[4 * (std::size_t(row) * n + i) + c], expected, 1e-5)
                        << "pixel " << i << ", " << row << (srgb ? " (sRGB)" : " (linear)");
                }
            }
    }
}
