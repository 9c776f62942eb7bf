// Scene internals shared by scene.cpp and renderer.cpp.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include <embree3/rtcore.h>
#include <glm/glm.hpp>

#include "gaussian_geometry.h"
#include "raysplats/render/scene.h"

namespace raysplats {

struct MeshRecord {
    MeshDesc desc;
    std::vector<float> padded_vertices;  // only when the caller's array is not padded (see MeshDesc)
    glm::mat3 linear{1.0f};
    glm::vec3 translation{0.0f};
    glm::mat3 normal_matrix{1.0f};  // inverse transpose of `linear`
    bool mirrored = false;          // negative determinant: the winding flips
    RTCScene sub_scene = nullptr;   // when instanced
    unsigned top_geom_id = RTC_INVALID_GEOMETRY_ID;

    const float* vertex_data() const { return padded_vertices.empty() ? desc.vertices : padded_vertices.data(); }
};

struct TopGeometry {
    enum Kind { Mesh, Gaussians } kind;
    std::uint32_t index;
};

struct Scene::Impl {
    RTCDevice device = nullptr;
    RTCScene scene = nullptr;
    std::string device_error;

    std::vector<Material> materials;
    std::vector<std::unique_ptr<MeshRecord>> meshes;
    std::vector<std::unique_ptr<GaussianSet>> gaussians;
    std::vector<Light> lights;
    World world;
    World world_default;

    bool built = false;
    GaussianMode built_mode = GaussianMode::Flat;
    std::vector<TopGeometry> top;  // by top-level geomID

    void release_scene();
    void check_device(const char* during);
};

}  // namespace raysplats
