// Cameras of Blender (docs/design.md §6): perspective, orthographic and the panoramic models of Cycles. A camera looks
// down its local -Z axis with +Y up and +X right; `camera_to_world` places it (Blender's matrix_world).
// Depth of field is Cycles' thin lens for every model (Camera.dof in Blender): a ray leaves a point of the aperture
// (a disc, or a polygon of `aperture_blades` sides, its width divided by `aperture_ratio`) and passes through the
// point its pinhole ray reaches at the focus distance, so what lies there is sharp and the rest is blurred.
// Motion blur moves the camera across the shutter (`motion`): a ray of shutter time t is the ray of the camera placed
// at t, as Cycles places it (translation interpolated linearly, rotation spherically).
#pragma once

#include <array>
#include <vector>

#include "raysplats/render/transform.h"

namespace raysplats {

enum class CameraType { Perspective, Orthographic, Equirectangular, FisheyeEquidistant, FisheyeEquisolid };
enum class SensorFit { Auto, Horizontal, Vertical };

struct Camera {
    CameraType type = CameraType::Perspective;
    Matrix4 camera_to_world;

    // Perspective (and the fitted sensor of the equisolid fisheye), millimetres as in Blender.
    float focal_length_mm = 50.0f;
    float sensor_width_mm = 36.0f;
    float sensor_height_mm = 24.0f;
    // Auto: the sensor width spans the larger image dimension. Horizontal: sensor width spans the image width.
    // Vertical: sensor height spans the image height.
    SensorFit sensor_fit = SensorFit::Auto;
    // Lens shift in units of the fitted (for Auto: the larger) image dimension, as in Blender.
    float shift_x = 0.0f;
    float shift_y = 0.0f;
    // Clipping distances measured along the view axis (-Z) for perspective/orthographic, along the ray for
    // panoramic cameras (Cycles' behaviour).
    float clip_start = 0.1f;
    float clip_end = 1000.0f;

    // Orthographic: width in scene units of the fitted image dimension.
    float ortho_scale = 6.0f;

    // Equirectangular: longitude grows to the right of the image, latitude to the top (radians).
    float longitude_min = -3.14159265358979f;
    float longitude_max = 3.14159265358979f;
    float latitude_min = -1.5707963267949f;
    float latitude_max = 1.5707963267949f;

    // Fisheye: full field of view (radians); the equisolid lens in millimetres (uses the fitted sensor).
    float fisheye_fov = 3.14159265358979f;
    float fisheye_lens_mm = 10.5f;

    // Depth of field, Blender's Camera.dof; off (a pinhole) unless use_dof. The aperture's radius follows Cycles
    // (intern/cycles/blender/camera.cpp): focal length in metres / (2 f-stop) in scene units for perspective and
    // panoramic cameras (the perspective `focal_length_mm`, also for fisheyes), 1 / (2 f-stop) for orthographic; an
    // f-stop below 1e-5 counts as 1e-5.
    bool use_dof = false;
    // Scene units: the distance of the plane in focus along the view axis (perspective, orthographic), or of the
    // sphere in focus around the camera (panoramic). A front end with a focus object gives the object's distance
    // along the view axis, as Cycles does.
    float focus_distance = 10.0f;
    float aperture_fstop = 2.8f;
    // 0 (or fewer than 3): a round aperture; else a regular polygon of that many sides, rotated by
    // `aperture_rotation` (radians) from the camera's +X axis toward +Y.
    int aperture_blades = 0;
    float aperture_rotation = 0.0f;
    // Anamorphic bokeh: the aperture's extent along the camera's X axis is divided by the ratio.
    float aperture_ratio = 1.0f;

    // Motion blur: camera_to_world at equally spaced times across the shutter, from its opening (the first) to its
    // closing (the last), each a rotation and a translation (a scale is dropped, as Blender's normalized
    // matrix_world drops it); fewer than two: a still camera. camera_to_world remains the frame's placement, which
    // the rays of every time are moved from.
    std::vector<Matrix4> motion;
    // Motion blur's shutter curve (Blender's render.motion_blur_shutter_curve): how open the shutter is at equally
    // spaced times from its opening to its closing (two values or more, >= 0, not all 0); a ray's time is drawn with
    // that density, through the inverse of its integral as Cycles tabulates it. Empty: fully open throughout.
    std::vector<float> shutter_curve;
    // The Vector pass: camera_to_world at the previous and at the next frame (two matrices), or none (the pass is
    // then 0), as Cycles' motion pass takes the camera's (perspective and orthographic cameras).
    std::vector<Matrix4> frame_motion;

    // Throws InvalidArgument for NaN/Inf, non-positive lens/sensor/scale, clip_end <= clip_start, a camera
    // matrix (or a motion step) that is not affine, more than 129 motion steps, a frame_motion other than two
    // matrices, a shutter curve of one value, negative or all 0, or empty angle ranges, a non-positive aperture
    // ratio, a negative f-stop, focus distance or blade count.
    void validate() const;
};

struct CameraRay {
    float origin[3];
    float direction[3];  // unit length, world space
    float t_min;         // the ray covers origin + t * direction for t in [t_min, t_max]
    float t_max;
    bool valid;          // false outside a fisheye's image circle
};

// The ray through image position (x, y) in pixel units of a width x height image: x grows to the right from the
// left edge, y grows DOWN from the top edge, so pixel (i, j) (row j from the top) has its centre at
// (i + 0.5, j + 0.5). The film stores rows top to bottom in the same way.
CameraRay generate_camera_ray(const Camera& camera, int width, int height, float x, float y);

// generate_camera_ray for the many rays of one image, with what depends only on the camera and the image size
// (sensor fit, extents, the camera matrix) worked out once: the same rays, bit for bit.
class CameraRayGenerator {
public:
    CameraRayGenerator(const Camera& camera, int width, int height);
    // The pinhole ray (through the centre of the lens).
    CameraRay operator()(float x, float y) const;

    // Whether the camera has depth of field (use_dof with an aperture of non-zero size).
    bool depth_of_field() const { return aperture_radius_ > 0.0f; }
    // With depth of field, the ray of image position (x, y) through the aperture point that (lens_u, lens_v), two
    // uniform numbers in [0, 1), choose (Cycles' camera_sample_aperture: a concentric disc or a regular polygon);
    // without, the pinhole ray. The clip distances are those of the pinhole ray, measured from the aperture point.
    CameraRay operator()(float x, float y, float lens_u, float lens_v) const;
    // The aperture point of (lens_u, lens_v) in the lens plane, scene units along the camera's X and Y axes (for
    // panoramic cameras, along the frame the thin-lens ray builds around each direction).
    void aperture_point(float lens_u, float lens_v, float point[2]) const;

    // Whether the camera moves during the shutter (Camera::motion).
    bool motion() const { return motion_.size() >= 2; }
    // `ray` (of the camera at camera_to_world) as the camera placed at shutter time `time` in [0, 1] casts it: moved
    // rigidly from camera_to_world to the interpolated placement. The same ray without motion.
    CameraRay at_time(const CameraRay& ray, float time) const;
    // The shutter time of a uniform number u in [0, 1): u itself, or with a shutter curve the inverse of its
    // normalised integral at u (Camera::shutter_curve).
    float shutter_time(float u) const;

    // Perspective: the pinhole projection these rays invert. A camera-space point (X, Y, Z) (looking down -Z) at
    // depth z = -Z lies at image position x = cx + fx X / z, y = cy - fy Y / z, in the pixel units above.
    struct PinholeProjection {
        float fx, fy, cx, cy;
        float half_width_tan, half_height_tan;  // the frustum's half extents, in X / z and Y / z
        float center_x_tan, center_y_tan;       // its centre (the lens shift), the same units
    };
    PinholeProjection pinhole_projection() const;

private:
    Camera camera_;
    float width_, height_;
    float linear_[9];        // camera_to_world's linear part, row-major
    float translation_[3];
    float extent_ = 0.0f;    // perspective: fitted sensor / focal length; orthographic: ortho scale
    float half_w_ = 0.0f, half_h_ = 0.0f;  // perspective/orthographic: half image extents
    float sensor_w_ = 0.0f, sensor_h_ = 0.0f;  // equisolid fisheye: the fitted sensor (mm)
    // Depth of field: the aperture's radius (0 without) and focus distance in scene units, Cycles' blade count (0
    // for a disc), and the camera's X, Y and view axes in world space as unit vectors (the lens is measured in
    // scene units whatever the camera matrix's scale, as Cycles clears it).
    float aperture_radius_ = 0.0f;
    float focus_distance_ = 0.0f;
    int blades_ = 0;
    float axis_x_[3] = {1, 0, 0}, axis_y_[3] = {0, 1, 0}, forward_[3] = {0, 0, -1};
    // Motion: each step's rotation (a unit quaternion w x y z) and translation, and camera_to_world's inverse
    // (row-major 3 x 4) that takes the frame's rays back to the camera's own space.
    std::vector<std::array<float, 7>> motion_;
    std::vector<float> shutter_table_;  // the shutter curve's inverse CDF at equally spaced u (empty: none)
    float world_to_camera_[12] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0};
};

}  // namespace raysplats
