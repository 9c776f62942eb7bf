// The Vector pass (internal; film.h, SampleRecord::vector): how far the surface a camera sample sees moves on the
// image to the previous and to the next frame, in pixels, as Cycles writes it for Blender's Vector Blur node
// (kernel/geom/primitive.h, primitive_motion_vector): with the surface's point P at this frame and P_prev, P_next
// where its object's matrices of the previous and next frames put it (Scene::set_*_frame_motion), each projected by
// the camera of its frame (Camera::frame_motion) to raster positions whose y grows UP (Blender's rows run from the
// bottom),
//     vector = (raster(P_prev) - raster(P), raster(P) - raster(P_next))   (x, y, then x, y).
#pragma once

#include <array>
#include <vector>

#include <glm/glm.hpp>

#include "raysplats/render/camera.h"
#include "raysplats/render/transform.h"

namespace raysplats {

// An object's motion to its previous and next frames: the matrices that take a point of this frame to where the
// object's matrices of those frames put it (M_prev M^-1 and M_next M^-1). Identity: still.
struct FrameMotion {
    glm::mat4 to_previous{1.0f}, to_next{1.0f};
    bool set = false;

    // From the object's matrix at this frame and at the previous and next ones.
    static FrameMotion between(const Matrix4& object_to_world, const Matrix4& previous, const Matrix4& next);
};

class MotionVectorProjector {
public:
    // Active when the camera has its previous and next frames' placements (Camera::frame_motion, two matrices) and
    // is perspective or orthographic; Cycles projects panoramic cameras otherwise, which this pass does not: their
    // vectors stay 0.
    MotionVectorProjector(const Camera& camera, int width, int height);
    bool active() const { return active_; }
    // The vector of a surface point `p` (world) of an object moving as `motion` (nullptr: still).
    std::array<float, 4> vector(const glm::vec3& p, const FrameMotion* motion) const;
    // The vector of a surface point `p` (world) that is at `previous` at the previous frame and at `next` at the next
    // (world; a deforming mesh's point).
    std::array<float, 4> vector_between(const glm::vec3& p, const glm::vec3& previous, const glm::vec3& next) const;

private:
    // Raster position (x right, y up, pixels) of world point `p` seen by the camera whose world-to-camera matrix is
    // `world_to_camera`.
    glm::vec2 raster(const glm::mat4& world_to_camera, const glm::vec3& p) const;

    bool active_ = false;
    bool perspective_ = true;
    float fx_ = 1.0f, fy_ = 1.0f, cx_ = 0.0f, cy_ = 0.0f, height_ = 0.0f;
    glm::mat4 current_{1.0f}, previous_{1.0f}, next_{1.0f};  // world to camera
};

}  // namespace raysplats
