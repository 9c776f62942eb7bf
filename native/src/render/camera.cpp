// Camera models. Conventions follow Cycles 3.x (intern/cycles/blender/camera.cpp for sensor fit, shift and the
// aperture, intern/cycles/kernel/camera/projection.h for the panoramic mappings, intern/cycles/kernel/camera/camera.h
// for the thin lens), written in Blender's camera frame: forward = -Z, right = +X, up = +Y.
#include "raysplats/render/camera.h"

#include <algorithm>
#include <cmath>
#include <string>

#include <glm/gtc/quaternion.hpp>

#include "raysplats/errors.h"
#include "render_math.h"

namespace raysplats {
namespace {

void require(bool ok, const std::string& message) {
    if (!ok) throw InvalidArgument("camera: " + message);
}

bool finite(float v) { return std::isfinite(v); }

// Whether the sensor spans the image width (true) or height (false); Cycles: Auto fits the larger dimension.
bool horizontal_fit(const Camera& c, int width, int height) {
    switch (c.sensor_fit) {
        case SensorFit::Horizontal: return true;
        case SensorFit::Vertical: return false;
        case SensorFit::Auto: default: return width > height;
    }
}

// Sensor size (mm) that spans the fitted dimension.
float fitted_sensor(const Camera& c) {
    return c.sensor_fit == SensorFit::Vertical ? c.sensor_height_mm : c.sensor_width_mm;
}

// Cycles' aperture radius in scene units (blender_camera_from_object): the f-stop clamped to 1e-5, then
// lens (m) / (2 f-stop) for perspective and panoramic cameras (the lens in millimetres times 1e-3, as scene units
// whatever the scene's unit scale), 1 / (2 f-stop) for orthographic ones.
float aperture_radius(const Camera& c) {
    if (!c.use_dof) return 0.0f;
    const float fstop = std::max(c.aperture_fstop, 1e-5f);
    return c.type == CameraType::Orthographic ? 1.0f / (2.0f * fstop) : c.focal_length_mm * 1e-3f / (2.0f * fstop);
}

// Uniform numbers (u, v) in [0, 1)^2 to the unit disc by Shirley and Chiu's concentric mapping (Cycles'
// sample_uniform_disk).
glm::vec2 concentric_disc(float u, float v) {
    const float a = 2.0f * u - 1.0f, b = 2.0f * v - 1.0f;
    if (a == 0.0f && b == 0.0f) return glm::vec2(0.0f);
    float r, phi;
    if (a * a > b * b) {
        r = a;
        phi = 0.25f * kPi * (b / a);
    } else {
        r = b;
        phi = 0.5f * kPi - 0.25f * kPi * (a / b);
    }
    return glm::vec2(r * std::cos(phi), r * std::sin(phi));
}

// Uniform numbers to a regular polygon of `corners` sides inscribed in the unit circle (Cycles'
// regular_polygon_sample): u picks one of the triangles from the centre to a side, then a uniform point in it; the
// polygon's corners lie at rotation + (2 k + 1) pi / corners.
glm::vec2 regular_polygon(int corners, float rotation, float u, float v) {
    const float n = float(corners);
    const float corner = std::floor(u * n);
    u = std::sqrt(u * n - corner);
    v = v * u;
    u = 1.0f - u;
    const float angle = kPi / n;
    const glm::vec2 p((u + v) * std::cos(angle), (u - v) * std::sin(angle));
    rotation += corner * 2.0f * angle;
    const float cr = std::cos(rotation), sr = std::sin(rotation);
    return glm::vec2(cr * p.x - sr * p.y, sr * p.x + cr * p.y);
}

glm::vec3 unit_column(const Matrix4& m, int column) {
    return glm::normalize(glm::vec3(m(0, column), m(1, column), m(2, column)));
}

}  // namespace

void Camera::validate() const {
    camera_to_world.check_affine("camera_to_world");
    for (float v : {focal_length_mm, sensor_width_mm, sensor_height_mm, shift_x, shift_y, clip_start, clip_end,
                    ortho_scale, longitude_min, longitude_max, latitude_min, latitude_max, fisheye_fov,
                    fisheye_lens_mm, focus_distance, aperture_fstop, aperture_rotation, aperture_ratio})
        require(finite(v) || v == clip_end, "parameters must be finite (NaN or Inf given)");
    require(!std::isnan(clip_end), "clip_end is NaN");
    require(focal_length_mm > 0.0f, "focal length must be > 0 mm");
    require(sensor_width_mm > 0.0f && sensor_height_mm > 0.0f, "sensor size must be > 0 mm");
    require(clip_start >= 0.0f && clip_end > clip_start, "need 0 <= clip_start < clip_end");
    require(ortho_scale > 0.0f, "ortho_scale must be > 0");
    require(longitude_max > longitude_min, "equirectangular longitude range is empty");
    require(latitude_max > latitude_min, "equirectangular latitude range is empty");
    require(fisheye_fov > 0.0f && fisheye_fov <= 2.0f * kPi + 1e-4f, "fisheye fov must be in (0, 2 pi]");
    require(fisheye_lens_mm > 0.0f, "fisheye lens must be > 0 mm");
    require(focus_distance >= 0.0f, "focus distance must be >= 0");
    require(aperture_fstop >= 0.0f, "aperture f-stop must be >= 0");
    require(aperture_blades >= 0, "aperture blades must be >= 0");
    require(aperture_ratio > 0.0f, "aperture ratio must be > 0");
    require(motion.size() <= 129, "at most 129 motion steps");
    for (std::size_t k = 0; k < motion.size(); ++k)
        motion[k].check_affine(("camera motion step " + std::to_string(k)).c_str());
    require(shutter_curve.empty() || shutter_curve.size() >= 2, "a shutter curve needs two values or more");
    float curve_total = 0.0f;
    for (float v : shutter_curve) {
        require(finite(v) && v >= 0.0f, "shutter curve values must be finite and >= 0");
        curve_total += v;
    }
    require(shutter_curve.empty() || curve_total > 0.0f, "the shutter curve is 0 throughout (never open)");
    require(frame_motion.empty() || frame_motion.size() == 2,
            "frame motion takes the previous and next frames' matrices (two)");
    for (const Matrix4& m : frame_motion) m.check_affine("camera frame motion");
}

CameraRay generate_camera_ray(const Camera& c, int width, int height, float x, float y) {
    return CameraRayGenerator(c, width, height)(x, y);
}

namespace {

// Cycles' shutter table (scene/camera.cpp, util_cdf_inverted with SHUTTER_TABLE_SIZE entries): the curve read
// linearly between its values (shutter_curve_eval), integrated by the trapezoid rule on a fine grid, normalised,
// and inverted at `entries` equally spaced values of u.
std::vector<float> shutter_table(const std::vector<float>& curve, int entries) {
    constexpr int kSteps = 4096;
    auto eval = [&](float x) {
        const float f = x * float(curve.size() - 1);
        const std::size_t k = std::min(std::size_t(f), curve.size() - 2);
        const float w = f - float(k);
        return (1.0f - w) * curve[k] + w * curve[k + 1];
    };
    std::vector<double> cdf(kSteps + 1, 0.0);
    for (int i = 1; i <= kSteps; ++i)
        cdf[i] = cdf[i - 1] + 0.5 * (double(eval(float(i - 1) / kSteps)) + double(eval(float(i) / kSteps))) / kSteps;
    std::vector<float> table(static_cast<std::size_t>(entries));
    int i = 0;
    for (int e = 0; e < entries; ++e) {
        const double u = double(e) / (entries - 1) * cdf[kSteps];
        while (i < kSteps && cdf[i + 1] < u) ++i;
        const double span = cdf[std::min(i + 1, kSteps)] - cdf[i];
        const double w = span > 0.0 ? (u - cdf[i]) / span : 0.0;
        table[std::size_t(e)] = float((double(i) + std::min(1.0, std::max(0.0, w))) / kSteps);
    }
    return table;
}

}  // namespace

CameraRayGenerator::CameraRayGenerator(const Camera& c, int width, int height)
    : camera_(c), width_(float(width)), height_(float(height)) {
    const float w = width_, h = height_;
    for (int r = 0; r < 3; ++r) {
        for (int k = 0; k < 3; ++k) linear_[3 * r + k] = c.camera_to_world(r, k);
        translation_[r] = c.camera_to_world(r, 3);
    }
    if (c.type == CameraType::Perspective || c.type == CameraType::Orthographic) {
        // Full extent of the fitted dimension: in tan units (sensor / lens) or in scene units (ortho scale).
        extent_ = c.type == CameraType::Perspective ? fitted_sensor(c) / c.focal_length_mm : c.ortho_scale;
        if (horizontal_fit(c, width, height)) {
            half_w_ = 0.5f * extent_;
            half_h_ = half_w_ * h / w;
        } else {
            half_h_ = 0.5f * extent_;
            half_w_ = half_h_ * w / h;
        }
    } else if (c.type == CameraType::FisheyeEquisolid) {
        if (horizontal_fit(c, width, height)) {
            sensor_w_ = fitted_sensor(c);
            sensor_h_ = sensor_w_ * h / w;
        } else {
            sensor_h_ = fitted_sensor(c);
            sensor_w_ = sensor_h_ * w / h;
        }
    }
    aperture_radius_ = aperture_radius(c);
    if (aperture_radius_ > 0.0f) {
        // Cycles clamps the focus distance to 1e-5 and draws a disc for fewer than 3 blades (scene/camera.cpp).
        focus_distance_ = std::max(c.focus_distance, 1e-5f);
        blades_ = c.aperture_blades < 3 ? 0 : c.aperture_blades;
        const glm::vec3 ax = unit_column(c.camera_to_world, 0), ay = unit_column(c.camera_to_world, 1),
                        fw = -unit_column(c.camera_to_world, 2);
        for (int i = 0; i < 3; ++i) {
            axis_x_[i] = ax[i];
            axis_y_[i] = ay[i];
            forward_[i] = fw[i];
        }
    }
    if (!c.shutter_curve.empty()) shutter_table_ = shutter_table(c.shutter_curve, 256);
    if (c.motion.size() >= 2) {
        for (const Matrix4& step : c.motion) {
            glm::mat3 rotation = linear_part(step);
            for (int k = 0; k < 3; ++k) rotation[k] = glm::normalize(rotation[k]);
            const glm::quat q = glm::normalize(glm::quat_cast(rotation));
            motion_.push_back({q.w, q.x, q.y, q.z, step(0, 3), step(1, 3), step(2, 3)});
        }
        const glm::mat3 inverse = glm::inverse(linear_part(c.camera_to_world));
        const glm::vec3 t = -(inverse * translation_part(c.camera_to_world));
        for (int r = 0; r < 3; ++r) {
            for (int k = 0; k < 3; ++k) world_to_camera_[4 * r + k] = inverse[k][r];
            world_to_camera_[4 * r + 3] = t[r];
        }
    }
}

float CameraRayGenerator::shutter_time(float u) const {
    if (shutter_table_.empty()) return u;
    // Cycles' lookup_table_read: linear between the table's entries.
    const float f = u * float(shutter_table_.size() - 1);
    const std::size_t k = std::min(std::size_t(f), shutter_table_.size() - 2);
    const float w = f - float(k);
    return (1.0f - w) * shutter_table_[k] + w * shutter_table_[k + 1];
}

CameraRay CameraRayGenerator::at_time(const CameraRay& ray, float time) const {
    if (motion_.size() < 2 || !ray.valid) return ray;
    // Cycles (util/transform.h, transform_motion_array_interpolate): between the two steps around `time`, the
    // translation interpolated linearly and the rotation spherically (the shorter way).
    const float f = std::min(std::max(time, 0.0f), 1.0f) * float(motion_.size() - 1);
    const std::size_t k = std::min(std::size_t(f), motion_.size() - 2);
    const float w = f - float(k);
    const auto& a = motion_[k];
    const auto& b = motion_[k + 1];
    const glm::quat q = glm::slerp(glm::quat(a[0], a[1], a[2], a[3]), glm::quat(b[0], b[1], b[2], b[3]), w);
    const glm::mat3 rotation = glm::mat3_cast(q);
    const glm::vec3 translation = glm::mix(glm::vec3(a[4], a[5], a[6]), glm::vec3(b[4], b[5], b[6]), w);
    const float* m = world_to_camera_;
    auto to_camera = [m](const float v[3], float w1) {
        return glm::vec3(m[0] * v[0] + m[1] * v[1] + m[2] * v[2] + w1 * m[3],
                         m[4] * v[0] + m[5] * v[1] + m[6] * v[2] + w1 * m[7],
                         m[8] * v[0] + m[9] * v[1] + m[10] * v[2] + w1 * m[11]);
    };
    const glm::vec3 o = rotation * to_camera(ray.origin, 1.0f) + translation;
    const glm::vec3 d = glm::normalize(rotation * to_camera(ray.direction, 0.0f));
    CameraRay moved = ray;
    for (int i = 0; i < 3; ++i) {
        moved.origin[i] = o[i];
        moved.direction[i] = d[i];
    }
    return moved;
}

void CameraRayGenerator::aperture_point(float lens_u, float lens_v, float point[2]) const {
    // Cycles' camera_sample_aperture: the unit disc or polygon, its X divided by the ratio, times the radius.
    glm::vec2 p = blades_ == 0 ? concentric_disc(lens_u, lens_v)
                               : regular_polygon(blades_, camera_.aperture_rotation, lens_u, lens_v);
    p.x /= camera_.aperture_ratio;
    point[0] = p.x * aperture_radius_;
    point[1] = p.y * aperture_radius_;
}

CameraRay CameraRayGenerator::operator()(float x, float y, float lens_u, float lens_v) const {
    CameraRay ray = (*this)(x, y);
    if (!ray.valid || aperture_radius_ <= 0.0f) return ray;
    // In world space, from the pinhole ray (origin o, unit direction d): the ray leaves the aperture point and meets
    // the pinhole ray where that reaches the focus (Cycles, kernel/camera/camera.h):
    //   perspective   (camera_sample_perspective): lens point o + u X + v Y, focus point o + d f / cos, cos = d . view
    //                 axis (the focus plane is perpendicular to the view axis);
    //   orthographic  (camera_sample_orthographic): the same from the pixel's point o on the camera plane, where the
    //                 pinhole ray runs along the view axis (cos = 1);
    //   panoramic     (camera_sample_panorama): focus point o + d f (a sphere), the lens in the plane normal to d, its
    //                 axes U = the view axis made normal to d, V = d x U.
    // Clipping: a perspective or orthographic ray keeps the clip planes perpendicular to the view axis (distances
    // along the ray grow by 1 / cos of its angle to the axis: for perspective the pinhole ray's, as Cycles' nearclip *
    // z_inv, for orthographic the lens ray's); a panoramic one clips at the same distances along the ray.
    const glm::vec3 o(ray.origin[0], ray.origin[1], ray.origin[2]),
        d(ray.direction[0], ray.direction[1], ray.direction[2]);
    const glm::vec3 ax(axis_x_[0], axis_x_[1], axis_x_[2]), ay(axis_y_[0], axis_y_[1], axis_y_[2]),
        fw(forward_[0], forward_[1], forward_[2]);
    float lens[2];
    aperture_point(lens_u, lens_v, lens);
    glm::vec3 focus, lens_point;
    switch (camera_.type) {
        case CameraType::Perspective:
            focus = o + d * (focus_distance_ / glm::dot(d, fw));
            lens_point = o + ax * lens[0] + ay * lens[1];
            break;
        case CameraType::Orthographic:
            focus = o + d * focus_distance_;
            lens_point = o + ax * lens[0] + ay * lens[1];
            break;
        case CameraType::Equirectangular:
        case CameraType::FisheyeEquidistant:
        case CameraType::FisheyeEquisolid: {
            focus = o + d * focus_distance_;
            glm::vec3 u = fw - glm::dot(d, fw) * d;
            const float ul = glm::length(u);
            // Looking straight along the view axis U is undefined (Cycles divides by zero there): any normal will do.
            u = ul > 1e-6f ? u / ul : ax;
            lens_point = o + u * lens[0] + glm::cross(d, u) * lens[1];
            break;
        }
    }
    const glm::vec3 dir = glm::normalize(focus - lens_point);
    const float clip_scale = camera_.type == CameraType::Orthographic ? 1.0f / glm::dot(dir, fw) : 1.0f;
    for (int i = 0; i < 3; ++i) {
        ray.origin[i] = lens_point[i];
        ray.direction[i] = dir[i];
    }
    ray.t_min *= clip_scale;
    ray.t_max *= clip_scale;
    return ray;
}

CameraRayGenerator::PinholeProjection CameraRayGenerator::pinhole_projection() const {
    // Inverse of operator()'s perspective mapping: X / z = (2 x / w - 1) half_w + shift_x extent, and Y / z likewise
    // with the image's y growing down.
    PinholeProjection p;
    p.half_width_tan = half_w_;
    p.half_height_tan = half_h_;
    p.center_x_tan = camera_.shift_x * extent_;
    p.center_y_tan = camera_.shift_y * extent_;
    p.fx = 0.5f * width_ / half_w_;
    p.fy = 0.5f * height_ / half_h_;
    p.cx = 0.5f * width_ - p.center_x_tan * p.fx;
    p.cy = 0.5f * height_ + p.center_y_tan * p.fy;
    return p;
}

CameraRay CameraRayGenerator::operator()(float x, float y) const {
    const Camera& c = camera_;
    CameraRay ray{};
    ray.valid = true;
    const float w = width_, h = height_;
    glm::vec3 org(0.0f), dir(0.0f, 0.0f, -1.0f);
    float t_min = c.clip_start, t_max = c.clip_end;

    switch (c.type) {
        case CameraType::Perspective:
        case CameraType::Orthographic: {
            const float px = (2.0f * x / w - 1.0f) * half_w_ + c.shift_x * extent_;
            const float py = (1.0f - 2.0f * y / h) * half_h_ + c.shift_y * extent_;
            if (c.type == CameraType::Perspective) {
                dir = glm::vec3(px, py, -1.0f);
                const float len = glm::length(dir);
                dir /= len;
                // Clipping planes are perpendicular to the view axis: t = clip / cos(angle to the axis).
                t_min = c.clip_start * len;
                t_max = c.clip_end * len;
            } else {
                org = glm::vec3(px, py, 0.0f);
            }
            break;
        }
        case CameraType::Equirectangular: {
            const float u = x / w, v = 1.0f - y / h;  // v from the bottom, as in Cycles' raster
            const float lon = c.longitude_min + u * (c.longitude_max - c.longitude_min);
            const float lat = c.latitude_min + v * (c.latitude_max - c.latitude_min);
            dir = glm::vec3(std::cos(lat) * std::sin(lon), std::sin(lat), -std::cos(lat) * std::cos(lon));
            break;
        }
        case CameraType::FisheyeEquidistant: {
            // Cycles fisheye_to_direction: u, v in [-1, 1] across each image axis, theta = r * fov / 2.
            const float u = 2.0f * (x / w) - 1.0f, v = 1.0f - 2.0f * (y / h);
            const float r = std::sqrt(u * u + v * v);
            if (r > 1.0f) {
                ray.valid = false;
                break;
            }
            const float theta = r * 0.5f * c.fisheye_fov;
            const float cu = r > 0.0f ? u / r : 1.0f, cv = r > 0.0f ? v / r : 0.0f;
            dir = glm::vec3(std::sin(theta) * cu, std::sin(theta) * cv, -std::cos(theta));
            break;
        }
        case CameraType::FisheyeEquisolid: {
            // Cycles fisheye_equisolid_to_direction: position on the fitted sensor in mm, r = 2 f sin(theta / 2).
            const float u = (x / w - 0.5f) * sensor_w_, v = (0.5f - y / h) * sensor_h_;
            const float r = std::sqrt(u * u + v * v);
            const float s = r / (2.0f * c.fisheye_lens_mm);
            if (s > 1.0f) {
                ray.valid = false;
                break;
            }
            const float theta = 2.0f * std::asin(s);
            if (theta > 0.5f * c.fisheye_fov) {
                ray.valid = false;
                break;
            }
            const float cu = r > 0.0f ? u / r : 1.0f, cv = r > 0.0f ? v / r : 0.0f;
            dir = glm::vec3(std::sin(theta) * cu, std::sin(theta) * cv, -std::cos(theta));
            break;
        }
    }

    const float* a = linear_;
    const glm::vec3 o(a[0] * org.x + a[1] * org.y + a[2] * org.z + translation_[0],
                      a[3] * org.x + a[4] * org.y + a[5] * org.z + translation_[1],
                      a[6] * org.x + a[7] * org.y + a[8] * org.z + translation_[2]);
    glm::vec3 d(a[0] * dir.x + a[1] * dir.y + a[2] * dir.z, a[3] * dir.x + a[4] * dir.y + a[5] * dir.z,
                a[6] * dir.x + a[7] * dir.y + a[8] * dir.z);
    const float dl = glm::length(d);
    d /= dl;
    // A scaled camera matrix scales distances too: keep the clip range in world units along the ray.
    for (int i = 0; i < 3; ++i) {
        ray.origin[i] = o[i];
        ray.direction[i] = d[i];
    }
    ray.t_min = t_min * dl;
    ray.t_max = t_max * dl;
    return ray;
}

}  // namespace raysplats
