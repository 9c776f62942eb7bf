// Lights in Blender/Cycles units (docs/design.md §6). Point, spot and sun lights are delta lights, reached by
// next-event estimation only; area lights are also visible to camera and reflection rays (one-sided), and
// both ways of reaching them are combined by multiple importance sampling (power heuristic), as in Cycles.
//
// Unit conventions, from Cycles 3.x (intern/cycles/kernel/light/light.h, lamp_light_sample, and
// intern/cycles/kernel/closure/emissive.h, whose emission closure evaluates to 1):
//   point, spot : eval_fac = 1/(4 pi) * invarea, invarea = 1 for radius 0, so a light of power P watts has
//                 radiant intensity I = P / (4 pi) W/sr (a spot does NOT concentrate its power into the cone).
//   spot cone   : attenuation = 0 outside cos(size/2); inside, smoothstep(0, (1 - cos(size/2)) * blend, t)
//                 with t = cos(angle) - cos(size/2)  (Cycles spot_attenuation).
//   area        : eval_fac = 0.25 * invarea, so the emitted radiance is L = P / (4 A) W/(m^2 sr), one-sided
//                 (towards the light's -Z). Note: not P / (pi A) — Blender's area-light "watts" emit pi/4 P.
//   sun         : strength S is the irradiance S W/m^2 on a surface facing the sun.
//   world       : colour * strength is the radiance of a uniform environment.
#pragma once

#include <array>

#include "raysplats/render/transform.h"

namespace raysplats {

enum class LightType { Point, Sun, Spot, AreaRectangle, AreaDisk };

struct Light {
    LightType type = LightType::Point;
    std::array<float, 3> color{1.0f, 1.0f, 1.0f};
    // Watts for point, spot and area lights; W/m^2 (Blender's "Strength") for the sun.
    float power = 1000.0f;
    // Position = translation; point/spot/area emit along local -Z (the sun shines along its local -Z).
    Matrix4 light_to_world;
    float spot_size = 0.785398163f;  // full cone angle, radians
    float spot_blend = 0.15f;
    float size_x = 1.0f;  // area rectangle extent along local X; disk diameter
    float size_y = 1.0f;  // area rectangle extent along local Y
    float sun_angle = 0.0f;  // angular diameter of the sun (radians); > 0 gives soft shadows

    void validate(const char* what) const;
};

struct World {
    std::array<float, 3> color{0.050876f, 0.050876f, 0.050876f};  // Blender's default world grey
    float strength = 1.0f;
    // The Mist pass (Blender's World > Mist Pass; Cycles kernel/film/data_passes.h): at distance d from the camera,
    // mist = clamp((d - mist_start) / mist_depth, 0, 1) ^ mist_falloff (Blender's falloffs: QUADRATIC 2, LINEAR 1,
    // INVERSE_QUADRATIC 0.5; a depth of 0 gives mist 0 everywhere, as Cycles' mist_inv_depth = 0 does). The defaults
    // are Cycles' film defaults, which a Blender scene without a World renders with.
    float mist_start = 0.0f;
    float mist_depth = 100.0f;
    float mist_falloff = 1.0f;
};

}  // namespace raysplats
