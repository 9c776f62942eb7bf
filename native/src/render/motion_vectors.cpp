// The Vector pass's projections (motion_vectors.h).
#include "motion_vectors.h"

#include "render_math.h"

namespace raysplats {
namespace {

glm::mat4 to_glm(const Matrix4& m) {
    glm::mat4 g;
    for (int r = 0; r < 4; ++r)
        for (int c = 0; c < 4; ++c) g[c][r] = m(r, c);
    return g;
}

}  // namespace

FrameMotion FrameMotion::between(const Matrix4& object_to_world, const Matrix4& previous, const Matrix4& next) {
    const glm::mat4 inverse = glm::inverse(to_glm(object_to_world));
    return FrameMotion{to_glm(previous) * inverse, to_glm(next) * inverse, true};
}

MotionVectorProjector::MotionVectorProjector(const Camera& camera, int width, int height) {
    if (camera.frame_motion.size() != 2 ||
        (camera.type != CameraType::Perspective && camera.type != CameraType::Orthographic))
        return;
    active_ = true;
    perspective_ = camera.type == CameraType::Perspective;
    // The image position of a camera-space point (X, Y, Z): x = cx + fx X / z, y_down = cy - fy Y / z with z = -Z
    // (CameraRayGenerator::PinholeProjection); an orthographic camera's is the same without the division, its
    // half extents being in scene units.
    const CameraRayGenerator::PinholeProjection p = CameraRayGenerator(camera, width, height).pinhole_projection();
    fx_ = p.fx;
    fy_ = p.fy;
    cx_ = p.cx;
    cy_ = p.cy;
    height_ = float(height);
    current_ = glm::inverse(to_glm(camera.camera_to_world));
    previous_ = glm::inverse(to_glm(camera.frame_motion[0]));
    next_ = glm::inverse(to_glm(camera.frame_motion[1]));
}

glm::vec2 MotionVectorProjector::raster(const glm::mat4& world_to_camera, const glm::vec3& p) const {
    const glm::vec4 c = world_to_camera * glm::vec4(p, 1.0f);
    const float scale = perspective_ ? 1.0f / -c.z : 1.0f;
    // Blender's raster y grows up: height minus the image's y, which grows down.
    return glm::vec2(cx_ + fx_ * c.x * scale, height_ - (cy_ - fy_ * c.y * scale));
}

std::array<float, 4> MotionVectorProjector::vector(const glm::vec3& p, const FrameMotion* motion) const {
    if (!active_) return {0.0f, 0.0f, 0.0f, 0.0f};
    glm::vec3 p_previous = p, p_next = p;
    if (motion && motion->set) {
        p_previous = glm::vec3(motion->to_previous * glm::vec4(p, 1.0f));
        p_next = glm::vec3(motion->to_next * glm::vec4(p, 1.0f));
    }
    return vector_between(p, p_previous, p_next);
}

std::array<float, 4> MotionVectorProjector::vector_between(const glm::vec3& p, const glm::vec3& p_previous,
                                                           const glm::vec3& p_next) const {
    if (!active_) return {0.0f, 0.0f, 0.0f, 0.0f};
    const glm::vec2 centre = raster(current_, p);
    const glm::vec2 pre = raster(previous_, p_previous) - centre;
    const glm::vec2 post = centre - raster(next_, p_next);
    return {pre.x, pre.y, post.x, post.y};
}

}  // namespace raysplats
