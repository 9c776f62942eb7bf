// How a Gaussian's colour is produced (internal; RenderSettings::gaussian_shading, Scene::set_gaussian_shading):
// BAKED, its captured (SH) radiance as is; LIT, a two-sided Lambertian surface element shaded by the scene's lights
// and world; BAKED_SHADOWED, its captured radiance times the lights' visibility.
//
// A lit Gaussian is the flat Gaussian: its normal is the axis of its smallest scale (flipped to face the ray), its
// albedo its degree-0 colour with the capture light divided out (grey-world delighting, see
// grey_world_albedo_scale). Shadow rays go through meshes and Gaussians (both semi-transparent), so splats shadow
// splats as well as meshes.
//
// Deferred shading of a ray's segment: along one segment the tracer composites the non-baked Gaussians' albedos
// (and shadowed colours) exactly, A = sum_i T_i a_i rho_i (the front-to-back weights of the baked colours), and picks
// ONE of them as the segment's shading point with probability proportional to its weight T_i a_i (weighted
// reservoir sampling, one random number per such Gaussian). The segment is shaded once at that point: radiance
// A * (1/pi) sum_lights L cos V. This costs one set of shadow rays per segment instead of one per composited
// Gaussian (a surface composites ~30), and averages the shading over the segment's Gaussians' normals across
// samples (it is exact when they share position and normal, as a surface's Gaussians nearly do; at a silhouette
// it mixes the front Gaussian's albedo with the back one's shading in proportion to their weights).
#pragma once

#include <cstdint>
#include <vector>

#include <glm/glm.hpp>

#include "gaussian_primitives.h"
#include "ray.h"
#include "raysplats/render/render_settings.h"
#include "render_math.h"
#include "scene_impl.h"
#include "shadow_visibility.h"

namespace raysplats {

// The non-baked Gaussians of one segment: their composited albedo and shadowed colour, and the shading point.
struct GaussianShadingPoint {
    glm::vec3 albedo_sum{0.0f};    // sum of T_i a_i rho_i over LIT Gaussians
    glm::vec3 shadowed_sum{0.0f};  // sum of T_i a_i c_i over BAKED_SHADOWED Gaussians (c_i: baked colour)
    float weight = 0.0f;           // sum of T_i a_i over both (the reservoir's total)
    glm::vec3 p{0.0f};             // the chosen Gaussian's hit point (world)
    glm::vec3 n{0.0f};             // its unit normal, facing the ray's origin
    float bias = 0.0f;             // how far along them shadow and bounce rays start (world units)
    float time = 0.0f;             // the shutter time of the ray that reached them (Ray::time)

    bool empty() const { return !(weight > 0.0f); }
    bool lit() const { return albedo_sum.x > 0.0f || albedo_sum.y > 0.0f || albedo_sum.z > 0.0f; }
    // Adds a Gaussian of weight w (> 0); it becomes the shading point with probability w / (total weight).
    void add(float w, const glm::vec3& point, const glm::vec3& normal, float shadow_bias, Sampler& rng);
    // Appends a segment that lies behind this one, seen through transmittance `t_front` (the segments of one ray
    // split at an area light).
    void append_behind(const GaussianShadingPoint& behind, float t_front, Sampler& rng);
};

// Grey-world delighting (Buchsbaum 1980, achromatic form): the capture light is assumed to be a grey illumination
// under which the splat object's mean reflectance is kGreyWorldAlbedo. Radiance = albedo x illumination, so
// albedo = c / E with E = (opacity-weighted mean luminance of the object's linear degree-0 colours) /
// kGreyWorldAlbedo; the result is clamped to [0, 1] per channel (no surface reflects more than it receives).
// One scale per splat object, since each was captured under its own light.
constexpr float kGreyWorldAlbedo = 0.5f;
float grey_world_albedo_scale(const GaussianSet& set);

// A real splat surface is several overlapping, semi-transparent Gaussians thick; a shadow ray that started at the
// chosen Gaussian would be shadowed by the ones above it (its own surface). So shadow and bounce rays start this
// many standard deviations (of the Gaussian's largest axis: its support radius) along their direction, skipping
// what lies within the Gaussian's own footprint. donut_sh0 under a vertical sun, half of it under a mesh slab
// (BAKED_SHADOWED / BAKED per covered pixel, blender_tests/test_relighting.py): starting at 1 sigma of the smaller
// axis, 36 % of the pixels were in full shadow, 15 % unshadowed and 50 % in between (the lit half self-shadowed); at 3
// sigmas of the largest, 34 %, 56 % and 10 %. Farther occluders' shadow edges stay exact (the ray is the same line);
// contact shadows closer than this are lost.
constexpr float kShadowBiasSigmas = 3.0f;

class GaussianShader {
public:
    // Resolves every set's shading (its own, or the scene's) and the albedo scales of lit sets (O(Gaussians) for
    // each lit set, in parallel).
    GaussianShader(const Scene::Impl& scene, const RenderSettings& settings, const ShadowVisibility& shadow);

    // The set's shading in this render.
    GaussianShading shading(std::uint32_t set_index) const { return shading_[set_index]; }
    bool any_non_baked() const { return any_non_baked_; }

    // Albedo of primitive `prim` of a LIT set (linear, in [0, 1]).
    glm::vec3 albedo(const GaussianSet& set, std::uint32_t prim) const;
    // Where the shading point's shadow and bounce rays start: kShadowBiasSigmas world standard deviations of the
    // Gaussian's largest axis.
    static float shadow_bias(const GaussianSet& set, std::uint32_t prim);

    // Light from the scene's lights leaving the shading point towards its ray's origin: the lit part
    // A (1/pi) sum L cos V (next-event estimation, MIS-weighted against the bounce ray for area lights, whose
    // solid-angle pdf is bounce_pdf_scale cos / pi) plus the shadowed colours times the luminance-weighted
    // visibility of the lights. The world's light reaches lit Gaussians through the bounce ray (as for meshes).
    glm::vec3 direct(const GaussianShadingPoint& sp, float bounce_pdf_scale, Sampler& rng, Counters& c) const;

    // A cosine-distributed direction about the shading point's normal (pdf cos / pi) and the ray that takes it.
    Ray bounce_ray(const GaussianShadingPoint& sp, Sampler& rng, float& pdf) const;

private:
    const Scene::Impl& s_;
    const ShadowVisibility& shadow_;
    std::vector<GaussianShading> shading_;  // by set index
    std::vector<float> albedo_scale_;       // by set index (LIT sets)
    bool any_non_baked_ = false;
};

}  // namespace raysplats
