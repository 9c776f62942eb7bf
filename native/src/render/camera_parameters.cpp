// The camera's vocabulary (raysplats/render/camera_parameters.h).
#include "raysplats/render/camera_parameters.h"

namespace raysplats {

const NameTable<CameraType>& camera_model_names() {
    static const NameTable<CameraType> names{
        "camera model",
        {{"PERSP", CameraType::Perspective, "perspective (pinhole) camera"},
         {"ORTHO", CameraType::Orthographic, "orthographic camera"},
         {"EQUIRECTANGULAR", CameraType::Equirectangular, "panoramic: longitude/latitude projection"},
         {"FISHEYE_EQUIDISTANT", CameraType::FisheyeEquidistant, "panoramic: image radius proportional to the angle"},
         {"FISHEYE_EQUISOLID", CameraType::FisheyeEquisolid, "panoramic: a real fisheye lens on the fitted sensor"}}};
    return names;
}

const NameTable<SensorFit>& sensor_fit_names() {
    static const NameTable<SensorFit> names{
        "sensor fit",
        {{"AUTO", SensorFit::Auto, "the sensor width spans the larger image dimension"},
         {"HORIZONTAL", SensorFit::Horizontal, "the sensor width spans the image width"},
         {"VERTICAL", SensorFit::Vertical, "the sensor height spans the image height"}}};
    return names;
}

const ParameterTable<Camera>& camera_parameters() {
    using namespace parameter_setters;
    using T = ParameterType;
    using C = Camera;
    static const ParameterTable<Camera> table{
        "camera parameter",
        {{"type", T::Name, "camera model", &named<&C::type, &camera_model_names>, camera_model_names().names()},
         {"matrix", T::Matrix, "camera to world (Blender's matrix_world; the camera looks down -Z, +Y up)",
          &member<&C::camera_to_world>, {}},
         {"lens", T::Real, "focal length (mm)", &member<&C::focal_length_mm>, {}},
         {"sensor_width", T::Real, "sensor width (mm)", &member<&C::sensor_width_mm>, {}},
         {"sensor_height", T::Real, "sensor height (mm)", &member<&C::sensor_height_mm>, {}},
         {"sensor_fit", T::Name, "which image dimension the sensor spans", &named<&C::sensor_fit, &sensor_fit_names>,
          sensor_fit_names().names()},
         {"shift_x", T::Real, "lens shift in units of the fitted image dimension", &member<&C::shift_x>, {}},
         {"shift_y", T::Real, "lens shift in units of the fitted image dimension", &member<&C::shift_y>, {}},
         {"clip_start", T::Real, "near clipping distance", &member<&C::clip_start>, {}},
         {"clip_end", T::Real, "far clipping distance", &member<&C::clip_end>, {}},
         {"ortho_scale", T::Real, "orthographic: width of the fitted image dimension in scene units",
          &member<&C::ortho_scale>, {}},
         {"longitude_min", T::Real, "equirectangular: longitude at the left edge (radians)", &member<&C::longitude_min>, {}},
         {"longitude_max", T::Real, "equirectangular: longitude at the right edge (radians)", &member<&C::longitude_max>, {}},
         {"latitude_min", T::Real, "equirectangular: latitude at the bottom edge (radians)", &member<&C::latitude_min>, {}},
         {"latitude_max", T::Real, "equirectangular: latitude at the top edge (radians)", &member<&C::latitude_max>, {}},
         {"fisheye_fov", T::Real, "fisheye: full field of view (radians)", &member<&C::fisheye_fov>, {}},
         {"fisheye_lens", T::Real, "equisolid fisheye: focal length (mm)", &member<&C::fisheye_lens_mm>, {}},
         {"use_dof", T::Bool, "depth of field (a thin lens) instead of a pinhole", &member<&C::use_dof>, {}},
         {"focus_distance", T::Real,
          "depth of field: distance in focus, along the view axis (panoramic: along the ray), scene units",
          &member<&C::focus_distance>, {}},
         {"aperture_fstop", T::Real,
          "depth of field: f-stop; aperture radius = lens / (2 f-stop), 1 / (2 f-stop) for ORTHO (Cycles)",
          &member<&C::aperture_fstop>, {}},
         {"aperture_blades", T::Integer, "depth of field: sides of a polygonal aperture (0: round)",
          &member<&C::aperture_blades>, {}},
         {"aperture_rotation", T::Real, "depth of field: rotation of the polygonal aperture (radians)",
          &member<&C::aperture_rotation>, {}},
         {"aperture_ratio", T::Real, "depth of field: anamorphic ratio (the aperture's width divided by it)",
          &member<&C::aperture_ratio>, {}}}};
    return table;
}

}  // namespace raysplats
