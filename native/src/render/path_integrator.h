// The path integrator (internal; docs/design.md §6): follows one camera path through Gaussian segments and mesh
// bounces. Each segment comes from the Gaussian segment tracer; a mesh hit is shaded with next-event estimation whose
// shadow rays carry Gaussian transmittance x mesh occlusion, and the path goes on by sampling the BSDF.
#pragma once

#include <cstdint>

#include <glm/glm.hpp>

#include "bsdf.h"
#include "gaussian_segment_tracer.h"
#include "light_sampling.h"
#include "motion_vectors.h"
#include "ray.h"
#include "raysplats/render/film.h"
#include "raysplats/render/render_settings.h"
#include "render_math.h"
#include "scene_impl.h"
#include "shadow_visibility.h"

namespace raysplats {

// A mesh hit, interpolated.
struct Surface {
    glm::vec3 p, ng, ns;  // ng, ns: outward (front-face) normals, world
    glm::vec2 uv{0.0f};
    std::uint32_t material = 0;
};

class PathIntegrator {
public:
    PathIntegrator(const Scene::Impl& scene, const RenderSettings& settings, const GaussianSegmentTracer& tracer,
                   const ShadowVisibility& shadow, const MotionVectorProjector& vectors)
        : s_(scene), st_(settings), tracer_(tracer), shadow_(shadow), vectors_(vectors),
          world_(glm::vec3(scene.world.color[0], scene.world.color[1], scene.world.color[2]) * scene.world.strength),
          cryptomatte_(cryptomatte_layout_of(settings).on()) {}

    // One path from a camera ray: its radiance, and the coverage, depth and normal of the primary segment.
    // `first`: the camera segment when it was already traced (GaussianSegmentTracer::trace_packet).
    SampleRecord path(Ray ray, Sampler& rng, Counters& c, const Segment* first = nullptr) const;

private:
    struct DisplayRun;
    struct PathState;
    struct GaussianBounce;

    Surface surface(const Segment& seg, const Ray& ray) const;
    int nearest_light_hit(const Ray& ray, LightHit& hit) const;
    Segment trace_with_lights(const Ray& ray, const Segment* first, float mis_pdf, const glm::vec3& beta,
                              PathState& p, Sampler& rng, Counters& c) const;
    // The camera segment and every later one: the Gaussians up to a mesh hit, their shading, and how it ends.
    float add_gaussians(PathState& p, Segment& seg) const;
    GaussianBounce shade_gaussians(PathState& p, const Segment& seg, Counters& c) const;
    bool end_segment(PathState& p, const Segment& seg, float behind_weight, bool gaussian_bounce, Counters& c) const;
    bool bounce_off_gaussians(PathState& p, const GaussianBounce& bounce) const;
    // Shading at a mesh hit, and the next bounce.
    bool mesh_hit(PathState& p, const Segment& seg, Counters& c) const;
    bool shade_hit(PathState& p, const Surface& sf, const Material& mat, bool entering, const glm::vec3& ng,
                   float eps, Counters& c) const;
    void add_direct_lighting(PathState& p, const Bsdf& bsdf, const glm::vec3& p_out, const glm::vec3& ng,
                             const glm::vec3& ns, const glm::vec3& wo, Counters& c) const;
    bool next_bounce(PathState& p, const Bsdf& bsdf, const glm::vec3& hit_p, const glm::vec3& ng,
                     const glm::vec3& wo, float eps) const;
    bool next_vertex(PathState& p) const;
    void add_mesh_mist(PathState& p, const Segment& seg) const;
    void mesh_data_passes(PathState& p, const Segment& seg, const Surface& sf) const;
    void add_mesh_guides(PathState& p, const Segment& seg, const Surface& sf, bool entering) const;
    void add_mesh_cryptomatte(PathState& p, const Segment& seg, const Surface& sf) const;
    void catch_shadows(PathState& p, const Segment& seg, const Surface& sf, bool add_world, Counters& c) const;
    SampleRecord sample_record(PathState& p) const;
    // The light passes (RenderSettings::light_passes, SampleRecord::light).
    void add_emitted(PathState& p, const glm::vec3& light, int level, bool world = false) const;
    void add_scattered(PathState& p, const glm::vec3& light, const glm::vec3& diffuse_share,
                       const glm::vec3& glossy_share) const;
    void add_colors(PathState& p, const glm::vec3& diffuse, const glm::vec3& glossy,
                    const glm::vec3& transmission) const;
    void close_run_light(PathState& p, const DisplayRun& r, const glm::vec3& l) const;

    const Scene::Impl& s_;
    const RenderSettings& st_;
    const GaussianSegmentTracer& tracer_;
    const ShadowVisibility& shadow_;
    const MotionVectorProjector& vectors_;
    glm::vec3 world_;
    const Material default_material_{};  // for meshes of a scene without materials
    const bool cryptomatte_;             // the render has Cryptomatte passes
};

}  // namespace raysplats
