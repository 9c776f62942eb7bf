// Bindings of the renderer (raysplats._native.RenderScene, RenderJob). Thin: arrays in are kept alive by the
// scene object (the core shares them without copies); a render runs on its own thread so that the Blender
// engine can poll progress and Esc from the main thread and cancel within a fraction of a second.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <deque>
#include <exception>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>

#include "raysplats/errors.h"
#include "raysplats/render/renderer.h"

namespace py = pybind11;
using namespace pybind11::literals;

namespace {

using FloatArray = py::array_t<float, py::array::c_style | py::array::forcecast>;
using UintArray = py::array_t<std::uint32_t, py::array::c_style | py::array::forcecast>;

void require_shape(const py::array& a, const char* name, std::initializer_list<py::ssize_t> shape) {
    bool ok = a.ndim() == py::ssize_t(shape.size());
    std::size_t i = 0;
    for (auto s : shape) {
        ok = ok && (s < 0 || a.shape(i) == s);
        ++i;
    }
    if (!ok) throw raysplats::InvalidArgument(std::string("array '") + name + "' has the wrong shape");
}

raysplats::Matrix4 matrix_from(const py::object& obj, const char* name) {
    raysplats::Matrix4 m;
    if (obj.is_none()) return m;
    FloatArray a = FloatArray::ensure(obj);
    if (!a || a.size() != 16) throw raysplats::InvalidArgument(std::string("'") + name + "' must be a 4x4 matrix");
    std::copy(a.data(), a.data() + 16, m.m.begin());
    return m;
}

std::array<float, 3> rgb_from(const py::sequence& s, const char* name) {
    if (py::len(s) < 3) throw raysplats::InvalidArgument(std::string("'") + name + "' needs 3 components");
    return {s[0].cast<float>(), s[1].cast<float>(), s[2].cast<float>()};
}

template <typename E>
E enum_from(const std::string& value, std::initializer_list<std::pair<const char*, E>> items, const char* name) {
    for (const auto& [key, e] : items)
        if (value == key) return e;
    throw raysplats::InvalidArgument(std::string("unknown ") + name + " '" + value + "'");
}

raysplats::GaussianMode gaussian_mode_from(const std::string& s) {
    return enum_from<raysplats::GaussianMode>(
        s, {{"FLAT", raysplats::GaussianMode::Flat}, {"VOLUMETRIC", raysplats::GaussianMode::Volumetric}},
        "Gaussian mode");
}

// A scene plus the Python objects whose memory it shares.
struct RenderScene {
    raysplats::Scene scene;
    std::vector<py::object> keep_alive;                // textures
    std::vector<std::vector<py::object>> mesh_arrays;  // per mesh index
    std::vector<std::unique_ptr<raysplats::GaussianCloud>> clouds;  // per cloud index (stable addresses)

    std::uint32_t add_material(const py::sequence& base_color, float metallic, float roughness, float specular,
                               float transmission, float ior, const py::sequence& emission_color,
                               float emission_strength, float alpha, const std::string& diffuse_model,
                               const std::optional<FloatArray>& base_color_texture, bool texture_srgb,
                               const std::string& principled_version, const py::sequence& specular_tint,
                               bool multiscatter) {
        raysplats::Material m;
        m.base_color = rgb_from(base_color, "base_color");
        m.metallic = metallic, m.roughness = roughness, m.specular = specular;
        m.transmission = transmission, m.ior = ior;
        m.emission_color = rgb_from(emission_color, "emission_color");
        m.emission_strength = emission_strength, m.alpha = alpha;
        m.diffuse_model = enum_from<raysplats::DiffuseModel>(
            diffuse_model, {{"LAMBERT", raysplats::DiffuseModel::Lambert}, {"PRINCIPLED", raysplats::DiffuseModel::Principled}},
            "diffuse model");
        m.principled_version = enum_from<raysplats::PrincipledVersion>(
            principled_version, {{"V1", raysplats::PrincipledVersion::V1}, {"V2", raysplats::PrincipledVersion::V2}},
            "Principled version");
        m.specular_tint = rgb_from(specular_tint, "specular_tint");
        m.multiscatter = multiscatter;
        if (base_color_texture) {
            // H x W x C (or H x W for one channel), row 0 = bottom as Blender's Image.pixels.
            const FloatArray& t = *base_color_texture;
            const int channels = t.ndim() == 2 ? 1 : t.ndim() == 3 ? int(t.shape(2)) : 0;
            if (channels != 1 && channels != 3 && channels != 4)
                throw raysplats::InvalidArgument("array 'base_color_texture' must be H x W x C with C = 1, 3 or 4");
            m.base_color_texture.pixels = t.data();
            m.base_color_texture.height = int(t.shape(0));
            m.base_color_texture.width = int(t.shape(1));
            m.base_color_texture.channels = channels;
            m.base_color_texture.srgb = texture_srgb;
        }
        const std::uint32_t index = scene.add_material(m);
        if (base_color_texture) keep_alive.push_back(*base_color_texture);
        return index;
    }

    // A mesh description over the caller's arrays, and the arrays it points into.
    static raysplats::MeshDesc mesh_desc(const FloatArray& vertices, const UintArray& triangles, const py::object& matrix,
                                         std::uint32_t material, const std::optional<UintArray>& face_materials,
                                         const std::optional<FloatArray>& normals, const std::optional<FloatArray>& uvs,
                                         std::vector<py::object>& arrays) {
        require_shape(vertices, "vertices", {-1, 3});
        require_shape(triangles, "triangles", {-1, 3});
        raysplats::MeshDesc d;
        d.vertices = vertices.data();
        d.vertex_count = std::size_t(vertices.shape(0));
        d.indices = triangles.data();
        d.triangle_count = std::size_t(triangles.shape(0));
        d.material = material;
        d.object_to_world = matrix_from(matrix, "matrix");
        arrays = {vertices, triangles};
        if (face_materials) {
            require_shape(*face_materials, "face_materials", {triangles.shape(0)});
            d.face_materials = face_materials->data();
            arrays.push_back(*face_materials);
        }
        if (normals) {
            require_shape(*normals, "normals", {vertices.shape(0), 3});
            d.normals = normals->data();
            arrays.push_back(*normals);
        }
        if (uvs) {
            require_shape(*uvs, "uvs", {vertices.shape(0), 2});
            d.uvs = uvs->data();
            arrays.push_back(*uvs);
        }
        return d;
    }

    std::uint32_t add_mesh(const FloatArray& vertices, const UintArray& triangles, const py::object& matrix,
                           std::uint32_t material, const std::optional<UintArray>& face_materials,
                           const std::optional<FloatArray>& normals, const std::optional<FloatArray>& uvs) {
        std::vector<py::object> arrays;
        const raysplats::MeshDesc d = mesh_desc(vertices, triangles, matrix, material, face_materials, normals, uvs, arrays);
        const std::uint32_t index = scene.add_mesh(d);
        mesh_arrays.push_back(std::move(arrays));
        return index;
    }

    void set_interactive(bool interactive, std::uint32_t chunk_size) {
        require_idle();
        scene.set_interactive(interactive, chunk_size);
    }

    py::dict last_build() const {
        const raysplats::Scene::BuildReport r = scene.last_build();
        py::dict d;
        d["full"] = r.full;
        d["gaussian_chunks"] = r.gaussian_chunks;
        d["meshes"] = r.meshes;
        return d;
    }

    // Updates must not race a render of this scene on a RenderJob thread.
    std::atomic<int> renders_running{0};
    void require_idle() const {
        if (renders_running.load() != 0)
            throw raysplats::Error("the scene is being rendered; wait for or cancel the render before changing it");
    }

    void update_mesh(std::uint32_t index, const FloatArray& vertices, const UintArray& triangles,
                     const py::object& matrix, std::uint32_t material, const std::optional<UintArray>& face_materials,
                     const std::optional<FloatArray>& normals, const std::optional<FloatArray>& uvs) {
        require_idle();
        std::vector<py::object> arrays;
        const raysplats::MeshDesc d = mesh_desc(vertices, triangles, matrix, material, face_materials, normals, uvs, arrays);
        scene.update_mesh(index, d);
        mesh_arrays[index] = std::move(arrays);  // the old arrays are released only now
    }

    static std::unique_ptr<raysplats::GaussianCloud> cloud_from(const FloatArray& positions, const FloatArray& rotations,
                                                                const FloatArray& scales, const FloatArray& opacities,
                                                                const FloatArray& sh) {
        require_shape(positions, "positions", {-1, 3});
        const py::ssize_t n = positions.shape(0);
        require_shape(rotations, "rotations", {n, 4});
        require_shape(scales, "scales", {n, 3});
        require_shape(opacities, "opacities", {n});
        require_shape(sh, "sh", {n, -1, 3});
        auto cloud = std::make_unique<raysplats::GaussianCloud>();
        int degree = -1;
        for (int d = 0; d <= 3; ++d)
            if (raysplats::sh_coeff_count(d) == sh.shape(1)) degree = d;
        if (degree < 0) throw raysplats::InvalidArgument("sh must have 1, 4, 9 or 16 coefficients per channel");
        cloud->sh_degree = degree;
        cloud->positions.assign(positions.data(), positions.data() + positions.size());
        cloud->rotations.assign(rotations.data(), rotations.data() + rotations.size());
        cloud->scales.assign(scales.data(), scales.data() + scales.size());
        cloud->opacities.assign(opacities.data(), opacities.data() + opacities.size());
        cloud->sh.assign(sh.data(), sh.data() + sh.size());
        return cloud;
    }

    std::uint32_t add_gaussians(const FloatArray& positions, const FloatArray& rotations, const FloatArray& scales,
                                const FloatArray& opacities, const FloatArray& sh, const py::object& matrix) {
        auto cloud = cloud_from(positions, rotations, scales, opacities, sh);
        const std::uint32_t index = scene.add_gaussians(*cloud, matrix_from(matrix, "matrix"));
        clouds.push_back(std::move(cloud));
        return index;
    }

    void update_gaussians(std::uint32_t index, const FloatArray& positions, const FloatArray& rotations,
                          const FloatArray& scales, const FloatArray& opacities, const FloatArray& sh,
                          const py::object& matrix) {
        require_idle();
        auto cloud = cloud_from(positions, rotations, scales, opacities, sh);
        scene.update_gaussians(index, *cloud, matrix_from(matrix, "matrix"));
        clouds[index] = std::move(cloud);
    }

    // Replaces some Gaussians of cloud `index` (the viewport's edit of a few splats): row j of the arrays becomes
    // Gaussian rows[j]. The rows are validated before the cloud is touched, so a bad edit changes nothing.
    void update_gaussian_rows(std::uint32_t index, const UintArray& rows, const FloatArray& positions,
                              const FloatArray& rotations, const FloatArray& scales, const FloatArray& opacities,
                              const FloatArray& sh) {
        require_idle();
        if (index >= clouds.size()) throw raysplats::InvalidArgument("Gaussian cloud " + std::to_string(index) + " does not exist");
        auto values = cloud_from(positions, rotations, scales, opacities, sh);
        require_shape(rows, "rows", {py::ssize_t(values->size())});
        clouds[index]->assign_rows(*values, rows.data(), "Gaussian cloud " + std::to_string(index));
        scene.gaussians_changed(index, rows.data(), values->size());
    }

    // Moves a Gaussian cloud without new data (the viewport's object transform).
    void set_gaussians_matrix(std::uint32_t index, const py::object& matrix) {
        require_idle();
        scene.set_gaussians_transform(index, matrix_from(matrix, "matrix"));
    }

    std::uint32_t add_light(const std::string& type, const py::sequence& color, float power, const py::object& matrix,
                            float spot_size, float spot_blend, float size_x, float size_y, float sun_angle) {
        raysplats::Light l;
        l.type = enum_from<raysplats::LightType>(type,
                                                 {{"POINT", raysplats::LightType::Point},
                                                  {"SUN", raysplats::LightType::Sun},
                                                  {"SPOT", raysplats::LightType::Spot},
                                                  {"AREA_RECTANGLE", raysplats::LightType::AreaRectangle},
                                                  {"AREA_DISK", raysplats::LightType::AreaDisk}},
                                                 "light type");
        l.color = rgb_from(color, "color");
        l.power = power, l.spot_size = spot_size, l.spot_blend = spot_blend;
        l.size_x = size_x, l.size_y = size_y, l.sun_angle = sun_angle;
        l.light_to_world = matrix_from(matrix, "matrix");
        return scene.add_light(l);
    }

    void set_world(const py::sequence& color, float strength) {
        raysplats::World w;
        w.color = rgb_from(color, "color");
        w.strength = strength;
        scene.set_world(w);
    }

    double build(const std::string& mode) {
        const auto m = gaussian_mode_from(mode);
        py::gil_scoped_release release;
        return scene.build(m);
    }
};

raysplats::Camera camera_from(const py::dict& c) {
    raysplats::Camera cam;
    auto get = [&](const char* key, float fallback) { return c.contains(key) ? c[key].cast<float>() : fallback; };
    cam.type = enum_from<raysplats::CameraType>(
        c.contains("type") ? c["type"].cast<std::string>() : std::string("PERSP"),
        {{"PERSP", raysplats::CameraType::Perspective},
         {"ORTHO", raysplats::CameraType::Orthographic},
         {"EQUIRECTANGULAR", raysplats::CameraType::Equirectangular},
         {"FISHEYE_EQUIDISTANT", raysplats::CameraType::FisheyeEquidistant},
         {"FISHEYE_EQUISOLID", raysplats::CameraType::FisheyeEquisolid}},
        "camera type");
    cam.camera_to_world = matrix_from(c.contains("matrix") ? py::object(c["matrix"]) : py::none(), "camera matrix");
    cam.focal_length_mm = get("lens", cam.focal_length_mm);
    cam.sensor_width_mm = get("sensor_width", cam.sensor_width_mm);
    cam.sensor_height_mm = get("sensor_height", cam.sensor_height_mm);
    cam.sensor_fit = enum_from<raysplats::SensorFit>(
        c.contains("sensor_fit") ? c["sensor_fit"].cast<std::string>() : std::string("AUTO"),
        {{"AUTO", raysplats::SensorFit::Auto},
         {"HORIZONTAL", raysplats::SensorFit::Horizontal},
         {"VERTICAL", raysplats::SensorFit::Vertical}},
        "sensor fit");
    cam.shift_x = get("shift_x", 0), cam.shift_y = get("shift_y", 0);
    cam.clip_start = get("clip_start", cam.clip_start), cam.clip_end = get("clip_end", cam.clip_end);
    cam.ortho_scale = get("ortho_scale", cam.ortho_scale);
    cam.longitude_min = get("longitude_min", cam.longitude_min);
    cam.longitude_max = get("longitude_max", cam.longitude_max);
    cam.latitude_min = get("latitude_min", cam.latitude_min);
    cam.latitude_max = get("latitude_max", cam.latitude_max);
    cam.fisheye_fov = get("fisheye_fov", cam.fisheye_fov);
    cam.fisheye_lens_mm = get("fisheye_lens", cam.fisheye_lens_mm);
    return cam;
}

raysplats::RenderSettings settings_from(const py::dict& s) {
    raysplats::RenderSettings r;
    auto get_int = [&](const char* key, int fallback) { return s.contains(key) ? s[key].cast<int>() : fallback; };
    r.width = get_int("width", r.width);
    r.height = get_int("height", r.height);
    r.samples = get_int("samples", r.samples);
    r.max_bounces = get_int("max_bounces", r.max_bounces);
    r.seed = std::uint32_t(get_int("seed", 0));
    if (s.contains("compositing"))
        r.compositing = enum_from<raysplats::Compositing>(
            s["compositing"].cast<std::string>(),
            {{"SORTED", raysplats::Compositing::Sorted}, {"STOCHASTIC", raysplats::Compositing::Stochastic}},
            "compositing");
    if (s.contains("transmittance_threshold")) r.transmittance_threshold = s["transmittance_threshold"].cast<float>();
    if (s.contains("gaussian_mode")) r.gaussian_mode = gaussian_mode_from(s["gaussian_mode"].cast<std::string>());
    if (s.contains("meshes_shadow_gaussians")) r.meshes_shadow_gaussians = s["meshes_shadow_gaussians"].cast<bool>();
    if (s.contains("transparent_background")) r.transparent_background = s["transparent_background"].cast<bool>();
    if (s.contains("caustics_reflective")) r.caustics_reflective = s["caustics_reflective"].cast<bool>();
    if (s.contains("caustics_refractive")) r.caustics_refractive = s["caustics_refractive"].cast<bool>();
    r.tile_size = get_int("tile_size", r.tile_size);
    r.validate();
    return r;
}

template <typename T, typename A>
py::array_t<T> to_numpy(std::vector<T, A>&& values, std::vector<py::ssize_t> shape) {
    auto* owned = new std::vector<T, A>(std::move(values));
    py::capsule owner(owned, [](void* p) { delete static_cast<std::vector<T, A>*>(p); });
    return py::array_t<T>(shape, owned->data(), owner);
}

// One render on a worker thread. Python polls progress()/wait() and may cancel(); result() hands the film over.
class RenderJob {
public:
    RenderJob(py::object scene_object, const py::dict& camera, const py::dict& settings)
        : scene_object_(std::move(scene_object)), camera_(camera_from(camera)), settings_(settings_from(settings)) {
        camera_.validate();
        RenderScene& rs = scene_object_.cast<RenderScene&>();
        ++rs.renders_running;
        thread_ = std::thread([this, &rs] {
            try {
                film_ = raysplats::render(rs.scene, camera_, settings_,
                                          [this](float f) { progress_.store(f); }, &cancel_);
            } catch (...) {
                error_ = std::current_exception();
            }
            --rs.renders_running;
            std::lock_guard<std::mutex> lock(mutex_);
            done_ = true;
            cv_.notify_all();
        });
    }
    ~RenderJob() {
        cancel_.store(true);
        if (thread_.joinable()) {
            py::gil_scoped_release release;
            thread_.join();
        }
    }

    float progress() const { return progress_.load(); }
    void cancel() { cancel_.store(true); }
    bool wait(double timeout_seconds) {
        py::gil_scoped_release release;
        std::unique_lock<std::mutex> lock(mutex_);
        return cv_.wait_for(lock, std::chrono::duration<double>(timeout_seconds), [this] { return done_; });
    }

    py::dict result() {
        wait(1e9);
        if (thread_.joinable()) thread_.join();
        if (error_) std::rethrow_exception(error_);
        const py::ssize_t h = film_.height, w = film_.width;
        py::dict d;
        d["cancelled"] = film_.stats.cancelled;
        d["render_seconds"] = film_.stats.render_seconds;
        d["camera_rays"] = film_.stats.camera_rays;
        d["gaussian_hits"] = film_.stats.gaussian_hits;
        d["rgba"] = to_numpy(std::move(film_.rgba), {h, w, 4});
        d["depth"] = to_numpy(std::move(film_.depth), {h, w});
        d["normal"] = to_numpy(std::move(film_.normal), {h, w, 3});
        d["alpha"] = to_numpy(std::move(film_.alpha), {h, w});
        return d;
    }

private:
    py::object scene_object_;
    raysplats::Camera camera_;
    raysplats::RenderSettings settings_;
    raysplats::Film film_;
    std::exception_ptr error_;
    std::atomic<float> progress_{0.0f};
    std::atomic<bool> cancel_{false};
    std::mutex mutex_;
    std::condition_variable cv_;
    bool done_ = false;
    std::thread thread_;
};

}  // namespace

void register_render_bindings(py::module_& m) {
    py::class_<RenderScene>(m, "RenderScene", "Meshes, Gaussians, lights, materials and world for the ray tracer")
        .def(py::init<>())
        .def("add_material", &RenderScene::add_material, "base_color"_a = std::vector<float>{0.8f, 0.8f, 0.8f},
             "metallic"_a = 0.0f, "roughness"_a = 0.5f, "specular"_a = 0.5f, "transmission"_a = 0.0f,
             "ior"_a = 1.45f, "emission_color"_a = std::vector<float>{0, 0, 0}, "emission_strength"_a = 1.0f,
             "alpha"_a = 1.0f, "diffuse_model"_a = "LAMBERT", "base_color_texture"_a = py::none(),
             "texture_srgb"_a = false, "principled_version"_a = "V1",
             "specular_tint"_a = std::vector<float>{1.0f, 1.0f, 1.0f}, "multiscatter"_a = false)
        .def("add_mesh", &RenderScene::add_mesh, "vertices"_a, "triangles"_a, "matrix"_a = py::none(),
             "material"_a = 0, "face_materials"_a = py::none(), "normals"_a = py::none(), "uvs"_a = py::none())
        .def("add_gaussians", &RenderScene::add_gaussians, "positions"_a, "rotations"_a, "scales"_a, "opacities"_a,
             "sh"_a, "matrix"_a = py::none())
        .def("add_light", &RenderScene::add_light, "type"_a, "color"_a, "power"_a, "matrix"_a,
             "spot_size"_a = 0.785398163f, "spot_blend"_a = 0.15f, "size_x"_a = 1.0f, "size_y"_a = 1.0f,
             "sun_angle"_a = 0.0f)
        .def("set_world", &RenderScene::set_world, "color"_a, "strength"_a = 1.0f)
        .def("build", &RenderScene::build, "gaussian_mode"_a = "FLAT", "Builds the BVH; returns seconds")
        .def("update_mesh", &RenderScene::update_mesh, "index"_a, "vertices"_a, "triangles"_a, "matrix"_a = py::none(),
             "material"_a = 0, "face_materials"_a = py::none(), "normals"_a = py::none(), "uvs"_a = py::none(),
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
        .def("set_interactive", &RenderScene::set_interactive, "interactive"_a, "chunk_size"_a = 1u << 18,
             "Splits Gaussian clouds into chunks so that edits rebuild only what they touch (the viewport)")
        .def("last_build", &RenderScene::last_build, "What the last build did: full, gaussian_chunks, meshes")
        .def_property_readonly("gaussian_count", [](RenderScene& s) { return s.scene.gaussian_count(); })
        .def_property_readonly("mesh_count", [](RenderScene& s) { return s.scene.mesh_count(); })
        .def_property_readonly("light_count", [](RenderScene& s) { return s.scene.light_count(); });

    py::class_<RenderJob>(m, "RenderJob", "A render running on a native thread")
        .def(py::init<py::object, const py::dict&, const py::dict&>(), "scene"_a, "camera"_a, "settings"_a)
        .def_property_readonly("progress", &RenderJob::progress)
        .def("cancel", &RenderJob::cancel)
        .def("wait", &RenderJob::wait, "timeout"_a, "True when the render has finished")
        .def("result", &RenderJob::result, "The film as numpy arrays (rows top to bottom); raises on errors");
}
