// Bindings of the renderer (raysplats._native.RenderScene, RenderJob). Thin: arrays in are kept alive by the
// scene object (the core shares them without copies); the render job is the core's (render/render_job.h),
// which runs on its own thread so that the Blender engine can poll progress and Esc from the main thread.
// Values are converted by conversions.h.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <memory>
#include <optional>
#include <string>

#include "conversions.h"
#include "raysplats/errors.h"
#include "raysplats/render/camera_parameters.h"
#include "raysplats/render/render_job.h"

namespace py = pybind11;
using namespace pybind11::literals;
using namespace raysplats::python;

namespace {

// Names of the light types and material models as the add-on passes them (Blender's spellings). Only the
// bindings take these by name (the JSON tool has lights of its own spelling), so the tables live here.
const raysplats::NameTable<raysplats::LightType>& light_type_names() {
    static const raysplats::NameTable<raysplats::LightType> names{
        "light type",
        {{"POINT", raysplats::LightType::Point, "point light"},
         {"SUN", raysplats::LightType::Sun, "directional light"},
         {"SPOT", raysplats::LightType::Spot, "spot light"},
         {"AREA_RECTANGLE", raysplats::LightType::AreaRectangle, "rectangular area light"},
         {"AREA_DISK", raysplats::LightType::AreaDisk, "disk area light"}}};
    return names;
}
const raysplats::NameTable<raysplats::DiffuseModel>& diffuse_model_names() {
    static const raysplats::NameTable<raysplats::DiffuseModel> names{
        "diffuse model",
        {{"LAMBERT", raysplats::DiffuseModel::Lambert, "Lambertian"},
         {"PRINCIPLED", raysplats::DiffuseModel::Principled, "Principled BSDF's diffuse"}}};
    return names;
}
const raysplats::NameTable<raysplats::PrincipledVersion>& principled_version_names() {
    static const raysplats::NameTable<raysplats::PrincipledVersion> names{
        "Principled version",
        {{"V1", raysplats::PrincipledVersion::V1, "Blender 3.x Principled BSDF"},
         {"V2", raysplats::PrincipledVersion::V2, "Blender 4.x Principled BSDF"}}};
    return names;
}

// A scene plus the Python objects whose memory it shares. Every change goes through shared.change(), which
// refuses while a RenderJob renders the scene.
struct RenderScene {
    raysplats::SharedScene shared;
    std::vector<py::object> keep_alive;                // textures
    std::vector<std::vector<py::object>> mesh_arrays;  // per mesh index
    std::vector<std::unique_ptr<raysplats::GaussianCloud>> clouds;  // per cloud index (stable addresses)

    std::uint32_t add_material(const py::object& base_color, float metallic, float roughness, float specular,
                               float transmission, float ior, const py::object& emission_color,
                               float emission_strength, float alpha, const std::string& diffuse_model,
                               const std::optional<FloatArray>& base_color_texture, bool texture_srgb,
                               const std::string& principled_version, const py::object& specular_tint,
                               bool multiscatter, std::uint32_t pass_index) {
        raysplats::Material m;
        m.base_color = rgb_from(base_color, "base_color");
        m.metallic = metallic, m.roughness = roughness, m.specular = specular;
        m.transmission = transmission, m.ior = ior;
        m.emission_color = rgb_from(emission_color, "emission_color");
        m.emission_strength = emission_strength, m.alpha = alpha;
        m.diffuse_model = diffuse_model_names().value_of(diffuse_model);
        m.principled_version = principled_version_names().value_of(principled_version);
        m.specular_tint = rgb_from(specular_tint, "specular_tint");
        m.multiscatter = multiscatter;
        m.pass_index = pass_index;
        if (base_color_texture) {
            // H x W x C (or H x W for one channel), row 0 = bottom as Blender's Image.pixels.
            const FloatArray& t = *base_color_texture;
            const int channels = t.ndim() == 2 ? 1 : t.ndim() == 3 ? int(t.shape(2)) : 0;
            if (channels != 1 && channels != 3 && channels != 4)
                throw raysplats::InvalidArgument("array 'base_color_texture' has shape " + shape_text(t) +
                                                 " but (H,W), (H,W,3) or (H,W,4) was expected");
            m.base_color_texture.pixels = t.data();
            m.base_color_texture.height = int(t.shape(0));
            m.base_color_texture.width = int(t.shape(1));
            m.base_color_texture.channels = channels;
            m.base_color_texture.srgb = texture_srgb;
        }
        const std::uint32_t index = shared.change()->add_material(m);
        if (base_color_texture) keep_alive.push_back(*base_color_texture);
        return index;
    }

    // A mesh description over the caller's arrays, and the arrays it points into.
    static raysplats::MeshDesc mesh_desc(const FloatArray& vertices, const UintArray& triangles, const py::object& matrix,
                                         std::uint32_t material, const std::optional<UintArray>& face_materials,
                                         const std::optional<FloatArray>& normals, const std::optional<FloatArray>& uvs,
                                         std::uint32_t pass_index, bool holdout, bool shadow_catcher,
                                         std::vector<py::object>& arrays) {
        const py::ssize_t vertex_count = require_shape(vertices, "vertices", {kAnySize, 3});
        const py::ssize_t triangle_count = require_shape(triangles, "triangles", {kAnySize, 3});
        raysplats::MeshDesc d;
        d.vertices = vertices.data();
        d.vertex_count = std::size_t(vertex_count);
        d.indices = triangles.data();
        d.triangle_count = std::size_t(triangle_count);
        d.material = material;
        d.pass_index = pass_index;
        d.holdout = holdout;
        d.shadow_catcher = shadow_catcher;
        d.object_to_world = matrix_from(matrix, "matrix");
        arrays = {vertices, triangles};
        if (face_materials) {
            require_shape(*face_materials, "face_materials", {triangle_count});
            d.face_materials = face_materials->data();
            arrays.push_back(*face_materials);
        }
        if (normals) {
            require_shape(*normals, "normals", {vertex_count, 3});
            d.normals = normals->data();
            arrays.push_back(*normals);
        }
        if (uvs) {
            require_shape(*uvs, "uvs", {vertex_count, 2});
            d.uvs = uvs->data();
            arrays.push_back(*uvs);
        }
        return d;
    }

    std::uint32_t add_mesh(const FloatArray& vertices, const UintArray& triangles, const py::object& matrix,
                           std::uint32_t material, const std::optional<UintArray>& face_materials,
                           const std::optional<FloatArray>& normals, const std::optional<FloatArray>& uvs,
                           std::uint32_t pass_index, bool holdout, bool shadow_catcher) {
        std::vector<py::object> arrays;
        const raysplats::MeshDesc d = mesh_desc(vertices, triangles, matrix, material, face_materials, normals, uvs,
                                                pass_index, holdout, shadow_catcher, arrays);
        const std::uint32_t index = shared.change()->add_mesh(d);
        mesh_arrays.push_back(std::move(arrays));
        return index;
    }

    void update_mesh(std::uint32_t index, const FloatArray& vertices, const UintArray& triangles,
                     const py::object& matrix, std::uint32_t material, const std::optional<UintArray>& face_materials,
                     const std::optional<FloatArray>& normals, const std::optional<FloatArray>& uvs,
                     std::uint32_t pass_index, bool holdout, bool shadow_catcher) {
        std::vector<py::object> arrays;
        const raysplats::MeshDesc d = mesh_desc(vertices, triangles, matrix, material, face_materials, normals, uvs,
                                                pass_index, holdout, shadow_catcher, arrays);
        shared.change()->update_mesh(index, d);
        mesh_arrays[index] = std::move(arrays);  // the old arrays are released only now
    }

    std::uint32_t add_gaussians(const FloatArray& positions, const FloatArray& rotations, const FloatArray& scales,
                                const FloatArray& opacities, const FloatArray& sh, const py::object& matrix) {
        auto cloud = std::make_unique<raysplats::GaussianCloud>(cloud_from_arrays(positions, rotations, scales, opacities, sh));
        const std::uint32_t index = shared.change()->add_gaussians(*cloud, matrix_from(matrix, "matrix"));
        clouds.push_back(std::move(cloud));
        return index;
    }

    void update_gaussians(std::uint32_t index, const FloatArray& positions, const FloatArray& rotations,
                          const FloatArray& scales, const FloatArray& opacities, const FloatArray& sh,
                          const py::object& matrix) {
        auto cloud = std::make_unique<raysplats::GaussianCloud>(cloud_from_arrays(positions, rotations, scales, opacities, sh));
        shared.change()->update_gaussians(index, *cloud, matrix_from(matrix, "matrix"));
        clouds[index] = std::move(cloud);
    }

    // Replaces some Gaussians of cloud `index` (the viewport's edit of a few splats): row j of the arrays becomes
    // Gaussian rows[j]. The rows are validated before the cloud is touched, so a bad edit changes nothing.
    void update_gaussian_rows(std::uint32_t index, const UintArray& rows, const FloatArray& positions,
                              const FloatArray& rotations, const FloatArray& scales, const FloatArray& opacities,
                              const FloatArray& sh) {
        auto change = shared.change();
        if (index >= clouds.size()) throw raysplats::InvalidArgument("Gaussian cloud " + std::to_string(index) + " does not exist");
        const raysplats::GaussianCloud values = cloud_from_arrays(positions, rotations, scales, opacities, sh);
        require_shape(rows, "rows", {py::ssize_t(values.size())});
        clouds[index]->assign_rows(values, rows.data(), "Gaussian cloud " + std::to_string(index));
        change->gaussians_changed(index, rows.data(), values.size());
    }

    // Moves a Gaussian cloud without new data (the viewport's object transform).
    void set_gaussians_matrix(std::uint32_t index, const py::object& matrix) {
        shared.change()->set_gaussians_transform(index, matrix_from(matrix, "matrix"));
    }

    void set_mesh_motion(std::uint32_t index, const py::object& matrices) {
        shared.change()->set_mesh_motion(index, matrices_from(matrices, "matrices"));
    }

    // `vertices`: (steps, vertex count, 3), or None for none.
    void set_mesh_deformation(std::uint32_t index, const std::optional<FloatArray>& vertices) {
        if (!vertices) return shared.change()->set_mesh_deformation(index, nullptr, 0, 0);
        const py::ssize_t steps = require_shape(*vertices, "vertices", {kAnySize, kAnySize, 3});
        shared.change()->set_mesh_deformation(index, vertices->data(), std::size_t(steps),
                                              std::size_t(vertices->shape(1)));
    }

    // `positions`, `rotations`, `scales`: (steps, Gaussians, 3 / 4 / 3), or None for none.
    void set_gaussians_deformation(std::uint32_t index, const std::optional<FloatArray>& positions,
                                   const std::optional<FloatArray>& rotations, const std::optional<FloatArray>& scales) {
        if (!positions && !rotations && !scales)
            return shared.change()->set_gaussians_deformation(index, 0, nullptr, nullptr, nullptr, 0);
        if (!positions || !rotations || !scales)
            throw raysplats::InvalidArgument("positions, rotations and scales are given together");
        const py::ssize_t steps = require_shape(*positions, "positions", {kAnySize, kAnySize, 3});
        const py::ssize_t n = positions->shape(1);
        require_shape(*rotations, "rotations", {steps, n, 4});
        require_shape(*scales, "scales", {steps, n, 3});
        shared.change()->set_gaussians_deformation(index, std::size_t(steps), positions->data(), rotations->data(),
                                                   scales->data(), std::size_t(n));
    }

    void set_gaussians_motion(std::uint32_t index, const py::object& matrices) {
        shared.change()->set_gaussians_motion(index, matrices_from(matrices, "matrices"));
    }

    void set_mesh_frame_motion(std::uint32_t index, const py::object& previous, const py::object& next) {
        shared.change()->set_mesh_frame_motion(index, matrix_from(previous, "previous"), matrix_from(next, "next"));
    }

    // `previous`, `next`: (vertex count, 3) each, or None for none.
    void set_mesh_frame_deformation(std::uint32_t index, const std::optional<FloatArray>& previous,
                                    const std::optional<FloatArray>& next) {
        if (!previous || !next) return shared.change()->set_mesh_frame_deformation(index, nullptr, nullptr, 0);
        const py::ssize_t n = require_shape(*previous, "previous", {kAnySize, 3});
        require_shape(*next, "next", {n, 3});
        shared.change()->set_mesh_frame_deformation(index, previous->data(), next->data(), std::size_t(n));
    }

    void set_gaussians_frame_motion(std::uint32_t index, const py::object& previous, const py::object& next) {
        shared.change()->set_gaussians_frame_motion(index, matrix_from(previous, "previous"),
                                                     matrix_from(next, "next"));
    }

    // `shading`: a name of gaussian_shading_names(), or None to follow the render setting gaussian_shading.
    void set_gaussian_shading(std::uint32_t index, const std::optional<std::string>& shading) {
        std::optional<raysplats::GaussianShading> value;
        if (shading) value = raysplats::gaussian_shading_names().value_of(*shading);
        shared.change()->set_gaussian_shading(index, value);
    }

    void set_gaussian_pass_indices(std::uint32_t index, std::uint32_t object_pass_index,
                                   std::uint32_t material_pass_index) {
        shared.change()->set_gaussian_pass_indices(index, object_pass_index, material_pass_index);
    }

    void set_gaussian_cryptomatte_names(std::uint32_t index, const std::string& object, const std::string& material,
                                        const std::string& asset) {
        shared.change()->set_gaussian_cryptomatte_names(index, object, material, asset);
    }
    void set_mesh_cryptomatte_names(std::uint32_t index, const std::string& object, const std::string& asset) {
        shared.change()->set_mesh_cryptomatte_names(index, object, asset);
    }
    void set_material_cryptomatte_name(std::uint32_t index, const std::string& material) {
        shared.change()->set_material_cryptomatte_name(index, material);
    }
    void set_gaussian_holdout(std::uint32_t index, bool holdout) {
        shared.change()->set_gaussian_holdout(index, holdout);
    }

    std::uint32_t add_light(const std::string& type, const py::object& color, float power, const py::object& matrix,
                            float spot_size, float spot_blend, float size_x, float size_y, float sun_angle) {
        raysplats::Light l;
        l.type = light_type_names().value_of(type);
        l.color = rgb_from(color, "color");
        l.power = power, l.spot_size = spot_size, l.spot_blend = spot_blend;
        l.size_x = size_x, l.size_y = size_y, l.sun_angle = sun_angle;
        l.light_to_world = matrix_from(matrix, "matrix");
        return shared.change()->add_light(l);
    }

    void set_world(const py::object& color, float strength, float mist_start, float mist_depth, float mist_falloff) {
        raysplats::World w;
        w.color = rgb_from(color, "color");
        w.strength = strength;
        w.mist_start = mist_start, w.mist_depth = mist_depth, w.mist_falloff = mist_falloff;
        shared.change()->set_world(w);
    }

    void set_interactive(bool interactive, std::uint32_t chunk_size) {
        shared.change()->set_interactive(interactive, chunk_size);
    }

    void set_keep_frame_buffers(bool keep) { shared.change()->set_keep_frame_buffers(keep); }

    double build(const std::string& mode) {
        const raysplats::GaussianMode m = raysplats::gaussian_mode_names().value_of(mode);
        auto change = shared.change();
        py::gil_scoped_release release;
        return change->build(m);
    }

    py::dict last_build() const {
        const raysplats::Scene::BuildReport r = shared.scene().last_build();
        py::dict d;
        d["full"] = r.full;
        d["gaussian_chunks"] = r.gaussian_chunks;
        d["meshes"] = r.meshes;
        return d;
    }
};

// raysplats::RenderJob for Python: keeps the scene object alive as long as the job, and releases the GIL while
// it waits so that Blender's UI (and other Python threads) go on.
class PyRenderJob {
public:
    PyRenderJob(py::object scene_object, const py::dict& camera, const py::dict& settings, int max_threads,
                bool below_normal_priority)
        : scene_object_(std::move(scene_object)),
          job_(std::make_unique<raysplats::RenderJob>(scene_object_.cast<RenderScene&>().shared, camera_from(camera),
                                                      settings_from(settings), max_threads, below_normal_priority)) {}
    ~PyRenderJob() {
        py::gil_scoped_release release;  // the render thread is joined here
        job_.reset();
    }

    float progress() const { return job_->progress(); }
    void cancel() { job_->cancel(); }
    bool wait(double timeout_seconds) {
        py::gil_scoped_release release;
        return job_->wait(timeout_seconds);
    }
    int snapshot_samples() const { return job_->snapshot_samples(); }
    py::dict snapshot(const std::optional<std::vector<std::string>>& keys) {
        std::vector<raysplats::FilmChannel> channels;
        if (keys)
            for (const std::string& key : *keys) channels.push_back(film_channel_of(key));
        raysplats::Film film;
        {
            py::gil_scoped_release release;  // a copy of the film, under the job's lock
            film = job_->snapshot(channels);
        }
        return film_to_dict(std::move(film));
    }
    py::dict result() {
        raysplats::Film film;
        {
            py::gil_scoped_release release;
            film = job_->result();
        }
        return film_to_dict(std::move(film));
    }

private:
    py::object scene_object_;  // declared first: released after the job has ended
    std::unique_ptr<raysplats::RenderJob> job_;
};

}  // namespace

// The film channel table (raysplats/render/film.h), for the engine's pass registration and result writer.
py::list film_channel_table() {
    py::list channels;
    for (const raysplats::FilmChannelInfo& info : raysplats::film_channels())
        channels.append(py::dict("key"_a = info.key, "pass_name"_a = info.pass_name, "components"_a = info.components,
                                 "kind"_a = info.kind, "empty_value"_a = info.empty_value,
                                 "first_sample_only"_a = info.combination == raysplats::SampleCombination::FirstSample,
                                 "description"_a = info.description));
    return channels;
}

void register_render_bindings(py::module_& m) {
    m.def("cryptomatte_hash", [](const std::string& name) { return raysplats::cryptomatte_hash(name); }, "name"_a,
          "A name's Cryptomatte hash (MurmurHash3_32, seed 0, of its UTF-8 bytes), which its id and the manifest's "
          "8 hex digits are made of");
    m.def("cryptomatte_passes", [] {
              py::list passes;
              for (std::size_t t = 0; t < raysplats::kCryptomatteTypes; ++t) {
                  const auto type = raysplats::CryptomatteType(t);
                  passes.append(py::dict("key"_a = raysplats::cryptomatte_key(type),
                                         "prefix"_a = raysplats::cryptomatte_pass_prefix(type)));
              }
              return passes;
          },
          "The Cryptomatte pass types in order: key (the render setting and RenderJob.result()'s dict key) and prefix "
          "(the passes' names before their two-digit layer number)");
    m.def("film_channels", &film_channel_table,
          "The render's film channels in order: key (RenderJob.result()'s dict key), pass_name, components (one letter "
          "each), kind (COLOR/VALUE/VECTOR), empty_value, first_sample_only, description");
    py::class_<RenderScene>(m, "RenderScene", "Meshes, Gaussians, lights, materials and world for the ray tracer")
        .def(py::init<>())
        .def("add_material", &RenderScene::add_material, "base_color"_a = std::vector<float>{0.8f, 0.8f, 0.8f},
             "metallic"_a = 0.0f, "roughness"_a = 0.5f, "specular"_a = 0.5f, "transmission"_a = 0.0f,
             "ior"_a = 1.45f, "emission_color"_a = std::vector<float>{0, 0, 0}, "emission_strength"_a = 1.0f,
             "alpha"_a = 1.0f, "diffuse_model"_a = "LAMBERT", "base_color_texture"_a = py::none(),
             "texture_srgb"_a = false, "principled_version"_a = "V1",
             "specular_tint"_a = std::vector<float>{1.0f, 1.0f, 1.0f}, "multiscatter"_a = false, "pass_index"_a = 0u)
        .def("add_mesh", &RenderScene::add_mesh, "vertices"_a, "triangles"_a, "matrix"_a = py::none(),
             "material"_a = 0, "face_materials"_a = py::none(), "normals"_a = py::none(), "uvs"_a = py::none(),
             "pass_index"_a = 0u, "holdout"_a = false, "shadow_catcher"_a = false)
        .def("add_gaussians", &RenderScene::add_gaussians, "positions"_a, "rotations"_a, "scales"_a, "opacities"_a,
             "sh"_a, "matrix"_a = py::none())
        .def("add_light", &RenderScene::add_light, "type"_a, "color"_a, "power"_a, "matrix"_a,
             "spot_size"_a = 0.785398163f, "spot_blend"_a = 0.15f, "size_x"_a = 1.0f, "size_y"_a = 1.0f,
             "sun_angle"_a = 0.0f)
        .def("set_world", &RenderScene::set_world, "color"_a, "strength"_a = 1.0f, "mist_start"_a = 0.0f,
             "mist_depth"_a = 100.0f, "mist_falloff"_a = 1.0f,
             "The world's colour and strength, and its mist settings (the Mist pass; falloff as an exponent)")
        .def("build", &RenderScene::build, "gaussian_mode"_a = "FLAT", "Builds the BVH; returns seconds")
        .def("update_mesh", &RenderScene::update_mesh, "index"_a, "vertices"_a, "triangles"_a, "matrix"_a = py::none(),
             "material"_a = 0, "face_materials"_a = py::none(), "normals"_a = py::none(), "uvs"_a = py::none(),
             "pass_index"_a = 0u, "holdout"_a = false, "shadow_catcher"_a = false,
             "Replaces mesh `index` (as add_mesh); the next build rebuilds only its BVH")
        .def("update_gaussians", &RenderScene::update_gaussians, "index"_a, "positions"_a, "rotations"_a, "scales"_a,
             "opacities"_a, "sh"_a, "matrix"_a = py::none(),
             "Replaces Gaussian cloud `index`; the next build rebuilds only the chunks that changed")
        .def("update_gaussian_rows", &RenderScene::update_gaussian_rows, "index"_a, "rows"_a, "positions"_a,
             "rotations"_a, "scales"_a, "opacities"_a, "sh"_a,
             "Replaces Gaussians `rows` of cloud `index` (row j of the arrays becomes Gaussian rows[j]); the next "
             "build recomputes only them and rebuilds only the chunks that hold them")
        .def("set_gaussians_matrix", &RenderScene::set_gaussians_matrix, "index"_a, "matrix"_a,
             "Moves Gaussian cloud `index`; the next build changes only instance transforms")
        .def("set_mesh_motion", &RenderScene::set_mesh_motion, "index"_a, "matrices"_a,
             "Motion blur: mesh `index`'s matrices (n, 4, 4) at equally spaced times from the shutter's opening to its "
             "closing; None or fewer than 2: no motion")
        .def("set_mesh_deformation", &RenderScene::set_mesh_deformation, "index"_a, "vertices"_a,
             "Deformation blur: mesh `index`'s vertex positions (steps, vertices, 3) at equally spaced times from the "
             "shutter's opening to its closing; None or fewer than 2 steps: none")
        .def("set_gaussians_deformation", &RenderScene::set_gaussians_deformation, "index"_a,
             "positions"_a = py::none(), "rotations"_a = py::none(), "scales"_a = py::none(),
             "Deformation blur: Gaussian cloud `index`'s Gaussians (positions (steps, n, 3), rotations (steps, n, 4), "
             "scales (steps, n, 3)) at equally spaced times from the shutter's opening to its closing; None or fewer "
             "than 2 steps: none")
        .def("set_gaussians_motion", &RenderScene::set_gaussians_motion, "index"_a, "matrices"_a,
             "Motion blur: Gaussian cloud `index`'s matrices (n, 4, 4) at equally spaced times from the shutter's "
             "opening to its closing; None or fewer than 2: no motion")
        .def("set_mesh_frame_motion", &RenderScene::set_mesh_frame_motion, "index"_a, "previous"_a, "next"_a,
             "The Vector pass: mesh `index`'s matrices at the previous and the next frame")
        .def("set_mesh_frame_deformation", &RenderScene::set_mesh_frame_deformation, "index"_a,
             "previous"_a = py::none(), "next"_a = py::none(),
             "The Vector pass: mesh `index`'s vertices (n, 3) at the previous and the next frame; None: none")
        .def("set_gaussians_frame_motion", &RenderScene::set_gaussians_frame_motion, "index"_a, "previous"_a, "next"_a,
             "The Vector pass: Gaussian cloud `index`'s matrices at the previous and the next frame")
        .def("set_gaussian_shading", &RenderScene::set_gaussian_shading, "index"_a, "shading"_a = py::none(),
             "Gaussian cloud `index`'s own shading (BAKED, LIT, BAKED_SHADOWED), or None for the render setting "
             "gaussian_shading")
        .def("set_gaussian_pass_indices", &RenderScene::set_gaussian_pass_indices, "index"_a, "object_pass_index"_a,
             "material_pass_index"_a = 0u,
             "The Object and Material Index passes' values where Gaussian cloud `index` is the surface")
        .def("set_gaussian_cryptomatte_names", &RenderScene::set_gaussian_cryptomatte_names, "index"_a, "object"_a,
             "material"_a = "", "asset"_a = "",
             "The names whose Cryptomatte ids Gaussian cloud `index` gives ('' gives none)")
        .def("set_mesh_cryptomatte_names", &RenderScene::set_mesh_cryptomatte_names, "index"_a, "object"_a,
             "asset"_a = "", "The names whose Cryptomatte ids mesh `index` gives (its materials give theirs)")
        .def("set_material_cryptomatte_name", &RenderScene::set_material_cryptomatte_name, "index"_a, "material"_a,
             "The name whose Cryptomatte id material `index` gives")
        .def("set_gaussian_holdout", &RenderScene::set_gaussian_holdout, "index"_a, "holdout"_a,
             "Holds out Gaussian cloud `index` (Blender's Holdout): camera rays take no colour from its Gaussians and "
             "Combined's alpha loses their coverage")
        .def("set_interactive", &RenderScene::set_interactive, "interactive"_a, "chunk_size"_a = 1u << 18,
             "Splits Gaussian clouds into chunks so that edits rebuild only what they touch (the viewport)")
        .def("set_keep_frame_buffers", &RenderScene::set_keep_frame_buffers, "keep"_a,
             "Keeps the last frame's camera-ray splatting storage for the next frame (Persistent Data); off frees it")
        .def_property_readonly("kept_frame_buffer_bytes",
                               [](const RenderScene& s) { return s.shared.scene().kept_frame_buffer_bytes(); })
        .def("last_build", &RenderScene::last_build, "What the last build did: full, gaussian_chunks, meshes")
        .def_property_readonly("gaussian_count", [](const RenderScene& s) { return s.shared.scene().gaussian_count(); })
        .def_property_readonly("mesh_count", [](const RenderScene& s) { return s.shared.scene().mesh_count(); })
        .def_property_readonly("light_count", [](const RenderScene& s) { return s.shared.scene().light_count(); })
        .def_property_readonly(
            "embree_device",
            [](const RenderScene& s) {
                const raysplats::EmbreeDeviceInfo d = s.shared.scene().embree_device();
                py::dict out;
                out["config"] = d.config;
                out["native_ray4"] = d.native_ray4;
                out["native_ray8"] = d.native_ray8;
                out["native_ray16"] = d.native_ray16;
                return out;
            },
            "The Embree device: its configuration (RAYSPLATS_EMBREE_CONFIG) and its native packet widths");

    py::class_<PyRenderJob>(m, "RenderJob", "A render running on a native thread")
        .def(py::init<py::object, const py::dict&, const py::dict&, int, bool>(), "scene"_a, "camera"_a, "settings"_a,
             "max_threads"_a = 0, "below_normal_priority"_a = false,
             "Starts rendering; camera and settings are dicts of camera_parameters() and render_settings() "
             "(unknown names are errors); max_threads > 0 caps the render's threads (0: all cores); "
             "below_normal_priority: the job's thread yields the CPU to the UI")
        .def_property_readonly("progress", &PyRenderJob::progress)
        .def("cancel", &PyRenderJob::cancel)
        .def("wait", &PyRenderJob::wait, "timeout"_a, "True when the render has finished")
        .def_property_readonly("snapshot_samples", &PyRenderJob::snapshot_samples,
                               "Sample passes done over the whole image (before the last); 0 before the first ends")
        .def("snapshot", &PyRenderJob::snapshot, "channels"_a = py::none(),
             "The film of the newest completed sample pass, as result() gives films (its 'samples': the passes; "
             "only the channels named, by key, when given: the viewport copies 'rgba' alone); 0 x 0 before the "
             "first pass ends")
        .def("result", &PyRenderJob::result, "The film as numpy arrays (rows top to bottom); raises on errors");

    // The core's vocabularies, for the add-on to read rather than restate.
    m.def("render_settings", [] { return describe(raysplats::render_setting_parameters()); },
          "The render settings a RenderJob takes: list of {name, type, description, choices}");
    m.def("camera_parameters", [] { return describe(raysplats::camera_parameters()); },
          "The camera parameters a RenderJob takes (angles in radians): list of {name, type, description, choices}");
    m.def("camera_models", [] { return describe(raysplats::camera_model_names()); },
          "The camera models (the camera parameter 'type'): list of {name, description}");
}
