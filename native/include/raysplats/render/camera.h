// Cameras of Blender (docs/design.md §6): perspective, orthographic and the panoramic models of Cycles. A camera looks
// down its local -Z axis with +Y up and +X right; `camera_to_world` places it (Blender's matrix_world).
#pragma once

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

    // Throws InvalidArgument for NaN/Inf, non-positive lens/sensor/scale, clip_end <= clip_start, a camera
    // matrix that is not affine, or empty angle ranges.
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
    CameraRay operator()(float x, float y) const;

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
};

}  // namespace raysplats
