// Every camera model maps pixel centres to the analytically expected world directions (tolerance 1e-5).
#include <gtest/gtest.h>

#include <cmath>

#include "raysplats/errors.h"
#include "raysplats/render/camera.h"

using namespace raysplats;

namespace {

constexpr double kPi = 3.14159265358979323846;

void expect_dir(const CameraRay& r, double x, double y, double z, double tol = 1e-5) {
    const double n = std::sqrt(x * x + y * y + z * z);
    ASSERT_TRUE(r.valid);
    EXPECT_NEAR(r.direction[0], x / n, tol);
    EXPECT_NEAR(r.direction[1], y / n, tol);
    EXPECT_NEAR(r.direction[2], z / n, tol);
}

double angle_from_forward(const CameraRay& r) { return std::acos(std::max(-1.0, std::min(1.0, -double(r.direction[2])))); }

}  // namespace

// Perspective, Auto fit, landscape: the sensor width spans the image width; tan of the half angle at the edge
// pixel centre is (sensor / 2f) * (2 (i + 0.5) / W - 1).
TEST(CameraPerspective, AutoFitLandscapeMatchesPinhole) {
    Camera c;
    c.focal_length_mm = 50;
    c.sensor_width_mm = 36;
    const int w = 64, h = 48;
    for (int j : {0, 17, 47})
        for (int i : {0, 31, 63}) {
            const double tx = (2.0 * (i + 0.5) / w - 1.0) * 18.0 / 50.0;
            const double ty = (1.0 - 2.0 * (j + 0.5) / h) * 18.0 / 50.0 * h / w;
            expect_dir(generate_camera_ray(c, w, h, i + 0.5f, j + 0.5f), tx, ty, -1.0);
        }
}

// Auto fit, portrait: the sensor WIDTH spans the larger dimension (the height), as in Blender.
TEST(CameraPerspective, AutoFitPortraitUsesSensorWidthVertically) {
    Camera c;
    c.focal_length_mm = 35;
    c.sensor_width_mm = 36;
    c.sensor_height_mm = 24;
    const int w = 30, h = 60;
    const CameraRay top = generate_camera_ray(c, w, h, 15.0f, 0.0f);  // top edge, centre column
    EXPECT_NEAR(std::atan2(top.direction[1], -top.direction[2]), std::atan(18.0 / 35.0), 1e-5);
    const CameraRay right = generate_camera_ray(c, w, h, 30.0f, 30.0f);
    EXPECT_NEAR(std::atan2(right.direction[0], -right.direction[2]), std::atan(9.0 / 35.0), 1e-5);
}

// Vertical fit uses the sensor height across the image height; Horizontal the width across the width.
TEST(CameraPerspective, ExplicitSensorFit) {
    Camera c;
    c.focal_length_mm = 20;
    c.sensor_width_mm = 36;
    c.sensor_height_mm = 24;
    c.sensor_fit = SensorFit::Vertical;
    const CameraRay top = generate_camera_ray(c, 100, 50, 50.0f, 0.0f);
    EXPECT_NEAR(std::atan2(top.direction[1], -top.direction[2]), std::atan(12.0 / 20.0), 1e-5);
    c.sensor_fit = SensorFit::Horizontal;
    const CameraRay right = generate_camera_ray(c, 50, 100, 50.0f, 50.0f);
    EXPECT_NEAR(std::atan2(right.direction[0], -right.direction[2]), std::atan(18.0 / 20.0), 1e-5);
}

// Shift moves the image by shift * (fitted sensor extent / focal length) in tangent units.
TEST(CameraPerspective, ShiftAndTransformAndClip) {
    Camera c;
    c.focal_length_mm = 50;
    c.sensor_width_mm = 36;
    c.shift_x = 0.25f;
    c.shift_y = -0.1f;
    c.clip_start = 0.5f;
    c.clip_end = 100.0f;
    const CameraRay centre = generate_camera_ray(c, 40, 40, 20.0f, 20.0f);
    expect_dir(centre, 0.25 * 36.0 / 50.0, -0.1 * 36.0 / 50.0, -1.0);
    // Clipping is by planes perpendicular to the view axis.
    EXPECT_NEAR(centre.t_min * -centre.direction[2], 0.5, 1e-5);
    EXPECT_NEAR(centre.t_max * -centre.direction[2], 100.0, 1e-3);
    // A rotated and moved camera: rotate 90 degrees about +Y, so local -Z becomes world -X.
    c.shift_x = c.shift_y = 0.0f;
    c.camera_to_world = Matrix4::translation(1, 2, 3) * Matrix4::rotation(float(kPi / 2), 0, 1, 0);
    const CameraRay r = generate_camera_ray(c, 40, 40, 20.0f, 20.0f);
    expect_dir(r, -1, 0, 0);
    EXPECT_NEAR(r.origin[0], 1, 1e-6);
    EXPECT_NEAR(r.origin[1], 2, 1e-6);
    EXPECT_NEAR(r.origin[2], 3, 1e-6);
}

// Orthographic: parallel rays along -Z, origins spread over ortho_scale across the fitted dimension.
TEST(CameraOrthographic, ParallelRaysOverOrthoScale) {
    Camera c;
    c.type = CameraType::Orthographic;
    c.ortho_scale = 8.0f;
    c.shift_x = 0.5f;
    const int w = 80, h = 40;
    for (int i : {0, 40, 79}) {
        const CameraRay r = generate_camera_ray(c, w, h, i + 0.5f, 10.5f);
        expect_dir(r, 0, 0, -1);
        EXPECT_NEAR(r.origin[0], ((i + 0.5) / w - 0.5) * 8.0 + 0.5 * 8.0, 1e-5);
        EXPECT_NEAR(r.origin[1], (0.5 - 10.5 / h) * 4.0, 1e-5);
    }
}

// Equirectangular: the centre looks forward (-Z), 3/4 across looks right (+X) with the full longitude range, the
// right edge looks back (+Z), the top edge up (+Y); a restricted range maps linearly.
TEST(CameraEquirectangular, KnownDirections) {
    Camera c;
    c.type = CameraType::Equirectangular;
    const int w = 360, h = 180;
    expect_dir(generate_camera_ray(c, w, h, 180.0f, 90.0f), 0, 0, -1);
    expect_dir(generate_camera_ray(c, w, h, 270.0f, 90.0f), 1, 0, 0);
    expect_dir(generate_camera_ray(c, w, h, 90.0f, 90.0f), -1, 0, 0);
    expect_dir(generate_camera_ray(c, w, h, 360.0f, 90.0f), 0, 0, 1, 1e-4);
    expect_dir(generate_camera_ray(c, w, h, 180.0f, 0.0f), 0, 1, 0, 1e-4);
    expect_dir(generate_camera_ray(c, w, h, 180.0f, 45.0f), 0, std::sin(kPi / 4), -std::cos(kPi / 4));
    c.longitude_min = -0.5f;
    c.longitude_max = 1.0f;
    c.latitude_min = -0.2f;
    c.latitude_max = 0.6f;
    const CameraRay r = generate_camera_ray(c, 100, 50, 25.5f, 10.5f);
    const double lon = -0.5 + 25.5 / 100.0 * 1.5, lat = -0.2 + (1.0 - 10.5 / 50.0) * 0.8;
    expect_dir(r, std::cos(lat) * std::sin(lon), std::sin(lat), -std::cos(lat) * std::cos(lon));
}

// Equidistant fisheye: the angle from the axis is proportional to the radius, r = 1 at the image edge is fov / 2.
TEST(CameraFisheye, EquidistantAngleProportionalToRadius) {
    Camera c;
    c.type = CameraType::FisheyeEquidistant;
    c.fisheye_fov = float(kPi);
    const int n = 100;
    expect_dir(generate_camera_ray(c, n, n, 50.0f, 50.0f), 0, 0, -1);
    // Half way to the right edge: 45 degrees to the right.
    expect_dir(generate_camera_ray(c, n, n, 75.0f, 50.0f), std::sin(kPi / 4), 0, -std::cos(kPi / 4));
    // Upwards at a quarter: 45 degrees up.
    expect_dir(generate_camera_ray(c, n, n, 50.0f, 25.0f), 0, std::sin(kPi / 4), -std::cos(kPi / 4));
    for (int k = 0; k < 20; ++k) {
        const float x = 10.5f + 4 * k, y = 90.5f - 3.7f * k;
        const double u = 2.0 * x / n - 1, v = 1 - 2.0 * y / n, r = std::sqrt(u * u + v * v);
        const CameraRay ray = generate_camera_ray(c, n, n, x, y);
        if (r > 1) {
            EXPECT_FALSE(ray.valid);
            continue;
        }
        EXPECT_NEAR(angle_from_forward(ray), r * kPi / 2, 1e-4);
        EXPECT_NEAR(std::atan2(ray.direction[1], ray.direction[0]), std::atan2(v, u), 1e-4);
    }
    EXPECT_FALSE(generate_camera_ray(c, n, n, 0.5f, 0.5f).valid);  // corner: outside the circle
}

// Equisolid fisheye: the radius on the sensor (mm) is r = 2 f sin(theta / 2); outside fov / 2 there is no ray.
TEST(CameraFisheye, EquisolidRadiusLaw) {
    Camera c;
    c.type = CameraType::FisheyeEquisolid;
    c.fisheye_lens_mm = 10.5f;
    c.fisheye_fov = float(kPi);
    c.sensor_width_mm = 36.0f;
    const int w = 120, h = 80;  // horizontal fit: 36 mm across 120 px, 24 mm across 80 px
    for (int k = 0; k < 20; ++k) {
        const float x = 5.5f + 5.9f * k, y = 7.5f + 3.3f * k;
        const double u = (x / w - 0.5) * 36.0, v = (0.5 - y / h) * 24.0, r = std::sqrt(u * u + v * v);
        const CameraRay ray = generate_camera_ray(c, w, h, x, y);
        if (r / 21.0 > std::sin(kPi / 4)) {  // beyond theta = fov / 2 = 90 degrees
            EXPECT_FALSE(ray.valid);
            continue;
        }
        const double theta = 2 * std::asin(r / 21.0);
        ASSERT_TRUE(ray.valid);
        EXPECT_NEAR(angle_from_forward(ray), theta, 1e-4);
        EXPECT_NEAR(std::atan2(ray.direction[1], ray.direction[0]), std::atan2(v, u), 1e-4);
    }
    c.fisheye_fov = float(kPi / 2);  // 45 degrees half angle: r = 21 sin(22.5 deg) = 8.04 mm
    EXPECT_FALSE(generate_camera_ray(c, w, h, 119.5f, 40.0f).valid);  // 17.85 mm from the centre
    EXPECT_TRUE(generate_camera_ray(c, w, h, 80.0f, 40.0f).valid);    // 6 mm
}

TEST(CameraValidate, RejectsBadParameters) {
    Camera c;
    EXPECT_NO_THROW(c.validate());
    c.focal_length_mm = std::nanf("");
    EXPECT_THROW(c.validate(), InvalidArgument);
    c = Camera{};
    c.clip_end = 0.01f;
    EXPECT_THROW(c.validate(), InvalidArgument);
    c = Camera{};
    c.camera_to_world(0, 3) = std::nanf("");
    EXPECT_THROW(c.validate(), InvalidArgument);
}
