// Gaussians as Embree user geometry (internal): the per-ray state that traversals hand to the callbacks, and the
// geometry whose bounds / intersect / occluded callbacks test rays against a chunk's GaussianGroups with SIMD.
#pragma once

#include <cstdint>
#include <limits>

#include <embree3/rtcore.h>

#include "gather_buffer.h"
#include "gaussian_primitives.h"
#include "ray.h"

namespace raysplats {

// What a traversal collects from Gaussians; the context passed to rtcIntersect1/16 and rtcOccluded1 extends
// RTCIntersectContext (the Embree tutorials' pattern for extra per-ray data).
enum class TraceMode : std::uint32_t {
    Gather,        // sorted: keep the k nearest hits in `gather`
    Stochastic,    // accept each with probability alpha, report the nearest accepted as an Embree hit
    Transmittance, // occlusion query: multiply `transmittance` by (1 - alpha) of every Gaussian on the segment
    MeshesOnly,    // Gaussians are ignored
};

// Per-ray state of a traversal.
struct LaneState {
    // Gather: the k nearest hits of the current pass.
    GatherBuffer gather;
    // Stochastic: random seed of this ray.
    std::uint32_t seed = 0;
    // Statistics: Gaussian tests (group members) and group callbacks (bounding-box candidates) of the traversal.
    std::uint64_t candidates = 0;
    std::uint64_t group_candidates = 0;
    // Transmittance (shadow rays) and the compositing threshold (also where the gather buffer is cut).
    float transmittance = 1.0f;
    float transmittance_threshold = 0.0f;
};

// The context handed to rtcIntersect1/16 and rtcOccluded1 (the Embree tutorials' way to carry per-ray data). No
// intersection filter functions are used: the Gaussians' own intersect and occluded callbacks do all the work, and
// meshes report their closest hit as Embree finds it.
// A callback finds the state of a ray by the ray's id, never by its position in the packet the callback gets:
// Embree's rtcIntersect4/8/16 "may change the ray packet size and ray order when calling back into ... user
// geometry callbacks" (rtcIntersect16's documentation). It does so wherever the CPU has no native 16-wide path
// (RTC_DEVICE_PROPERTY_NATIVE_RAY16_SUPPORTED false: every CPU without AVX-512), where the ray stream filter splits
// a 16-ray packet into packets of 8 (AVX, AVX2) or 4 (SSE) rays, ray 8 arriving as lane 0. RTCRay::id is there for
// this ("the ray ID can be used to identify a ray inside a callback function, even if the order of rays inside a
// ray packet or stream has changed"). So every ray handed to Embree carries the index of its LaneState in `lanes`:
// 0 for single rays, its packet lane for packets (set_packet_lane).
struct TraceContext : RTCIntersectContext {
    TraceMode mode = TraceMode::Gather;
    LaneState* lanes;
    unsigned lane_count;  // rays with an id >= lane_count are not ours: the callbacks leave them alone
    TraceContext(LaneState* lane_array, unsigned count, TraceMode m) : mode(m), lanes(lane_array), lane_count(count) {
        rtcInitIntersectContext(this);
    }
};

// Lane l of a 16-ray packet set to the segment [ray.tmin, tfar] of `ray`, with no hit yet (the packet's other
// fields as rtcIntersect16 wants them: every ray's mask, its motion time, the id of its LaneState).
inline void set_packet_lane(RTCRayHit16& rh, int l, const Ray& ray, float tfar) {
    rh.ray.org_x[l] = ray.o.x;
    rh.ray.org_y[l] = ray.o.y;
    rh.ray.org_z[l] = ray.o.z;
    rh.ray.dir_x[l] = ray.d.x;
    rh.ray.dir_y[l] = ray.d.y;
    rh.ray.dir_z[l] = ray.d.z;
    rh.ray.tnear[l] = ray.tmin;
    rh.ray.tfar[l] = tfar;
    rh.ray.time[l] = ray.time;
    rh.ray.mask[l] = 0xffffffffu;
    rh.ray.id[l] = unsigned(l);
    rh.ray.flags[l] = 0;
    rh.hit.geomID[l] = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0][l] = RTC_INVALID_GEOMETRY_ID;
}

// Lane l of a 16-ray packet made inactive (its `valid` entry must be 0 too). The valid mask alone is not enough:
// where the packet goes through Embree's ray stream filter (every CPU without AVX-512) a ray counts as active when
// tnear <= tfar, whatever `valid` says, so a finished or padding lane would be traced again and its callbacks
// would run. An empty segment (tnear 0, tfar -inf, the value Embree itself writes to mark an occluded ray) is
// inactive on every path, and the ray is a valid one (finite origin, unit direction) for any code that reads it.
inline void set_packet_lane_inactive(RTCRayHit16& rh, int l) {
    set_packet_lane(rh, l, Ray{glm::vec3(0.0f), glm::vec3(0.0f, 0.0f, 1.0f), 0.0f, 0.0f},
                    -std::numeric_limits<float>::infinity());
    rh.ray.mask[l] = 0u;
}

// Creates the Embree user geometry of a chunk of `chunk.set` (bounds + intersect + occluded callbacks for the set's
// flat or volumetric Gaussians), groups its primitives and commits it.
RTCGeometry create_gaussian_geometry(RTCDevice device, GaussianChunk& chunk);

// The group test the callbacks use on this machine: "avx2" (AVX2 + FMA) or "sse" (the x86-64 baseline, or
// RAYSPLATS_SIMD=sse). Chosen once per process.
const char* gaussian_group_test_path();

}  // namespace raysplats
