// Embree scene construction (DESIGN §6). Pattern of Embree's minimal tutorial: every geometry is created,
// committed, attached, then released (the scene holds the reference), and the scene committed last.
#include "raysplats/render/scene.h"

#include <chrono>
#include <cmath>
#include <string>

#include "microfacet_tables.h"
#include "raysplats/errors.h"
#include "render_math.h"
#include "scene_impl.h"

namespace raysplats {
namespace {

void device_error_callback(void* user, RTCError code, const char* message) {
    auto* impl = static_cast<Scene::Impl*>(user);
    if (impl->device_error.empty()) impl->device_error = std::string("Embree error ") + std::to_string(int(code)) + ": " + (message ? message : "");
}

std::string at(const char* what, std::size_t index) { return std::string(what) + " " + std::to_string(index); }

}  // namespace

void Scene::Impl::release_scene() {
    if (scene) rtcReleaseScene(scene);
    scene = nullptr;
    for (auto& m : meshes) {
        if (m->sub_scene) rtcReleaseScene(m->sub_scene);
        m->sub_scene = nullptr;
    }
    built = false;
}

void Scene::Impl::check_device(const char* during) {
    if (!device_error.empty()) {
        std::string msg = device_error;
        device_error.clear();
        throw Error(std::string("while ") + during + ": " + msg);
    }
}

Scene::Scene() : impl_(new Impl) {
    impl_->device = rtcNewDevice(nullptr);
    if (!impl_->device) throw Error("cannot create the Embree device (error " + std::to_string(int(rtcGetDeviceError(nullptr))) + ")");
    rtcSetDeviceErrorFunction(impl_->device, device_error_callback, impl_.get());
}

Scene::~Scene() {
    impl_->release_scene();
    rtcReleaseDevice(impl_->device);
}

std::uint32_t Scene::add_material(const Material& material) {
    material.validate(("material " + std::to_string(impl_->materials.size())).c_str());
    // Principled v2 reads the GGX albedo tables: build them now rather than inside the first render.
    if (material.principled_version == PrincipledVersion::V2) microfacet_tables();
    impl_->materials.push_back(material);
    impl_->built = false;
    return std::uint32_t(impl_->materials.size() - 1);
}

std::uint32_t Scene::add_mesh(const MeshDesc& mesh) {
    const std::string name = at("mesh", impl_->meshes.size());
    auto fail = [&](const std::string& problem) { throw InvalidArgument(name + ": " + problem); };
    if (mesh.vertex_count == 0 || mesh.triangle_count == 0) fail("has no vertices or no triangles");
    if (!mesh.vertices || !mesh.indices) fail("vertex or index array is null");
    if (mesh.vertex_count > 0xffffffffu || mesh.triangle_count > 0x7fffffffu) fail("too many vertices or triangles");
    mesh.object_to_world.check_affine((name + " object_to_world").c_str());
    for (std::size_t i = 0; i < 3 * mesh.vertex_count; ++i)
        if (!std::isfinite(mesh.vertices[i])) fail("vertex " + std::to_string(i / 3) + " has a NaN or Inf coordinate");
    for (std::size_t i = 0; i < 3 * mesh.triangle_count; ++i)
        if (mesh.indices[i] >= mesh.vertex_count)
            fail("triangle " + std::to_string(i / 3) + " uses vertex " + std::to_string(mesh.indices[i]) + " of " +
                 std::to_string(mesh.vertex_count));
    if (mesh.normals)
        for (std::size_t i = 0; i < 3 * mesh.vertex_count; ++i)
            if (!std::isfinite(mesh.normals[i])) fail("normal " + std::to_string(i / 3) + " is NaN or Inf");
    if (mesh.uvs)
        for (std::size_t i = 0; i < 2 * mesh.vertex_count; ++i)
            if (!std::isfinite(mesh.uvs[i])) fail("UV " + std::to_string(i / 2) + " is NaN or Inf");
    // Material indices are checked against the materials present when the scene is built (they may be added later).
    auto rec = std::make_unique<MeshRecord>();
    rec->desc = mesh;
    if (!mesh.vertices_padded) {
        rec->padded_vertices.assign(mesh.vertices, mesh.vertices + 3 * mesh.vertex_count);
        rec->padded_vertices.push_back(0.0f);
    }
    rec->linear = linear_part(mesh.object_to_world);
    rec->translation = translation_part(mesh.object_to_world);
    rec->normal_matrix = glm::transpose(glm::inverse(rec->linear));
    rec->mirrored = glm::determinant(rec->linear) < 0.0f;
    impl_->meshes.push_back(std::move(rec));
    impl_->built = false;
    return std::uint32_t(impl_->meshes.size() - 1);
}

std::uint32_t Scene::add_gaussians(const GaussianCloud& cloud, const Matrix4& object_to_world) {
    const std::string name = at("Gaussian cloud", impl_->gaussians.size());
    cloud.check_consistent();
    object_to_world.check_affine((name + " object_to_world").c_str());
    if (cloud.size() >= 0xffffffffu) throw InvalidArgument(name + ": too many Gaussians");
    const std::size_t n = cloud.size();
    const int k = cloud.coeffs_per_channel() * 3;
    for (std::size_t i = 0; i < n; ++i) {
        bool ok = std::isfinite(cloud.opacities[i]);
        for (int j = 0; j < 3; ++j) ok = ok && std::isfinite(cloud.positions[3 * i + j]) && std::isfinite(cloud.scales[3 * i + j]);
        for (int j = 0; j < 4; ++j) ok = ok && std::isfinite(cloud.rotations[4 * i + j]);
        for (int j = 0; j < k; ++j) ok = ok && std::isfinite(cloud.sh[i * k + j]);
        if (!ok) throw InvalidArgument(name + ": Gaussian " + std::to_string(i) + " has a NaN or Inf value");
        if (cloud.scales[3 * i] < 0 || cloud.scales[3 * i + 1] < 0 || cloud.scales[3 * i + 2] < 0)
            throw InvalidArgument(name + ": Gaussian " + std::to_string(i) + " has a negative scale (scales are linear)");
    }
    auto set = std::make_unique<GaussianSet>();
    set->cloud = &cloud;
    set->object_to_world = object_to_world;
    impl_->gaussians.push_back(std::move(set));
    impl_->built = false;
    return std::uint32_t(impl_->gaussians.size() - 1);
}

std::uint32_t Scene::add_light(const Light& light) {
    light.validate(("light " + std::to_string(impl_->lights.size())).c_str());
    impl_->lights.push_back(light);
    return std::uint32_t(impl_->lights.size() - 1);
}

void Scene::set_world(const World& world) {
    for (float v : {world.color[0], world.color[1], world.color[2], world.strength})
        if (!std::isfinite(v) || v < 0.0f) throw InvalidArgument("world: colour and strength must be finite and >= 0");
    impl_->world = world;
}

double Scene::build(GaussianMode mode) {
    Impl& s = *impl_;
    if (s.built && s.built_mode == mode) return 0.0;
    const auto start = std::chrono::steady_clock::now();
    s.release_scene();
    for (std::size_t mi = 0; mi < s.meshes.size(); ++mi) {
        const MeshRecord& m = *s.meshes[mi];
        if (m.desc.face_materials) {
            for (std::size_t f = 0; f < m.desc.triangle_count; ++f)
                if (m.desc.face_materials[f] >= std::max<std::size_t>(1, s.materials.size()))
                    throw InvalidArgument(at("mesh", mi) + ": triangle " + std::to_string(f) + " uses material " +
                                          std::to_string(m.desc.face_materials[f]) + " but the scene has " +
                                          std::to_string(s.materials.size()));
        } else if (m.desc.material >= std::max<std::size_t>(1, s.materials.size())) {
            throw InvalidArgument(at("mesh", mi) + ": material " + std::to_string(m.desc.material) + " does not exist");
        }
    }

    s.scene = rtcNewScene(s.device);
    s.top.clear();
    for (std::size_t mi = 0; mi < s.meshes.size(); ++mi) {
        MeshRecord& m = *s.meshes[mi];
        // The caller's arrays go to Embree as shared buffers: no copy (the padded copy only if needed).
        RTCGeometry tri = rtcNewGeometry(s.device, RTC_GEOMETRY_TYPE_TRIANGLE);
        rtcSetSharedGeometryBuffer(tri, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, m.vertex_data(), 0,
                                   3 * sizeof(float), m.desc.vertex_count);
        rtcSetSharedGeometryBuffer(tri, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, m.desc.indices, 0,
                                   3 * sizeof(std::uint32_t), m.desc.triangle_count);
        rtcCommitGeometry(tri);
        if (m.desc.object_to_world.is_identity()) {
            m.top_geom_id = rtcAttachGeometry(s.scene, tri);
        } else {
            // Instanced rather than transformed: a transformed copy would break the zero-copy contract, and an
            // instance lets a moved object keep its BVH.
            m.sub_scene = rtcNewScene(s.device);
            rtcAttachGeometry(m.sub_scene, tri);
            rtcCommitScene(m.sub_scene);
            RTCGeometry inst = rtcNewGeometry(s.device, RTC_GEOMETRY_TYPE_INSTANCE);
            rtcSetGeometryInstancedScene(inst, m.sub_scene);
            rtcSetGeometryTransform(inst, 0, RTC_FORMAT_FLOAT3X4_ROW_MAJOR, m.desc.object_to_world.m.data());
            rtcCommitGeometry(inst);
            m.top_geom_id = rtcAttachGeometry(s.scene, inst);
            rtcReleaseGeometry(inst);
        }
        rtcReleaseGeometry(tri);
        if (s.top.size() <= m.top_geom_id) s.top.resize(m.top_geom_id + 1);
        s.top[m.top_geom_id] = TopGeometry{TopGeometry::Mesh, std::uint32_t(mi)};
        s.check_device("building a mesh");
    }
    for (std::size_t gi = 0; gi < s.gaussians.size(); ++gi) {
        GaussianSet& g = *s.gaussians[gi];
        if (g.cloud->size() == 0) continue;
        g.prepare(mode);
        RTCGeometry geom = g.create_geometry(s.device);
        g.geom_id = rtcAttachGeometry(s.scene, geom);
        rtcReleaseGeometry(geom);
        if (s.top.size() <= g.geom_id) s.top.resize(g.geom_id + 1);
        s.top[g.geom_id] = TopGeometry{TopGeometry::Gaussians, std::uint32_t(gi)};
    }
    rtcCommitScene(s.scene);
    s.check_device("building the BVH");
    s.built = true;
    s.built_mode = mode;
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

std::size_t Scene::gaussian_count() const {
    std::size_t n = 0;
    for (const auto& g : impl_->gaussians) n += g->cloud->size();
    return n;
}
std::size_t Scene::mesh_count() const { return impl_->meshes.size(); }
std::size_t Scene::light_count() const { return impl_->lights.size(); }
std::size_t Scene::material_count() const { return impl_->materials.size(); }

}  // namespace raysplats
