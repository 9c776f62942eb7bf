// Camera-ray splatting (internal; RenderSettings::camera_ray_splatting): the Gaussians a perspective camera's rays
// see in front of their first mesh hit are drawn as splat viewers draw them, not traced. Ray tracing draws each
// Gaussian by its exact 3D response along the ray, in per-ray order; viewers draw the EWA footprint in centre-depth
// order, and on scenes of Gaussians that are large for their distance or thin and seen obliquely the two differ by
// more than the training's noise (native/tests/reference/test_viewer_agreement.py measures it).
//
// The model, that of the 3DGS rasterizer (Kerbl et al. 2023, §4 and §6; its CUDA forward.cu, computeCov2D and
// renderCUDA):
//   centre m (world), view-space p = W (m - o), view depth z;  pixel (u, v) = the camera's projection of p;
//   2D covariance  Sigma' = J W A Sigma A^T W^T J^T + 0.3 I  (px^2), Sigma the Gaussian's 3D covariance in either
//   Gaussian mode (flat mode traces disks, but a viewer draws the whole Gaussian), J the perspective Jacobian at p, its x/z and
//   y/z clamped to 1.3 times the frustum's half extent about its centre (forward.cu: 1.3 tan(fov / 2));
//   alpha(x) = min(0.99, a exp(-1/2 d^T Sigma'^-1 d)), d = x - (u, v), skipped below 1/255, evaluated at each camera
//   sample's own (jittered) position; cut outside the square of half side 3 sqrt(lambda_max(Sigma'));
//   every camera sample composites the same list, sorted by (z, Gaussian) once per frame, front to back, C += T alpha c,
//   T *= 1 - alpha, stopping once T < transmittance_threshold; c is the Gaussian's SH colour in the direction camera
//   -> centre, in the render's blend space (display values by default).
// Gaussians whose centre is nearer than the camera's clip start or beyond its clip end are culled (the rasterizer's
// near cut), as are those whose opacity never reaches 1/255. Behind the splats the camera ray goes on as a traced ray
// does: its first mesh hit (found with a meshes-only traversal) bounds the list by view depth, is shaded by the path
// integrator and weighted by the transmittance left (the world without a mesh hit), exactly as a traced segment's.
//
// The pre-pass (camera_splat_prepass.h) projects, sorts and bins the splats once per frame; a 4 x 4 packet of camera
// rays then reads the lists of its own fine tile and of the coarse tile holding it once, for all 16 samples.
//
// Applies when the camera is perspective without depth of field (a thin lens's rays leave the aperture at many
// points; the splats are a pinhole's projection), nothing moves during the shutter (motion blur) and every
// Gaussian cloud is BAKED (effective shading): LIT and BAKED_SHADOWED Gaussians are shaded per hit point along the
// ray and cannot join a screen-space list, so a scene holding any keeps every camera ray traced (CameraSplatting::applies, traced_reason). Secondary rays (reflections, refraction,
// shadows, a camera ray continuing through a semi-transparent mesh) are always traced, and so is a camera ray that
// meets an area light in front of its mesh hit (or with none): the path integrator traces the part in front of the
// light again, as it does for a traced first segment (PathIntegrator::trace_with_lights).
#pragma once

#include <atomic>
#include <cstdint>
#include <vector>

#include <glm/glm.hpp>

#include "camera_splat_prepass.h"
#include "gaussian_segment_tracer.h"
#include "ray.h"
#include "raysplats/render/camera.h"
#include "raysplats/render/render_settings.h"
#include "render_math.h"
#include "scene_impl.h"
#include "shadow_visibility.h"

namespace raysplats {

class CameraSplatting {
public:
    // Whether camera-ray splatting renders this frame's camera rays (the setting on, a perspective camera without
    // depth of field, every Gaussian cloud BAKED and none held out).
    static bool applies(const Scene::Impl& scene, const RenderSettings& settings, const Camera& camera,
                        const GaussianShader& shader);
    // Why it does not, though the setting is on, in the user's words ("needs a perspective camera", "needs a camera
    // without depth of field", "needs a scene without motion blur", "needs every Gaussian object Baked", "needs no
    // Gaussian object held out"); null when it does or the setting is off. Its splats are one pinhole projection: a
    // thin lens's rays leave the aperture at many points, a moving object or camera is at many places during the
    // shutter, and its blend has no held-out fraction.
    static const char* traced_reason(const Scene::Impl& scene, const RenderSettings& settings, const Camera& camera,
                                     const GaussianShader& shader);

    // Runs the pre-pass. Returns early, incomplete, once `cancel` is set (the render loop then renders nothing).
    CameraSplatting(const Scene::Impl& scene, const RenderSettings& settings, const Camera& camera,
                    const ShadowVisibility& shadow, const std::atomic<bool>* cancel);

    // First segments of up to 16 camera rays (lanes where `active` is set) of the 4 x 4 pixels from (packet_x,
    // packet_y), lane l at pixel (packet_x + l % 4, packet_y + l / 4), whose samples lie at image positions (xs, ys):
    // the splats in front of each ray's first mesh hit, then that hit (as GaussianSegmentTracer's).
    void trace_packet(int packet_x, int packet_y, const Ray* rays, const bool* active, const float* xs,
                      const float* ys, Sampler* rngs, Segment* segs, Counters& c) const;

    std::size_t splat_count() const { return prepass_.splats().size(); }
    std::size_t tile_entry_count() const {
        return prepass_.coarse().entries.size() + prepass_.fine().entries.size();
    }
    // Bytes held by the splats and tile lists.
    std::size_t memory_bytes() const { return prepass_.memory_bytes(); }

private:
    // Composites onto the segments of the lanes in `lanes` (a mask), whose samples all lie in fine tile `fine_tile`,
    // the splats of that fine tile's list and of its coarse tile's list, merged in depth order, in front of each
    // lane's `mesh_depth` (view depth): the lists are read once for all of them. `view_rates`: each lane's view depth
    // per unit of t along its ray.
    void composite(std::size_t fine_tile, std::uint32_t lanes, const Ray* rays, const float* xs, const float* ys,
                   const float* mesh_depth, const float* view_rates, Sampler* rngs, Segment* segs, Counters& c) const;

    // Composites splat `index` onto a lane's segment, at `power` (its exponent at the lane's sample): C += T alpha c,
    // T *= 1 - alpha; the splat that makes the segment opaque gives its depth, normal and cloud. Its Mist pass term
    // (Segment::mist_clearance) is taken where the ray reaches the splat's view depth (the ray's view depth per unit
    // t: `view_rate`), which needs no fetch of its centre. Returns whether the segment stopped (T below the
    // transmittance threshold).
    bool blend(std::uint32_t index, float power, const Ray& ray, float view_rate, Sampler& rng, Segment& seg,
               Counters& c) const;

    const Scene::Impl& s_;
    const RenderSettings& st_;
    const ShadowVisibility& shadow_;
    const CameraSplatPrepass prepass_;
    const bool cryptomatte_;  // the render has Cryptomatte passes
};

}  // namespace raysplats
