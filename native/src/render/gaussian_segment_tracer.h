// The Gaussian segment tracer (internal; docs/design.md §6): traces a ray to its closest opaque mesh hit and composites the
// Gaussians in front of it, either sorted (gathered k at a time in exact (t, id) order by the intersect callback,
// composited front to back, C += T a_i c_i, T *= 1 - a_i, re-traced from the k-th hit until the segment is done
// or T < threshold) or stochastic (the nearest Gaussian accepted with probability alpha), for single rays and for
// 16-wide packets of camera rays.
#pragma once

#include <cstdint>

#include <embree3/rtcore.h>
#include <glm/glm.hpp>

#include "gaussian_callbacks.h"
#include "gaussian_shading.h"
#include "ray.h"
#include "raysplats/render/cryptomatte.h"
#include "raysplats/render/render_settings.h"
#include "render_math.h"
#include "scene_impl.h"
#include "shadow_visibility.h"

namespace raysplats {

// What a ray met up to its closest opaque mesh hit.
struct Segment {
    // Premultiplied Gaussian radiance sum T_i a_i c_i, in the settings' blend space: linear (BlendSpace::Linear), or
    // display values as trained (BlendSpace::Display), which the path integrator takes to linear together with
    // what lies behind: linear(radiance + transmittance * display(behind)).
    glm::vec3 radiance{0.0f};
    float transmittance = 1.0f;
    bool terminated = false;   // T fell below the threshold (or a stochastic Gaussian was accepted)
    bool mesh = false;
    unsigned top_geom = RTC_INVALID_GEOMETRY_ID;
    unsigned prim = 0;
    float t = kInf, u = 0.0f, v = 0.0f;
    float depth = kInf;        // first point where opacity reaches 0.5
    glm::vec3 normal{0.0f};    // there; left 0 when that point is the mesh hit (the path integrator shades it)
    bool depth_at_mesh = false;
    const GaussianSet* depth_set = nullptr;  // the cloud of the Gaussian at `depth` (null: a mesh's depth, or none)
    // Camera rays (Ray::camera_distance >= 0): the Mist pass's sum over the Gaussians (mist.h), sum T_i a_i (1 -
    // mist(d_i)), where a terminated segment gives the transmittance it leaves to its terminating Gaussian, which
    // stands for what lies behind as it does for coverage. The mesh hit is the path integrator's to add. 0 for
    // other rays.
    float mist_clearance = 0.0f;
    // Camera rays with RenderSettings::denoising_data: the denoiser's guides over the Gaussians (SampleRecord), sum
    // T_i a_i x_i, a terminating Gaussian taking the transmittance left as for mist. The mesh hit is the path
    // integrator's to add. 0 otherwise.
    glm::vec3 guide_albedo{0.0f};
    glm::vec3 guide_normal{0.0f};
    // Camera rays with Cryptomatte passes (RenderSettings::cryptomatte_*): each Gaussian cloud's weight T_i a_i summed
    // by its ids, weighted as for mist. The mesh hit is the path integrator's to add. Empty otherwise.
    CryptomatteCoverage cryptomatte;
    // Camera rays: the coverage of held-out Gaussians (GaussianSet::holdout), sum T_i a_i over them, a terminating
    // one taking the transmittance left as for mist; they add no radiance. 0 otherwise.
    float holdout = 0.0f;
    float end = kInf;          // where the segment ended: its terminating Gaussian or mesh hit (+inf: escaped)
    std::uint32_t gaussians = 0;  // Gaussians composited (sorted) or accepted (stochastic) on it
    // The LIT and BAKED_SHADOWED Gaussians on it, which the path integrator shades (`radiance` has the BAKED ones).
    GaussianShadingPoint shading;
};

class GaussianSegmentTracer {
public:
    // `shadow` gives the light visibility of Gaussian centres (RenderSettings::meshes_shadow_gaussians).
    GaussianSegmentTracer(const Scene::Impl& scene, const RenderSettings& settings, const ShadowVisibility& shadow)
        : s_(scene), st_(settings), shadow_(shadow), shader_(scene, settings, shadow),
          cryptomatte_(cryptomatte_layout_of(settings).on()) {}

    // The segment of one ray, in the settings' compositing mode.
    Segment trace(const Ray& ray, Sampler& rng, Counters& c) const;

    // First segments of up to 16 coherent camera rays (lanes where `active` is set) with packet queries;
    // `ends`: speculative segment ends in sorted mode (+inf for none). See the definition.
    void trace_packet(const Ray* rays, const bool* active, const float* ends, Sampler* rngs, Segment* segs,
                      Counters& c) const;

    const GaussianShader& shader() const { return shader_; }

private:
    void init_rayhit(RTCRayHit& rh, const Ray& ray, float tnear) const;
    void record_mesh(Segment& seg, float t, unsigned geom, unsigned inst, unsigned prim, float u, float v) const;
    const GaussianSet& gaussian_of(unsigned geom, std::uint32_t& prim) const;
    void add_shaded(Segment& seg, const GaussianSet& set, std::uint32_t prim, GaussianShading shading, const Ray& ray,
                    float t, float weight, Sampler& rng) const;
    glm::vec3 gaussian_color(const GaussianSet& set, std::uint32_t prim, const Ray& ray, Sampler& rng,
                             Counters& c) const;
    void composite(Segment& seg, const Ray& ray, std::uint32_t geom, std::uint32_t prim, float t, float alpha,
                   Sampler& rng, Counters& c) const;
    void add_mist(Segment& seg, const Ray& ray, float t, float weight) const;
    void add_guides(Segment& seg, const GaussianSet& set, std::uint32_t prim, const Ray& ray, float weight) const;
    void add_cryptomatte(Segment& seg, const GaussianSet& set, const Ray& ray, float weight) const;
    void init_lane(LaneState& L) const;
    static void count_traversal(LaneState& L, Counters& c);
    bool consume_gather(Segment& seg, LaneState& L, const Ray& ray, float end, float tfar, unsigned geom,
                        unsigned inst, unsigned prim, float u, float v, Sampler& rng, Counters& c) const;
    void trace_sorted_from(Segment& seg, LaneState& L, const Ray& ray, Sampler& rng, Counters& c) const;
    Segment trace_sorted(const Ray& ray, Sampler& rng, Counters& c) const;
    void consume_stochastic(Segment& seg, LaneState& L, const Ray& ray, float tfar, unsigned geom, unsigned inst,
                            unsigned prim, float u, float v, Sampler& rng, Counters& c) const;
    Segment trace_stochastic(const Ray& ray, Sampler& rng, Counters& c) const;

    const Scene::Impl& s_;
    const RenderSettings& st_;
    const ShadowVisibility& shadow_;
    GaussianShader shader_;
    const bool cryptomatte_;  // the render has Cryptomatte passes
};

}  // namespace raysplats
