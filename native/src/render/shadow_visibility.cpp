#include "shadow_visibility.h"

#include <cmath>

#include "gaussian_callbacks.h"
#include "light_sampling.h"

namespace raysplats {

float ShadowVisibility::shadow(const glm::vec3& o, const glm::vec3& d, float dist, float time, bool meshes_only,
                              Counters& c) const {
    LaneState L;
    L.transmittance_threshold = st_.transmittance_threshold;
    TraceContext ctx(&L, 1, meshes_only ? TraceMode::MeshesOnly : TraceMode::Transmittance);
    RTCRay ray;
    ray.org_x = o.x;
    ray.org_y = o.y;
    ray.org_z = o.z;
    ray.dir_x = d.x;
    ray.dir_y = d.y;
    ray.dir_z = d.z;
    ray.tnear = 0.0f;
    ray.tfar = std::isfinite(dist) ? dist * (1.0f - 1e-4f) : kInf;
    ray.time = time;
    ray.mask = 0xffffffffu;
    ray.id = 0;
    ray.flags = 0;
    // rtcOccluded1: a single ray (N = 1 in the callbacks, id 0 = lanes[0]); Embree reports occlusion by setting tfar
    // to -inf, and so does the Gaussians' occluded callback once the transmittance falls below the threshold.
    rtcOccluded1(meshes_only ? s_.mesh_scene : s_.scene, &ctx, &ray);
    ++c.traced;
    if (ray.tfar == -kInf) return 0.0f;
    return L.transmittance;
}

float ShadowVisibility::gaussian_light_visibility(const glm::vec3& p, float time, Sampler& rng, Counters& c) const {
    if (s_.lights.empty()) return 1.0f;
    float total = 0.0f, visible = 0.0f;
    for (const Light& l : s_.lights) {
        LightSample ls;
        if (!sample_light(l, p, rng, ls)) continue;
        const float e = luminance(ls.value);
        if (!(e > 0.0f)) continue;
        total += e;
        visible += e * shadow(p, ls.wi, ls.distance, time, true, c);
    }
    return total > 0.0f ? visible / total : 1.0f;
}

}  // namespace raysplats
