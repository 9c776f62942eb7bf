// The camera's vocabulary, shared by every front end (the add-on's camera dict, the JSON tool's "camera"
// object): the camera models by name, spelt as Blender spells them (Camera.type "PERSP"/"ORTHO", and the
// panorama types for "PANO"), and every Camera field by name. Angles are radians everywhere, as in Blender's
// Python API; lengths of the lens and sensor are millimetres.
#pragma once

#include "raysplats/render/camera.h"
#include "raysplats/render/parameters.h"

namespace raysplats {

// PERSP, ORTHO, EQUIRECTANGULAR, FISHEYE_EQUIDISTANT, FISHEYE_EQUISOLID.
const NameTable<CameraType>& camera_model_names();
// AUTO, HORIZONTAL, VERTICAL (Blender's Camera.sensor_fit).
const NameTable<SensorFit>& sensor_fit_names();

// type, matrix, lens, sensor_width, sensor_height, sensor_fit, shift_x, shift_y, clip_start, clip_end,
// ortho_scale, longitude_min/max, latitude_min/max, fisheye_fov, fisheye_lens, and depth of field's use_dof,
// focus_distance, aperture_fstop, aperture_blades, aperture_rotation, aperture_ratio: Blender's names for them
// (Camera.dof's for the last six).
const ParameterTable<Camera>& camera_parameters();

}  // namespace raysplats
