// Scene internals shared by scene.cpp and renderer.cpp.
#pragma once

#include <algorithm>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include <embree3/rtcore.h>
#include <glm/glm.hpp>

#include "camera_splat_buffers.h"
#include "gaussian_primitives.h"
#include "raysplats/render/scene.h"

namespace raysplats {

struct TileState;  // (tile_sampler.h)

struct MeshRecord {
    MeshDesc desc;
    std::vector<float> padded_vertices;  // only when the caller's array is not padded (see MeshDesc)
    glm::mat3 linear{1.0f};
    glm::vec3 translation{0.0f};
    glm::mat3 normal_matrix{1.0f};  // inverse transpose of `linear`
    bool mirrored = false;          // negative determinant: the winding flips
    RTCScene sub_scene = nullptr;   // every mesh is instanced, so that moving or editing it rebuilds only its BVH
    unsigned top_geom_id = RTC_INVALID_GEOMETRY_ID;
    bool dirty = false;             // replaced by Scene::update_mesh since the last build
    // Scene::set_mesh_motion's matrices (empty: none), and their linear parts for the normals at a ray's time.
    std::vector<Matrix4> motion;
    std::vector<glm::mat3> motion_linear;
    // Scene::set_mesh_deformation's vertex positions, step after step, and one float more (Embree's 16-byte loads
    // at a step's last vertex read the next step's first or this padding); empty: none.
    std::vector<float> deformation;
    std::size_t deformation_steps = 0;
    FrameMotion frame_motion;  // Scene::set_mesh_frame_motion's (the Vector pass)
    // Scene::set_mesh_frame_deformation's vertices at the previous and the next frame (empty: none).
    std::vector<float> frame_previous, frame_next;
    // Scene::set_mesh_cryptomatte_names (kept by update_mesh): the object's and the asset's Cryptomatte ids.
    float cryptomatte_object = 0.0f, cryptomatte_asset = 0.0f;

    const float* vertex_data() const { return padded_vertices.empty() ? desc.vertices : padded_vertices.data(); }
    // Vertex `i` where a ray of shutter time `time` sees it (object space): with deformation, the linear
    // interpolation of the two nearest steps, as Embree interpolates a geometry's time steps; else the frame's.
    glm::vec3 vertex_at(std::uint32_t i, float time) const {
        if (deformation_steps < 2) {
            const float* v = vertex_data() + 3 * std::size_t(i);
            return {v[0], v[1], v[2]};
        }
        const float f = glm::clamp(time, 0.0f, 1.0f) * float(deformation_steps - 1);
        const std::size_t k = std::min(std::size_t(f), deformation_steps - 2);
        const float w = f - float(k);
        const float* a = deformation.data() + 3 * (k * desc.vertex_count + i);
        const float* b = a + 3 * desc.vertex_count;
        return (1.0f - w) * glm::vec3(a[0], a[1], a[2]) + w * glm::vec3(b[0], b[1], b[2]);
    }
    // The normal matrix where a ray of shutter time `time` sees the mesh: with motion, the inverse transpose of the
    // linear part Embree's linear interpolation of the two nearest steps gives; else normal_matrix.
    glm::mat3 normal_matrix_at(float time) const {
        if (motion_linear.empty()) return normal_matrix;
        const float f = glm::clamp(time, 0.0f, 1.0f) * float(motion_linear.size() - 1);
        const std::size_t k = std::min(std::size_t(f), motion_linear.size() - 2);
        const float w = f - float(k);
        return glm::transpose(glm::inverse((1.0f - w) * motion_linear[k] + w * motion_linear[k + 1]));
    }
};

// What a top-level geomID (always an instance) is: a mesh, or a chunk of a Gaussian set whose primitives start at
// `offset`.
struct TopGeometry {
    enum Kind { Mesh, Gaussians } kind;
    std::uint32_t index;
    std::uint32_t offset = 0;
};

struct Scene::Impl {
    RTCDevice device = nullptr;
    std::string embree_config;  // what rtcNewDevice was given
    RTCScene scene = nullptr;
    // The meshes alone, each instanced with the same geomID as in `scene`: the queries that ignore the Gaussians
    // (camera-ray splatting's mesh hits, the meshes' shadows on Gaussians) would otherwise descend into every Gaussian
    // chunk their rays cross and call its callback only to return.
    RTCScene mesh_scene = nullptr;
    std::string device_error;

    std::vector<Material> materials;
    std::vector<std::unique_ptr<MeshRecord>> meshes;
    std::vector<std::unique_ptr<GaussianSet>> gaussians;
    std::vector<Light> lights;
    World world;
    World world_default;

    bool interactive = false;
    std::uint32_t interactive_chunk_size = 1u << 18;
    Scene::BuildReport report;
    bool built = false;
    GaussianMode built_mode = GaussianMode::Flat;
    std::vector<TopGeometry> top;  // by top-level geomID
    // Camera-ray splatting's storage, kept from one frame's pre-pass for the next when keep_frame_buffers is set
    // (Scene::set_keep_frame_buffers); a pre-pass takes it while it renders and gives it back after.
    bool keep_frame_buffers = false;
    mutable std::mutex frame_buffers_mutex;
    mutable std::unique_ptr<CameraSplatBuffers> frame_buffers;
    // The last render's tiles (render(), under the same mutex), for the next render of the same region and passes
    // to sample into (TileState::restart).
    mutable std::vector<std::unique_ptr<TileState>> frame_tiles;

    // Whether some mesh or Gaussian cloud has motion (Scene::has_motion).
    bool has_motion() const;
    void release_scene();
    void build_all(GaussianMode mode);
    // Rebuilds what update_* marked; false when a change needs build_all (a Gaussian count changed).
    bool build_changes(GaussianMode mode);
    void check_device(const char* during);
};

}  // namespace raysplats
