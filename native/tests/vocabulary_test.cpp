// The core's vocabularies: render settings, camera parameters and splat formats by name, as every front end
// (the Python bindings, the JSON tool, the add-on) spells them.
#include <gtest/gtest.h>

#include <functional>
#include <set>
#include <string>

#include "raysplats/errors.h"
#include "raysplats/render/camera_parameters.h"
#include "raysplats/render/render_settings.h"
#include "raysplats/splat_io.h"

using namespace raysplats;

namespace {

std::string message_of(const std::function<void()>& f) {
    try {
        f();
    } catch (const InvalidArgument& e) {
        return e.what();
    }
    return "(no error)";
}

}  // namespace

TEST(RenderSettingNames, EverySettingIsSetByItsName) {
    const auto& table = render_setting_parameters();
    RenderSettings s;
    table.set(s, "width", std::int64_t(1280));
    table.set(s, "samples", std::int64_t(1000));
    table.set(s, "max_bounces", std::int64_t(7));
    table.set(s, "seed", std::int64_t(4000000000));  // beyond int32: the seed is unsigned
    table.set(s, "compositing", std::string("STOCHASTIC"));
    table.set(s, "gaussian_mode", std::string("VOLUMETRIC"));
    table.set(s, "transmittance_threshold", 0.25);
    table.set(s, "transmittance_threshold", std::int64_t(0));  // an integer is a number too
    table.set(s, "transparent_background", true);
    table.set(s, "caustics_refractive", false);
    table.set(s, "pixel_filter", std::string("BLACKMAN_HARRIS"));
    table.set(s, "filter_width", 1.5);
    table.set(s, "adaptive_sampling", true);
    table.set(s, "adaptive_threshold", 0.005);
    table.set(s, "adaptive_min_samples", std::int64_t(24));
    table.set(s, "region_x", std::int64_t(10));
    table.set(s, "region_y", std::int64_t(20));
    table.set(s, "region_width", std::int64_t(30));
    table.set(s, "region_height", std::int64_t(40));
    table.set(s, "gaussian_shading", std::string("BAKED_SHADOWED"));
    table.set(s, "blend_space", std::string("LINEAR"));
    table.set(s, "camera_ray_splatting", true);
    table.set(s, "denoising_data", true);
    table.set(s, "light_passes", true);
    table.set(s, "mist_pass", true);
    table.set(s, "cryptomatte_object", true);
    table.set(s, "cryptomatte_material", true);
    table.set(s, "cryptomatte_asset", true);
    table.set(s, "cryptomatte_levels", std::int64_t(4));
    table.set(s, "shadow_catcher_pass", true);
    EXPECT_EQ(s.width, 1280);
    EXPECT_EQ(s.samples, 1000);
    EXPECT_EQ(s.max_bounces, 7);
    EXPECT_EQ(s.seed, 4000000000u);
    EXPECT_EQ(s.compositing, Compositing::Stochastic);
    EXPECT_EQ(s.gaussian_mode, GaussianMode::Volumetric);
    EXPECT_EQ(s.transmittance_threshold, 0.0f);
    EXPECT_TRUE(s.transparent_background);
    EXPECT_FALSE(s.caustics_refractive);
    EXPECT_EQ(s.pixel_filter, PixelFilter::BlackmanHarris);
    EXPECT_EQ(s.filter_width, 1.5f);
    EXPECT_TRUE(s.adaptive_sampling);
    EXPECT_EQ(s.adaptive_threshold, 0.005f);
    EXPECT_EQ(s.adaptive_min_samples, 24);
    EXPECT_EQ(s.region_x + s.region_y + s.region_width + s.region_height, 100);
    EXPECT_EQ(s.gaussian_shading, GaussianShading::BakedShadowed);
    EXPECT_EQ(s.blend_space, BlendSpace::Linear);
    EXPECT_TRUE(s.camera_ray_splatting);
    EXPECT_TRUE(s.denoising_data);
    EXPECT_TRUE(s.light_passes);
    EXPECT_TRUE(s.mist_pass);
    EXPECT_TRUE(s.cryptomatte_object && s.cryptomatte_material && s.cryptomatte_asset);
    EXPECT_EQ(s.cryptomatte_levels, 4);
    EXPECT_TRUE(s.shadow_catcher_pass);

    std::set<std::string> names;
    for (const auto& p : table.parameters()) EXPECT_TRUE(names.insert(p.name).second) << p.name << " twice";
    EXPECT_EQ(names.size(), 36u);  // every field of RenderSettings
}

TEST(RenderSettingNames, MisspeltNamesAndWrongTypesAreErrorsThatSayWhat) {
    const auto& table = render_setting_parameters();
    RenderSettings s;
    EXPECT_EQ(message_of([&] { table.set(s, "sample", std::int64_t(1000)); }).rfind(
                  "unknown render setting 'sample' (known: width, height, samples, max_bounces, ", 0),
              0u);
    EXPECT_EQ(message_of([&] { table.set(s, "samples", std::string("many")); }),
              "render setting 'samples' must be an integer (got 'many')");
    EXPECT_EQ(message_of([&] { table.set(s, "samples", 1.5); }), "render setting 'samples' must be an integer (got 1.5)");
    EXPECT_EQ(message_of([&] { table.set(s, "jitter", std::int64_t(1)); }),
              "render setting 'jitter' must be true or false (got 1)");
    EXPECT_EQ(message_of([&] { table.set(s, "compositing", std::string("sorted")); }),
              "unknown compositing 'sorted' (known: SORTED, STOCHASTIC)");
    EXPECT_EQ(message_of([&] { table.set(s, "seed", std::int64_t(-1)); }),
              "render setting 'seed' must be in 0 .. 4294967295 (got -1)");
    EXPECT_EQ(s.samples, RenderSettings{}.samples);  // nothing was set by the failed calls
}

TEST(CameraNames, ModelsAndParametersByName) {
    const auto& table = camera_parameters();
    Camera c;
    table.set(c, "type", std::string("FISHEYE_EQUISOLID"));
    table.set(c, "fisheye_fov", 3.0);
    table.set(c, "lens", std::int64_t(35));
    table.set(c, "sensor_fit", std::string("VERTICAL"));
    Matrix4 m = Matrix4::translation(1, 2, 3);
    table.set(c, "matrix", m);
    EXPECT_EQ(c.type, CameraType::FisheyeEquisolid);
    EXPECT_FLOAT_EQ(c.fisheye_fov, 3.0f);  // radians, taken as given
    EXPECT_FLOAT_EQ(c.focal_length_mm, 35.0f);
    EXPECT_EQ(c.sensor_fit, SensorFit::Vertical);
    EXPECT_EQ(c.camera_to_world.m, m.m);
    // Depth of field by Blender's Camera.dof names.
    table.set(c, "use_dof", true);
    table.set(c, "focus_distance", 2.5);
    table.set(c, "aperture_fstop", 1.4);
    table.set(c, "aperture_blades", std::int64_t(6));
    table.set(c, "aperture_rotation", 0.5);
    table.set(c, "aperture_ratio", 2.0);
    EXPECT_TRUE(c.use_dof);
    EXPECT_FLOAT_EQ(c.focus_distance, 2.5f);
    EXPECT_FLOAT_EQ(c.aperture_fstop, 1.4f);
    EXPECT_EQ(c.aperture_blades, 6);
    EXPECT_FLOAT_EQ(c.aperture_rotation, 0.5f);
    EXPECT_FLOAT_EQ(c.aperture_ratio, 2.0f);
    EXPECT_EQ(message_of([&] { table.set(c, "aperture_blades", 6.5); }),
              "camera parameter 'aperture_blades' must be an integer (got 6.5)");

    // Every model has one name, and the name table gives it back.
    for (const auto& model : camera_model_names().values)
        EXPECT_EQ(camera_model_names().value_of(model.name), model.value);
    EXPECT_EQ(camera_model_names().values.size(), 5u);
    EXPECT_EQ(message_of([&] { table.set(c, "type", std::string("perspective")); }),
              "unknown camera model 'perspective' (known: PERSP, ORTHO, EQUIRECTANGULAR, FISHEYE_EQUIDISTANT, "
              "FISHEYE_EQUISOLID)");
    EXPECT_EQ(message_of([&] { table.set(c, "fov", 3.0); }).rfind("unknown camera parameter 'fov' (known: type, ", 0), 0u);
    EXPECT_EQ(message_of([&] { table.set(c, "matrix", 1.0); }), "camera parameter 'matrix' must be a 4x4 matrix (got 1)");
}

TEST(SplatFormatTable, ExtensionsLeadToTheirFormat) {
    std::set<std::string> extensions;
    for (const SplatFormatInfo& f : splat_formats()) {
        ASSERT_FALSE(f.extensions.empty()) << f.name;
        for (const char* e : f.extensions) {
            EXPECT_TRUE(extensions.insert(e).second) << e << " belongs to two formats";
            EXPECT_EQ(splat_format_from_extension(std::string("scene") + e), f.format) << e;
        }
        EXPECT_STREQ(splat_format_name(f.format), f.name);
        // Every reader converts to the core's RDF (docs/design.md §4): the up axis is the scene's, not the format's.
        EXPECT_EQ(std::string(f.up_axis), "-Y") << f.name;
    }
    EXPECT_EQ(extensions, (std::set<std::string>{".ply", ".splat", ".spz", ".glb", ".gltf", ".compressed.ply", ".sog",
                                                 "meta.json"}));
    EXPECT_EQ(splat_format_from_extension("A.SPZ"), SplatFormat::Spz);
    try {
        splat_format_from_extension("scene.obj");
        FAIL();
    } catch (const FileFormatError& e) {
        EXPECT_NE(std::string(e.what()).find("'.obj' is not one of .ply, .splat, .spz, .glb, .gltf, .compressed.ply, .sog, meta.json"), std::string::npos) << e.what();
    }
}
