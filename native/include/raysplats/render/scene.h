// The scene the renderer traces (docs/design.md §6): Gaussian clouds, triangle meshes, materials, lights and the world,
// in one Embree 3 BVH. Meshes are instanced so that the caller's arrays are shared with Embree without copies
// (Mitsuba's scene_embree.inl pattern); Gaussians are Embree user geometry with the exact ray tests of
// gaussian_callbacks.cpp.
//
// Lifetime: a Scene keeps POINTERS to the caller's mesh arrays, textures and Gaussian clouds. They must stay
// alive and unchanged until the Scene is destroyed (numpy arrays held by the binding, for example).
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "raysplats/gaussian_cloud.h"
#include "raysplats/render/light.h"
#include "raysplats/render/material.h"
#include "raysplats/render/transform.h"

namespace raysplats {

enum class GaussianMode {
    Flat,        // disk in the plane of the two largest axes, evaluated exactly at the ray-plane hit
    Volumetric,  // ellipsoid, response at the point of maximum response along the ray (3DGRT)
};

// How a Gaussian's colour is produced (src/render/gaussian_shading.h has the model).
enum class GaussianShading {
    Baked,          // its captured (SH) radiance, as trained
    Lit,            // a two-sided Lambertian surface element (albedo: its colour, delit) shaded by lights and world
    BakedShadowed,  // its captured radiance times the lights' visibility (shadows of meshes and Gaussians)
};

// A triangle mesh handed over without copies. All arrays are the caller's.
struct MeshDesc {
    const float* vertices = nullptr;  // vertex_count * 3 floats (x y z), object space
    std::size_t vertex_count = 0;
    // Embree reads vertices with 16-byte loads, so the array must be readable one float past its end. Set this
    // when the caller allocated 3 * vertex_count + 1 floats: the array is then shared. Otherwise the Scene makes
    // one padded copy of the vertices (the only copy it ever makes of mesh data).
    bool vertices_padded = false;
    const std::uint32_t* indices = nullptr;  // triangle_count * 3, counter-clockwise = front
    std::size_t triangle_count = 0;
    const float* normals = nullptr;                 // optional, vertex_count * 3 (object space)
    const float* uvs = nullptr;                     // optional, vertex_count * 2
    const std::uint32_t* face_materials = nullptr;  // optional, triangle_count indices into the scene's materials
    std::uint32_t material = 0;                     // material of every face when face_materials is null
    Matrix4 object_to_world;
    // The object's pass index (Blender's Object.pass_index), which the Object Index pass shows.
    std::uint32_t pass_index = 0;
    // Blender's Holdout (the object's, or its collection's in the view layer), as Cycles renders it
    // (kernel/integrator/shade_surface.h): where a camera ray (or its continuation through transparency) meets the
    // mesh, the path ends with zero colour and the transmittance left joins the pixel's held-out fraction, which
    // Combined's alpha loses (SampleRecord::holdout). Other rays see the mesh as usual.
    bool holdout = false;
    // Blender's Shadow Catcher (Object.is_shadow_catcher): where a camera ray meets the mesh it shows only the
    // shadows the lights cast on it, as Cycles' shadow catcher (kernel/film/read.h): with r the ratio of the lights'
    // direct light at the point with visibility to that without (per channel; 1 where no light reaches it) and T the
    // transmittance in front, the Shadow Catcher pass is 1 - T (1 - r) (SampleRecord::shadow_catcher); Combined
    // leaves the mesh transparent when that pass is written (RenderSettings::shadow_catcher_pass), else gets alpha
    // T (1 - mean(r)) and no colour with a transparent background, the world's colour times T mean(r) otherwise.
    // Other rays see the mesh as usual.
    bool shadow_catcher = false;
};

// The Embree device a Scene traces with. Embree picks its kernels (packet width, ray order in callbacks, the
// rounding of triangle distances) by the instruction set it runs, so the same scene renders through different code
// on different CPUs; the tests force the instruction sets users have with `config`.
struct EmbreeDeviceInfo {
    std::string config;          // the configuration string given to rtcNewDevice ("" = Embree's defaults)
    bool native_ray4 = false;    // RTC_DEVICE_PROPERTY_NATIVE_RAY4/8/16_SUPPORTED: packets of that width reach the
    bool native_ray8 = false;    // callbacks as they were sent; a narrower native width means rtcIntersect16 goes
    bool native_ray16 = false;   // through Embree's ray stream filter, which splits and reorders the packet
};

// The configuration a Scene gets when none is given: the environment variable RAYSPLATS_EMBREE_CONFIG (e.g.
// "isa=sse4.2", "isa=avx2"; Embree's device configuration syntax), or "" for Embree's defaults.
std::string default_embree_config();

class Scene {
public:
    // `embree_config`: rtcNewDevice's configuration string; none = default_embree_config(). Throws Error naming the
    // configuration when Embree refuses it (an unknown option, an instruction set this CPU lacks).
    Scene();
    explicit Scene(const std::string& embree_config);
    EmbreeDeviceInfo embree_device() const;
    ~Scene();
    Scene(const Scene&) = delete;
    Scene& operator=(const Scene&) = delete;

    // Each returns the index of what it added. Every input is validated (NaN/Inf, out-of-range indices,
    // sizes); problems throw InvalidArgument naming the element.
    std::uint32_t add_material(const Material& material);
    std::uint32_t add_mesh(const MeshDesc& mesh);
    // `cloud` is kept by pointer (see Lifetime above). SH coefficients are in the cloud's frame: view
    // directions are mapped into it by the inverse of the matrix's linear part (nothing to do for the
    // identity, the add-on's world-space clouds).
    std::uint32_t add_gaussians(const GaussianCloud& cloud, const Matrix4& object_to_world = Matrix4{});
    std::uint32_t add_light(const Light& light);

    // Interactive updates (the viewport): each replaces what an add_* call gave, keeping its index, with the same
    // validation. The next build() then redoes only what changed: the Gaussian chunks whose primitives differ (the
    // same count; another count rebuilds everything), the instance transforms of moved objects, the BVH of an
    // edited mesh. The lifetime rule above applies to the new data; the old may be released after this returns.
    void update_gaussians(std::uint32_t index, const GaussianCloud& cloud, const Matrix4& object_to_world);
    // The caller changed Gaussians `rows[0..count)` of cloud `index` in place (the cloud given to add_gaussians or
    // update_gaussians; same count): the next build recomputes only their primitives and rebuilds only the chunks
    // that hold them. Their values are validated here.
    void gaussians_changed(std::uint32_t index, const std::uint32_t* rows, std::size_t count);
    // Moves Gaussian cloud `index` without new data: the next build rewrites only instance transforms.
    void set_gaussians_transform(std::uint32_t index, const Matrix4& object_to_world);
    void update_mesh(std::uint32_t index, const MeshDesc& mesh);
    // Gaussian cloud `index`'s own shading, or none to follow RenderSettings::gaussian_shading (the default). No
    // rebuild is needed.
    void set_gaussian_shading(std::uint32_t index, std::optional<GaussianShading> shading);
    // What the Object Index and Material Index passes show where Gaussian cloud `index` is the surface (film.h,
    // SampleRecord): its object's pass index and the material pass index the caller gives its Gaussians (Gaussians
    // have no material of their own; the add-on gives its object's first material's). Both 0 until set. No rebuild
    // is needed.
    void set_gaussian_pass_indices(std::uint32_t index, std::uint32_t object_pass_index,
                                   std::uint32_t material_pass_index);
    // Motion blur: the object-to-world matrices of mesh or Gaussian cloud `index` at equally spaced times across the
    // shutter, from its opening (the first) to its closing (the last), at most 129 (Embree's limit). A ray of time
    // t in [0, 1] (a camera ray draws it) sees the object where Embree places its instance, interpolating the two
    // nearest matrices linearly (rtcSetGeometryTransform per time step); shading uses the same interpolation for a
    // mesh's normals and the frame's matrix (the object_to_world of add_* / update_*) for a Gaussian's view
    // direction and normal. Empty (or one matrix): no motion, the object stays where object_to_world puts it.
    // Validated as object_to_world; a change of motion makes the next build a full one.
    void set_mesh_motion(std::uint32_t index, const std::vector<Matrix4>& object_to_world_steps);
    void set_gaussians_motion(std::uint32_t index, const std::vector<Matrix4>& object_to_world_steps);
    // Deformation blur: mesh `index`'s vertex positions (object space, as MeshDesc::vertices) at `step_count` equally
    // spaced times across the shutter, from its opening to its closing (step_count * vertex_count * 3 floats, step
    // after step; copied; vertex_count must be the mesh's). A ray of time t sees each vertex where Embree's linear interpolation of the two nearest
    // steps puts it (rtcSetGeometryTimeStepCount on the triangles, one vertex buffer per step), inside the
    // object's own motion (set_mesh_motion), and shading interpolates the triangle the same way (its geometric
    // normal; MeshDesc::normals stay the frame's). step_count 0 (or 1): none, the frame's vertices. At most 129
    // steps; a NaN or Inf position is an InvalidArgument. A change makes the next build a full one; update_mesh
    // drops it.
    void set_mesh_deformation(std::uint32_t index, const float* step_vertices, std::size_t step_count,
                              std::size_t vertex_count);
    // Deformation blur of Gaussian cloud `index`: its Gaussians (in the cloud's order and frame, gaussian_count of
    // them, the cloud's count) at `step_count` equally spaced times across the shutter, step after step: centres
    // (3 floats each), rotations (quaternions w x y z, 4) and scales (3); copied. A ray of time t sees each Gaussian
    // interpolated between the two steps around t (centre and scales linearly, rotation by normalised linear
    // interpolation), inside the cloud's own motion (set_gaussians_motion); its opacity and colours, and what
    // shading takes from it (view direction, normal, shadow origin), stay the cloud's. step_count 0 (or 1): none. At
    // most 129 steps; NaN or Inf, a negative scale or a zero quaternion is an InvalidArgument. A change makes the
    // next build a full one; update_gaussians drops it.
    void set_gaussians_deformation(std::uint32_t index, std::size_t step_count, const float* positions,
                                   const float* rotations, const float* scales, std::size_t gaussian_count);
    // The Vector pass: where mesh or Gaussian cloud `index` was at the previous frame and will be at the next (its
    // object_to_world then), for the motion of its surface points (film.h, SampleRecord::vector); an object without
    // them is still. Forgotten when the object's matrix or data is replaced (update_*, set_gaussians_transform). No
    // rebuild is needed.
    void set_mesh_frame_motion(std::uint32_t index, const Matrix4& previous, const Matrix4& next);
    // The Vector pass of a deforming mesh: its vertex positions (object space, vertex_count * 3 floats each, copied;
    // vertex_count must be the mesh's) at the previous and at the next frame, placed by set_mesh_frame_motion's
    // matrices (the frame's object_to_world without them): a surface point moves as the point of the same triangle
    // and barycentric coordinates does, as Cycles' motion pass takes a deforming mesh's vertex motion. Null: none
    // (the object's matrices alone). NaN or Inf is an InvalidArgument; update_mesh drops them.
    void set_mesh_frame_deformation(std::uint32_t index, const float* previous, const float* next,
                                    std::size_t vertex_count);
    void set_gaussians_frame_motion(std::uint32_t index, const Matrix4& previous, const Matrix4& next);
    // Whether some object has motion (set_*_motion with two matrices or more, set_*_deformation with two steps or
    // more).
    bool has_motion() const;
    // The names whose ids the Cryptomatte passes give (raysplats/render/cryptomatte.h; "" gives none): Gaussian cloud
    // `index`'s object, the material its Gaussians count as (the add-on gives its object's first material, as for the
    // Material Index pass) and its asset (Cycles: the object's top-level parent, else the object itself); a mesh's
    // object and asset (its faces' materials give theirs); a material's. None until set. No rebuild is needed.
    void set_gaussian_cryptomatte_names(std::uint32_t index, std::string_view object, std::string_view material,
                                        std::string_view asset);
    void set_mesh_cryptomatte_names(std::uint32_t index, std::string_view object, std::string_view asset);
    void set_material_cryptomatte_name(std::uint32_t index, std::string_view material);
    // Gaussian cloud `index` held out (Blender's Holdout; MeshDesc::holdout): along camera rays each of its Gaussians
    // adds no colour and holds out its weight T_i a_i, the coverage it would have given the pixel. Off until set. No
    // rebuild is needed.
    void set_gaussian_holdout(std::uint32_t index, bool holdout);
    // Interactive scenes split Gaussian clouds into chunks (2^18 Gaussians), so that an edit rebuilds only the
    // chunks it touched, at a small cost in render speed; others keep each cloud whole (the default, for final
    // renders).
    void set_interactive(bool interactive, std::uint32_t chunk_size = 1u << 18);
    // Whether the scene keeps the storage of its last frame's camera-ray splatting (the splats in depth order, their
    // tile lists and the pre-pass's working arrays: 60 bytes per Gaussian of the scene, 65 more per Gaussian in view
    // and 4 per tile entry) for the next frame, which then writes into memory already mapped instead of faulting in
    // fresh pages. For a scene rendered frame after frame (Persistent Data, the viewport); off by default, and turning
    // it off frees what is kept. The images are the same either way.
    void set_keep_frame_buffers(bool keep);
    // Bytes kept that way (0 when nothing is).
    std::size_t kept_frame_buffer_bytes() const;

    // What the last build() that had something to do did (a build of an up-to-date scene leaves it).
    struct BuildReport {
        bool full = false;                  // everything was (re)built
        std::size_t gaussian_chunks = 0;    // Gaussian chunk BVHs built
        std::size_t meshes = 0;             // mesh BVHs built
    };
    BuildReport last_build() const;
    void set_world(const World& world);

    // Builds (or rebuilds, if the mode changed or something was added) the BVH, or applies the updates since the
    // last build. render() calls it; calling it beforehand separates build time from render time. Returns the
    // build time in seconds (0 if nothing to do).
    double build(GaussianMode mode);

    std::size_t gaussian_count() const;
    std::size_t mesh_count() const;
    std::size_t light_count() const;
    std::size_t material_count() const;

    struct Impl;
    Impl& impl() { return *impl_; }
    const Impl& impl() const { return *impl_; }

private:
    std::unique_ptr<Impl> impl_;
};

}  // namespace raysplats
