// Embree scene construction (docs/design.md §6). Pattern of Embree's minimal tutorial: every geometry is created,
// committed, attached, then released (the scene holds the reference), and the scene committed last.
#include "raysplats/render/scene.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <iterator>
#include <string>

#include "core/linear_algebra.h"
#include "gaussian_callbacks.h"
#include "microfacet_tables.h"
#include "raysplats/errors.h"
#include "raysplats/render/cryptomatte.h"
#include "render_math.h"
#include "scene_impl.h"
#include "tile_sampler.h"

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
    if (mesh_scene) rtcReleaseScene(mesh_scene);
    mesh_scene = nullptr;
    for (auto& m : meshes) {
        if (m->sub_scene) rtcReleaseScene(m->sub_scene);
        m->sub_scene = nullptr;
    }
    for (auto& g : gaussians) {
        for (GaussianChunk& c : g->chunks)
            if (c.scene) rtcReleaseScene(c.scene);
        g->chunks.clear();
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

std::string default_embree_config() {
    const char* env = std::getenv("RAYSPLATS_EMBREE_CONFIG");
    return env ? std::string(env) : std::string();
}

Scene::Scene() : Scene(default_embree_config()) {}

namespace {

// Embree takes an instruction set name it does not know without complaint and runs its SSE2 kernels, so a typo in
// a test's configuration would quietly test the wrong path: the names of rtcNewDevice's documentation only.
void check_isa_names(const std::string& config) {
    static const char* const known[] = {"sse2", "sse4.2", "avx", "avx2", "avx512", "avx512knl", "avx512skx"};
    for (const char* key : {"isa=", "max_isa="}) {
        for (std::size_t at = config.find(key); at != std::string::npos; at = config.find(key, at + 1)) {
            if (at > 0 && config[at - 1] != ',' && config[at - 1] != ' ') continue;  // e.g. "max_isa=" inside "isa="
            const std::size_t begin = at + std::strlen(key);
            const std::string name = config.substr(begin, config.find_first_of(", ", begin) - begin);
            if (std::find(std::begin(known), std::end(known), name) == std::end(known))
                throw InvalidArgument("Embree configuration \"" + config + "\": unknown instruction set \"" + name +
                                      "\" (sse2, sse4.2, avx, avx2, avx512)");
        }
    }
}

}  // namespace

Scene::Scene(const std::string& embree_config) : impl_(new Impl) {
    check_isa_names(embree_config);
    impl_->embree_config = embree_config;
    // rtcNewDevice: null and an error code for a configuration it cannot honour (RTC_ERROR_UNSUPPORTED_CPU for an
    // instruction set the CPU lacks, RTC_ERROR_INVALID_ARGUMENT for a malformed string).
    impl_->device = rtcNewDevice(embree_config.empty() ? nullptr : embree_config.c_str());
    if (!impl_->device) {
        const int code = int(rtcGetDeviceError(nullptr));
        throw Error("cannot create the Embree device with configuration \"" + embree_config + "\" (Embree error " +
                    std::to_string(code) + (code == RTC_ERROR_UNSUPPORTED_CPU ? ": this CPU lacks that instruction set" : "") +
                    "; RAYSPLATS_EMBREE_CONFIG sets it)");
    }
    rtcSetDeviceErrorFunction(impl_->device, device_error_callback, impl_.get());
}

EmbreeDeviceInfo Scene::embree_device() const {
    EmbreeDeviceInfo info;
    info.config = impl_->embree_config;
    info.native_ray4 = rtcGetDeviceProperty(impl_->device, RTC_DEVICE_PROPERTY_NATIVE_RAY4_SUPPORTED) != 0;
    info.native_ray8 = rtcGetDeviceProperty(impl_->device, RTC_DEVICE_PROPERTY_NATIVE_RAY8_SUPPORTED) != 0;
    info.native_ray16 = rtcGetDeviceProperty(impl_->device, RTC_DEVICE_PROPERTY_NATIVE_RAY16_SUPPORTED) != 0;
    return info;
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

namespace {

// Validates a mesh description (naming it `name`) and makes its record.
std::unique_ptr<MeshRecord> make_mesh_record(const std::string& name, const MeshDesc& mesh) {
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
    return rec;
}

void validate_gaussians(const std::string& name, const GaussianCloud& cloud, const Matrix4& object_to_world) {
    cloud.check_consistent();
    object_to_world.check_affine((name + " object_to_world").c_str());
    if (cloud.size() >= 0xffffffffu) throw InvalidArgument(name + ": too many Gaussians");
    cloud.check_values(name);
}

// Places an instance: one transform, or with motion one per time step (Embree interpolates linearly between the two
// steps around a ray's time, the first at time 0 and the last at time 1).
void place_instance(RTCGeometry inst, const Matrix4& object_to_world, const std::vector<Matrix4>& motion) {
    if (motion.size() < 2) {
        rtcSetGeometryTimeStepCount(inst, 1);
        rtcSetGeometryTransform(inst, 0, RTC_FORMAT_FLOAT3X4_ROW_MAJOR, object_to_world.m.data());
        return;
    }
    rtcSetGeometryTimeStepCount(inst, unsigned(motion.size()));
    for (std::size_t k = 0; k < motion.size(); ++k)
        rtcSetGeometryTransform(inst, unsigned(k), RTC_FORMAT_FLOAT3X4_ROW_MAJOR, motion[k].m.data());
}

// Instances `sub` in `top` with an object-to-world matrix (or its motion); returns the instance's geomID. Every
// top-level geometry is such an instance (one level: RTC_MAX_INSTANCE_LEVEL_COUNT is 1 in Debian's Embree), so a
// hit's instID[0] names the mesh or Gaussian chunk, and the Gaussians' callbacks read it from their context
// (gaussian_callbacks.cpp). Embree hands user geometry inside an instance the ray in the instance's space at the
// ray's time, so a Gaussian chunk moves with its instance like a mesh.
// `id`: attach it with that geomID (RTC_INVALID_GEOMETRY_ID: the next free one).
unsigned attach_instance(RTCDevice device, RTCScene top, RTCScene sub, const Matrix4& object_to_world,
                         const std::vector<Matrix4>& motion, unsigned id = RTC_INVALID_GEOMETRY_ID) {
    RTCGeometry inst = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_INSTANCE);
    rtcSetGeometryInstancedScene(inst, sub);
    place_instance(inst, object_to_world, motion);
    rtcCommitGeometry(inst);
    if (id == RTC_INVALID_GEOMETRY_ID) id = rtcAttachGeometry(top, inst);
    else rtcAttachGeometryByID(top, inst, id);
    rtcReleaseGeometry(inst);
    return id;
}

void set_instance_transform(RTCScene top, unsigned id, const Matrix4& object_to_world,
                            const std::vector<Matrix4>& motion) {
    RTCGeometry inst = rtcGetGeometry(top, id);
    place_instance(inst, object_to_world, motion);
    rtcCommitGeometry(inst);
}

// Checks a motion's matrices (naming the object), and says whether they differ from `current`.
bool check_motion(const std::string& name, const std::vector<Matrix4>& steps, const std::vector<Matrix4>& current) {
    if (steps.size() > RTC_MAX_TIME_STEP_COUNT)
        throw InvalidArgument(name + ": " + std::to_string(steps.size()) + " motion steps (at most " +
                              std::to_string(RTC_MAX_TIME_STEP_COUNT) + ")");
    for (std::size_t k = 0; k < steps.size(); ++k)
        steps[k].check_affine((name + " motion step " + std::to_string(k)).c_str());
    const bool none = steps.size() < 2, had_none = current.size() < 2;
    if (none || had_none) return none != had_none;
    if (steps.size() != current.size()) return true;
    for (std::size_t k = 0; k < steps.size(); ++k)
        if (steps[k].m != current[k].m) return true;
    return false;
}

void set_triangle_buffers(RTCGeometry tri, const MeshRecord& m) {
    // The caller's arrays go to Embree as shared buffers: no copy (the padded copy only if needed). Embree's
    // contract for shared vertex buffers: readable with a 16-byte load at the last vertex, so 4 bytes past its end
    // (MeshDesc::vertices_padded); the buffers must outlive the geometry (the Scene's lifetime rule).
    if (m.deformation_steps >= 2) {
        // Deformation: one vertex buffer per time step (slot k = step k), which Embree interpolates linearly at a
        // ray's time, the first step at time 0 and the last at 1 (rtcSetGeometryTimeStepCount).
        rtcSetGeometryTimeStepCount(tri, unsigned(m.deformation_steps));
        for (std::size_t k = 0; k < m.deformation_steps; ++k)
            rtcSetSharedGeometryBuffer(tri, RTC_BUFFER_TYPE_VERTEX, unsigned(k), RTC_FORMAT_FLOAT3,
                                       m.deformation.data(), 3 * sizeof(float) * k * m.desc.vertex_count,
                                       3 * sizeof(float), m.desc.vertex_count);
    } else {
        rtcSetGeometryTimeStepCount(tri, 1);  // (Embree's default; an update may drop a deformation)
        rtcSetSharedGeometryBuffer(tri, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, m.vertex_data(), 0,
                                   3 * sizeof(float), m.desc.vertex_count);
    }
    rtcSetSharedGeometryBuffer(tri, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, m.desc.indices, 0,
                               3 * sizeof(std::uint32_t), m.desc.triangle_count);
}

}  // namespace

std::uint32_t Scene::add_mesh(const MeshDesc& mesh) {
    impl_->meshes.push_back(make_mesh_record(at("mesh", impl_->meshes.size()), mesh));
    impl_->built = false;
    return std::uint32_t(impl_->meshes.size() - 1);
}

void Scene::update_mesh(std::uint32_t index, const MeshDesc& mesh) {
    if (index >= impl_->meshes.size()) throw InvalidArgument(at("mesh", index) + " does not exist");
    auto rec = make_mesh_record(at("mesh", index), mesh);
    rec->sub_scene = impl_->meshes[index]->sub_scene;
    rec->motion = impl_->meshes[index]->motion;
    rec->motion_linear = impl_->meshes[index]->motion_linear;
    rec->top_geom_id = impl_->meshes[index]->top_geom_id;
    rec->dirty = true;
    rec->cryptomatte_object = impl_->meshes[index]->cryptomatte_object;
    rec->cryptomatte_asset = impl_->meshes[index]->cryptomatte_asset;
    impl_->meshes[index] = std::move(rec);
}

std::uint32_t Scene::add_gaussians(const GaussianCloud& cloud, const Matrix4& object_to_world) {
    validate_gaussians(at("Gaussian cloud", impl_->gaussians.size()), cloud, object_to_world);
    auto set = std::make_unique<GaussianSet>();
    set->index = std::uint32_t(impl_->gaussians.size());
    set->cloud = &cloud;
    set->set_transform(object_to_world);
    impl_->gaussians.push_back(std::move(set));
    impl_->built = false;
    return std::uint32_t(impl_->gaussians.size() - 1);
}

void Scene::update_gaussians(std::uint32_t index, const GaussianCloud& cloud, const Matrix4& object_to_world) {
    if (index >= impl_->gaussians.size()) throw InvalidArgument(at("Gaussian cloud", index) + " does not exist");
    validate_gaussians(at("Gaussian cloud", index), cloud, object_to_world);
    GaussianSet& set = *impl_->gaussians[index];
    set.cloud = &cloud;
    set.set_transform(object_to_world);
    set.frame_motion = FrameMotion{};
    set.deformation = GaussianSet::Deformation{};
    set.dirty = GaussianSet::Dirty::Data;
}

void Scene::gaussians_changed(std::uint32_t index, const std::uint32_t* rows, std::size_t count) {
    if (index >= impl_->gaussians.size()) throw InvalidArgument(at("Gaussian cloud", index) + " does not exist");
    GaussianSet& set = *impl_->gaussians[index];
    const std::string name = at("Gaussian cloud", index);
    const std::size_t n = set.cloud->size();
    for (std::size_t k = 0; k < count; ++k) {
        if (rows[k] >= n)
            throw InvalidArgument(name + ": changed Gaussian " + std::to_string(rows[k]) + " of " + std::to_string(n));
        set.cloud->check_values(name, rows[k], rows[k] + 1);
    }
    if (set.dirty == GaussianSet::Dirty::Data) return;  // every primitive is recomputed anyway
    set.dirty = GaussianSet::Dirty::Rows;
    set.changed_rows.insert(set.changed_rows.end(), rows, rows + count);
}

void Scene::set_gaussians_transform(std::uint32_t index, const Matrix4& object_to_world) {
    if (index >= impl_->gaussians.size()) throw InvalidArgument(at("Gaussian cloud", index) + " does not exist");
    object_to_world.check_affine((at("Gaussian cloud", index) + " object_to_world").c_str());
    GaussianSet& set = *impl_->gaussians[index];
    set.set_transform(object_to_world);
    set.frame_motion = FrameMotion{};
    if (set.dirty == GaussianSet::Dirty::None) set.dirty = GaussianSet::Dirty::Transform;
}

void Scene::set_gaussian_shading(std::uint32_t index, std::optional<GaussianShading> shading) {
    if (index >= impl_->gaussians.size()) throw InvalidArgument(at("Gaussian cloud", index) + " does not exist");
    impl_->gaussians[index]->shading = shading;
}

void Scene::set_gaussian_pass_indices(std::uint32_t index, std::uint32_t object_pass_index,
                                      std::uint32_t material_pass_index) {
    if (index >= impl_->gaussians.size()) throw InvalidArgument(at("Gaussian cloud", index) + " does not exist");
    impl_->gaussians[index]->object_pass_index = object_pass_index;
    impl_->gaussians[index]->material_pass_index = material_pass_index;
}

void Scene::set_mesh_motion(std::uint32_t index, const std::vector<Matrix4>& object_to_world_steps) {
    if (index >= impl_->meshes.size()) throw InvalidArgument(at("mesh", index) + " does not exist");
    MeshRecord& m = *impl_->meshes[index];
    if (!check_motion(at("mesh", index), object_to_world_steps, m.motion)) return;
    m.motion.clear();
    m.motion_linear.clear();
    if (object_to_world_steps.size() >= 2) {
        m.motion = object_to_world_steps;
        for (const Matrix4& step : m.motion) m.motion_linear.push_back(linear_part(step));
    }
    impl_->built = false;
}

void Scene::set_mesh_deformation(std::uint32_t index, const float* step_vertices, std::size_t step_count,
                                 std::size_t vertex_count) {
    if (index >= impl_->meshes.size()) throw InvalidArgument(at("mesh", index) + " does not exist");
    MeshRecord& m = *impl_->meshes[index];
    const std::string name = at("mesh", index);
    if (step_count > RTC_MAX_TIME_STEP_COUNT)
        throw InvalidArgument(name + ": " + std::to_string(step_count) + " deformation steps (at most " +
                              std::to_string(RTC_MAX_TIME_STEP_COUNT) + ")");
    if (step_count >= 2 && !step_vertices) throw InvalidArgument(name + ": the deformation's vertex array is null");
    if (step_count >= 2 && vertex_count != m.desc.vertex_count)
        throw InvalidArgument(name + ": a deformation of " + std::to_string(vertex_count) + " vertices (the mesh has " +
                              std::to_string(m.desc.vertex_count) + ")");
    const std::size_t values = step_count >= 2 ? 3 * step_count * m.desc.vertex_count : 0;
    for (std::size_t i = 0; i < values; ++i)
        if (!std::isfinite(step_vertices[i]))
            throw InvalidArgument(name + ": deformation step " + std::to_string(i / (3 * m.desc.vertex_count)) +
                                  " vertex " + std::to_string(i / 3 % m.desc.vertex_count) +
                                  " has a NaN or Inf coordinate");
    if (values == 0 && m.deformation_steps < 2) return;
    if (values != 0 && step_count == m.deformation_steps &&
        std::equal(step_vertices, step_vertices + values, m.deformation.begin()))
        return;
    m.deformation.clear();
    m.deformation_steps = 0;
    if (values != 0) {
        m.deformation.assign(step_vertices, step_vertices + values);
        m.deformation.push_back(0.0f);
        m.deformation_steps = step_count;
    }
    impl_->built = false;
}

namespace {

// One Gaussian is the same for any order and signs of its axes (its scales taken in that order), and recovery may
// name a Gaussian's axes differently at two steps (exactly at its imported polygon, by moments elsewhere). Rewrites
// rotation `q` (unit, w x y z) and `scales` to the order and signs of the axes nearest those of the previous step's
// rotation `previous`, as a proper rotation, so that interpolating between the steps turns each axis the short way
// and keeps each scale on its axis.
void align_axes(const float* previous, glm::vec4& q, float* scales) {
    const la::Mat3 before = la::quaternion_to_matrix(previous[0], previous[1], previous[2], previous[3]);
    const la::Mat3 now = la::quaternion_to_matrix(q[0], q[1], q[2], q[3]);
    static const int orders[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
    int best = 0;
    double best_match = -1.0;
    for (int o = 0; o < 6; ++o) {
        double match = 0.0;
        for (int j = 0; j < 3; ++j) match += std::abs(la::dot(before.column(j), now.column(orders[o][j])));
        if (match > best_match) best_match = match, best = o;
    }
    la::Mat3 aligned;
    int weakest = 0;
    double weakest_dot = 2.0;
    for (int j = 0; j < 3; ++j) {
        const la::Vec3 axis = now.column(orders[best][j]);
        const double along = la::dot(before.column(j), axis);
        aligned.set_column(j, along < 0.0 ? -axis : axis);
        if (std::abs(along) < weakest_dot) weakest_dot = std::abs(along), weakest = j;
    }
    if (la::determinant(aligned) < 0.0) aligned.set_column(weakest, -aligned.column(weakest));
    double aligned_q[4];
    la::matrix_to_quaternion(aligned, aligned_q);
    q = glm::vec4(float(aligned_q[0]), float(aligned_q[1]), float(aligned_q[2]), float(aligned_q[3]));
    const float s[3] = {scales[0], scales[1], scales[2]};
    for (int j = 0; j < 3; ++j) scales[j] = s[orders[best][j]];
}

}  // namespace

void Scene::set_gaussians_deformation(std::uint32_t index, std::size_t step_count, const float* positions,
                                      const float* rotations, const float* scales, std::size_t gaussian_count) {
    if (index >= impl_->gaussians.size()) throw InvalidArgument(at("Gaussian cloud", index) + " does not exist");
    GaussianSet& set = *impl_->gaussians[index];
    const std::string name = at("Gaussian cloud", index);
    const std::size_t n = set.cloud->size();
    if (step_count > RTC_MAX_TIME_STEP_COUNT)
        throw InvalidArgument(name + ": " + std::to_string(step_count) + " deformation steps (at most " +
                              std::to_string(RTC_MAX_TIME_STEP_COUNT) + ")");
    GaussianSet::Deformation d;
    if (step_count >= 2) {
        if (!positions || !rotations || !scales) throw InvalidArgument(name + ": a deformation array is null");
        if (gaussian_count != n)
            throw InvalidArgument(name + ": a deformation of " + std::to_string(gaussian_count) +
                                  " Gaussians (the cloud has " + std::to_string(n) + ")");
        d.steps = step_count;
        d.positions.assign(positions, positions + 3 * step_count * n);
        d.scales.assign(scales, scales + 3 * step_count * n);
        d.rotations.resize(4 * step_count * n);
        for (std::size_t k = 0; k < step_count; ++k)
            for (std::size_t i = 0; i < n; ++i) {
                const std::size_t at_step = k * n + i;
                auto fail = [&](const char* what) {
                    throw InvalidArgument(name + ": deformation step " + std::to_string(k) + " Gaussian " +
                                          std::to_string(i) + " " + what);
                };
                for (int a = 0; a < 3; ++a) {
                    if (!std::isfinite(d.positions[3 * at_step + a]) || !std::isfinite(d.scales[3 * at_step + a]))
                        fail("has a NaN or Inf position or scale");
                    if (d.scales[3 * at_step + a] < 0.0f) fail("has a negative scale");
                }
                glm::vec4 q(rotations[4 * at_step], rotations[4 * at_step + 1], rotations[4 * at_step + 2],
                            rotations[4 * at_step + 3]);
                const float length = glm::length(q);
                if (!std::isfinite(length) || length == 0.0f) fail("has a zero, NaN or Inf rotation");
                q /= length;
                if (k > 0) {
                    const float* p = &d.rotations[4 * (at_step - n)];
                    align_axes(p, q, &d.scales[3 * at_step]);
                    // q and -q are one rotation: the one nearer the previous step's, so that interpolating between
                    // them turns the short way (GaussianSet::deformed_group).
                    if (p[0] * q[0] + p[1] * q[1] + p[2] * q[2] + p[3] * q[3] < 0.0f) q = -q;
                }
                for (int a = 0; a < 4; ++a) d.rotations[4 * at_step + a] = q[a];
            }
    }
    if (d.steps == set.deformation.steps && d.positions == set.deformation.positions &&
        d.rotations == set.deformation.rotations && d.scales == set.deformation.scales)
        return;
    set.deformation = std::move(d);
    impl_->built = false;
}

void Scene::set_gaussians_motion(std::uint32_t index, const std::vector<Matrix4>& object_to_world_steps) {
    if (index >= impl_->gaussians.size()) throw InvalidArgument(at("Gaussian cloud", index) + " does not exist");
    GaussianSet& set = *impl_->gaussians[index];
    if (!check_motion(at("Gaussian cloud", index), object_to_world_steps, set.motion)) return;
    set.motion.clear();
    if (object_to_world_steps.size() >= 2) set.motion = object_to_world_steps;
    impl_->built = false;
}

void Scene::set_mesh_frame_motion(std::uint32_t index, const Matrix4& previous, const Matrix4& next) {
    if (index >= impl_->meshes.size()) throw InvalidArgument(at("mesh", index) + " does not exist");
    previous.check_affine((at("mesh", index) + " previous frame's matrix").c_str());
    next.check_affine((at("mesh", index) + " next frame's matrix").c_str());
    MeshRecord& m = *impl_->meshes[index];
    m.frame_motion = FrameMotion::between(m.desc.object_to_world, previous, next);
}

void Scene::set_mesh_frame_deformation(std::uint32_t index, const float* previous, const float* next,
                                       std::size_t vertex_count) {
    if (index >= impl_->meshes.size()) throw InvalidArgument(at("mesh", index) + " does not exist");
    MeshRecord& m = *impl_->meshes[index];
    const std::string name = at("mesh", index);
    if (!previous || !next) {
        m.frame_previous.clear();
        m.frame_next.clear();
        return;
    }
    if (vertex_count != m.desc.vertex_count)
        throw InvalidArgument(name + ": a frame deformation of " + std::to_string(vertex_count) +
                              " vertices (the mesh has " + std::to_string(m.desc.vertex_count) + ")");
    for (std::size_t i = 0; i < 3 * vertex_count; ++i)
        if (!std::isfinite(previous[i]) || !std::isfinite(next[i]))
            throw InvalidArgument(name + ": frame deformation vertex " + std::to_string(i / 3) +
                                  " has a NaN or Inf coordinate");
    m.frame_previous.assign(previous, previous + 3 * vertex_count);
    m.frame_next.assign(next, next + 3 * vertex_count);
}

void Scene::set_gaussians_frame_motion(std::uint32_t index, const Matrix4& previous, const Matrix4& next) {
    if (index >= impl_->gaussians.size()) throw InvalidArgument(at("Gaussian cloud", index) + " does not exist");
    previous.check_affine((at("Gaussian cloud", index) + " previous frame's matrix").c_str());
    next.check_affine((at("Gaussian cloud", index) + " next frame's matrix").c_str());
    GaussianSet& set = *impl_->gaussians[index];
    set.frame_motion = FrameMotion::between(set.object_to_world, previous, next);
}

bool Scene::Impl::has_motion() const {
    return std::any_of(meshes.begin(), meshes.end(),
                       [](const auto& m) { return !m->motion.empty() || m->deformation_steps >= 2; }) ||
           std::any_of(gaussians.begin(), gaussians.end(),
                       [](const auto& g) { return !g->motion.empty() || g->deformation.steps >= 2; });
}

bool Scene::has_motion() const { return impl_->has_motion(); }

namespace {

// A name's Cryptomatte id; "" has none.
float cryptomatte_id_or_none(std::string_view name) { return name.empty() ? 0.0f : cryptomatte_id_of(name); }

}  // namespace

void Scene::set_gaussian_cryptomatte_names(std::uint32_t index, std::string_view object, std::string_view material,
                                           std::string_view asset) {
    if (index >= impl_->gaussians.size()) throw InvalidArgument(at("Gaussian cloud", index) + " does not exist");
    impl_->gaussians[index]->cryptomatte_ids = {cryptomatte_id_or_none(object), cryptomatte_id_or_none(material),
                                                cryptomatte_id_or_none(asset)};
}

void Scene::set_mesh_cryptomatte_names(std::uint32_t index, std::string_view object, std::string_view asset) {
    if (index >= impl_->meshes.size()) throw InvalidArgument(at("mesh", index) + " does not exist");
    impl_->meshes[index]->cryptomatte_object = cryptomatte_id_or_none(object);
    impl_->meshes[index]->cryptomatte_asset = cryptomatte_id_or_none(asset);
}

void Scene::set_material_cryptomatte_name(std::uint32_t index, std::string_view material) {
    if (index >= impl_->materials.size()) throw InvalidArgument(at("material", index) + " does not exist");
    impl_->materials[index].cryptomatte_id = cryptomatte_id_or_none(material);
}

void Scene::set_gaussian_holdout(std::uint32_t index, bool holdout) {
    if (index >= impl_->gaussians.size()) throw InvalidArgument(at("Gaussian cloud", index) + " does not exist");
    impl_->gaussians[index]->holdout = holdout;
}

std::uint32_t Scene::add_light(const Light& light) {
    light.validate(("light " + std::to_string(impl_->lights.size())).c_str());
    impl_->lights.push_back(light);
    return std::uint32_t(impl_->lights.size() - 1);
}

void Scene::set_world(const World& world) {
    for (float v : {world.color[0], world.color[1], world.color[2], world.strength})
        if (!std::isfinite(v) || v < 0.0f) throw InvalidArgument("world: colour and strength must be finite and >= 0");
    for (float v : {world.mist_start, world.mist_depth})
        if (!std::isfinite(v) || v < 0.0f) throw InvalidArgument("world: mist start and depth must be finite and >= 0");
    if (!std::isfinite(world.mist_falloff) || world.mist_falloff <= 0.0f)
        throw InvalidArgument("world: mist falloff must be finite and > 0");
    impl_->world = world;
}

namespace {

void check_materials(const Scene::Impl& s) {
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
}

}  // namespace

void Scene::Impl::build_all(GaussianMode mode) {
    release_scene();
    report = Scene::BuildReport{true, 0, 0};
    scene = rtcNewScene(device);
    mesh_scene = rtcNewScene(device);
    top.clear();
    auto record_top = [&](unsigned id, TopGeometry what) {
        if (top.size() <= id) top.resize(id + 1);
        top[id] = what;
    };
    for (std::size_t mi = 0; mi < meshes.size(); ++mi) {
        MeshRecord& m = *meshes[mi];
        // Instanced rather than transformed: a transformed copy would break the zero-copy contract, and an instance
        // lets a moved object keep its BVH.
        RTCGeometry tri = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
        set_triangle_buffers(tri, m);
        rtcCommitGeometry(tri);
        m.sub_scene = rtcNewScene(device);
        rtcAttachGeometry(m.sub_scene, tri);
        rtcReleaseGeometry(tri);
        rtcCommitScene(m.sub_scene);
        m.top_geom_id = attach_instance(device, scene, m.sub_scene, m.desc.object_to_world, m.motion);
        attach_instance(device, mesh_scene, m.sub_scene, m.desc.object_to_world, m.motion, m.top_geom_id);
        m.dirty = false;
        ++report.meshes;
        record_top(m.top_geom_id, TopGeometry{TopGeometry::Mesh, std::uint32_t(mi)});
        check_device("building a mesh");
    }
    for (std::size_t gi = 0; gi < gaussians.size(); ++gi) {
        GaussianSet& g = *gaussians[gi];
        g.dirty = GaussianSet::Dirty::None;
        g.changed_rows.clear();
        g.chunks.clear();
        const std::size_t n = g.cloud->size();
        if (n == 0) continue;
        g.chunk_size = interactive ? interactive_chunk_size : 0xffffffffu;
        g.prepare(mode, false);
        // Chunk records are the geometries' user data: sized once, before any geometry points at them.
        g.chunks.resize((n + g.chunk_size - 1) / g.chunk_size);
        for (std::size_t k = 0; k < g.chunks.size(); ++k) {
            GaussianChunk& c = g.chunks[k];
            c.set = &g;
            c.offset = std::uint32_t(k * g.chunk_size);
            c.count = std::uint32_t(std::min<std::size_t>(g.chunk_size, n - c.offset));
            c.scene = rtcNewScene(device);
            c.geometry = create_gaussian_geometry(device, c);
            rtcAttachGeometry(c.scene, c.geometry);
            rtcReleaseGeometry(c.geometry);  // the chunk's scene holds it
            rtcCommitScene(c.scene);
            c.instance_id = attach_instance(device, scene, c.scene, g.object_to_world, g.motion);
            record_top(c.instance_id, TopGeometry{TopGeometry::Gaussians, std::uint32_t(gi), c.offset});
            ++report.gaussian_chunks;
        }
        check_device("building Gaussians");
    }
    rtcCommitScene(scene);
    rtcCommitScene(mesh_scene);
    check_device("building the BVH");
}

bool Scene::Impl::build_changes(GaussianMode mode) {
    for (const auto& g : gaussians)
        if (g->dirty == GaussianSet::Dirty::Data && g->cloud->size() != g->prims.size()) return false;
    report = Scene::BuildReport{};
    for (auto& mp : meshes) {
        MeshRecord& m = *mp;
        if (!m.dirty) continue;
        RTCGeometry tri = rtcGetGeometry(m.sub_scene, 0);
        set_triangle_buffers(tri, m);
        rtcCommitGeometry(tri);
        rtcCommitScene(m.sub_scene);
        set_instance_transform(scene, m.top_geom_id, m.desc.object_to_world, m.motion);
        set_instance_transform(mesh_scene, m.top_geom_id, m.desc.object_to_world, m.motion);
        m.dirty = false;
        ++report.meshes;
    }
    for (auto& gp : gaussians) {
        GaussianSet& g = *gp;
        if (g.dirty == GaussianSet::Dirty::Data || g.dirty == GaussianSet::Dirty::Rows) {
            // New data keeps the primitives' order only in an interactive scene, where it spares the chunks whose
            // Gaussians did not change; a scene of one chunk per cloud rebuilds it anyway, and ordering it afresh
            // makes it the very scene build_all would make (the same groups, so the same image to the last bit).
            const std::vector<char> changed = g.dirty == GaussianSet::Dirty::Data ? g.prepare(mode, interactive)
                                                                                  : g.prepare_rows(g.changed_rows);
            for (std::size_t k = 0; k < g.chunks.size(); ++k) {
                if (!changed[k]) continue;
                g.update_geometry(g.chunks[k]);  // regrouped; the chunk's BVH is rebuilt
                rtcCommitScene(g.chunks[k].scene);
                ++report.gaussian_chunks;
            }
        }
        if (g.dirty != GaussianSet::Dirty::None)
            for (const GaussianChunk& c : g.chunks)
                set_instance_transform(scene, c.instance_id, g.object_to_world, g.motion);
        g.dirty = GaussianSet::Dirty::None;
        g.changed_rows.clear();
    }
    rtcCommitScene(scene);
    rtcCommitScene(mesh_scene);
    check_device("updating the BVH");
    return true;
}

double Scene::build(GaussianMode mode) {
    Impl& s = *impl_;
    const bool changes =
        std::any_of(s.gaussians.begin(), s.gaussians.end(), [](const auto& g) { return g->dirty != GaussianSet::Dirty::None; }) ||
        std::any_of(s.meshes.begin(), s.meshes.end(), [](const auto& m) { return m->dirty; });
    // Nothing to do: nothing written either (the report stays that of the last build that did something), so that
    // the render jobs of a SharedScene may all call build() on the built scene at once.
    if (s.built && s.built_mode == mode && !changes) return 0.0;
    const auto start = std::chrono::steady_clock::now();
    check_materials(s);
    if (!(s.built && s.built_mode == mode && s.build_changes(mode))) s.build_all(mode);
    s.built = true;
    s.built_mode = mode;
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// Chunks are separate instances whose boxes overlap, so a chunked frame costs somewhat more than one chunk's
// (docs/benchmarks.md), while an edit rebuilds one 2^18 chunk instead of the whole cloud.
void Scene::set_interactive(bool interactive, std::uint32_t chunk_size) {
    if (chunk_size == 0) throw InvalidArgument("interactive chunk size must be at least 1");
    if (impl_->interactive != interactive || impl_->interactive_chunk_size != chunk_size) impl_->built = false;
    impl_->interactive = interactive;
    impl_->interactive_chunk_size = chunk_size;
}

void Scene::set_keep_frame_buffers(bool keep) {
    impl_->keep_frame_buffers = keep;
    if (keep) return;
    const std::lock_guard<std::mutex> lock(impl_->frame_buffers_mutex);
    impl_->frame_buffers.reset();
    impl_->frame_tiles.clear();
}

std::size_t Scene::kept_frame_buffer_bytes() const {
    const std::lock_guard<std::mutex> lock(impl_->frame_buffers_mutex);
    std::size_t bytes = impl_->frame_buffers ? impl_->frame_buffers->capacity_bytes() : 0;
    for (const std::unique_ptr<TileState>& tile : impl_->frame_tiles)
        if (tile) bytes += tile->capacity_bytes();
    return bytes;
}

Scene::BuildReport Scene::last_build() const { return impl_->report; }

std::size_t Scene::gaussian_count() const {
    std::size_t n = 0;
    for (const auto& g : impl_->gaussians) n += g->cloud->size();
    return n;
}
std::size_t Scene::mesh_count() const { return impl_->meshes.size(); }
std::size_t Scene::light_count() const { return impl_->lights.size(); }
std::size_t Scene::material_count() const { return impl_->materials.size(); }

}  // namespace raysplats
