#include "light_sampling.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace raysplats {

bool sample_light(const Light& l, const glm::vec3& p, Sampler& rng, LightSample& out) {
    const glm::vec3 color = glm::vec3(l.color[0], l.color[1], l.color[2]) * l.power;
    const glm::mat3 a = linear_part(l.light_to_world);
    const glm::vec3 pos = translation_part(l.light_to_world);
    const glm::vec3 axis = glm::normalize(a * glm::vec3(0, 0, -1));  // emission direction (local -Z)
    const float u1 = rng.next(), u2 = rng.next();
    switch (l.type) {
        case LightType::Point:
        case LightType::Spot: {
            glm::vec3 to = pos - p;
            const float d2 = glm::dot(to, to);
            if (!(d2 > 0.0f)) return false;
            out.distance = std::sqrt(d2);
            out.wi = to / out.distance;
            // Cycles: radiant intensity I = P / (4 pi) W/sr.
            float att = 1.0f;
            if (l.type == LightType::Spot) {
                // Cycles spot_attenuation: cos(angle) * smoothstep inside the blend band, 0 outside the cone.
                const float spot_angle = std::cos(0.5f * l.spot_size);
                const float spot_smooth = (1.0f - spot_angle) * l.spot_blend;
                att = glm::dot(-out.wi, axis);
                if (att <= spot_angle) return false;
                const float t = att - spot_angle;
                if (t < spot_smooth && spot_smooth != 0.0f) {
                    const float x = t / spot_smooth;
                    att *= x * x * (3.0f - 2.0f * x);
                }
            }
            out.value = color * (att / (4.0f * kPi * d2));
            out.pdf = 0.0f;
            return true;
        }
        case LightType::Sun: {
            // Direction towards the sun is the light's +Z; a finite angular diameter is sampled uniformly in the cone,
            // and radiance / pdf = (S / solid angle) / (1 / solid angle) = S.
            glm::vec3 w = -axis;
            if (l.sun_angle > 0.0f) {
                const float cos_max = std::cos(0.5f * l.sun_angle);
                const float cos_t = 1.0f - u1 * (1.0f - cos_max);
                const float sin_t = std::sqrt(std::max(0.0f, 1.0f - cos_t * cos_t));
                glm::vec3 t, b;
                make_frame(w, t, b);
                const float phi = 2.0f * kPi * u2;
                w = glm::normalize(sin_t * std::cos(phi) * t + sin_t * std::sin(phi) * b + cos_t * w);
            }
            out.wi = w;
            out.distance = std::numeric_limits<float>::infinity();
            out.value = color;
            out.pdf = 0.0f;  // the sun is not hit by rays; its samples need no MIS weight
            return true;
        }
        case LightType::AreaRectangle:
        case LightType::AreaDisk: {
            const glm::vec3 ax = a * glm::vec3(l.size_x, 0, 0);
            const glm::vec3 ay = a * glm::vec3(0, l.type == LightType::AreaDisk ? l.size_x : l.size_y, 0);
            float sx, sy, area;
            if (l.type == LightType::AreaRectangle) {
                sx = u1 - 0.5f;
                sy = u2 - 0.5f;
                area = glm::length(glm::cross(ax, ay));
            } else {
                const float r = 0.5f * std::sqrt(u1), phi = 2.0f * kPi * u2;
                sx = r * std::cos(phi);
                sy = r * std::sin(phi);
                area = 0.25f * kPi * glm::length(glm::cross(ax, ay));
            }
            const glm::vec3 q = pos + sx * ax + sy * ay;
            const glm::vec3 to = q - p;
            const float d2 = glm::dot(to, to);
            if (!(d2 > 0.0f) || !(area > 0.0f)) return false;
            out.distance = std::sqrt(d2);
            out.wi = to / out.distance;
            const float cos_l = glm::dot(-out.wi, axis);
            if (cos_l <= 0.0f) return false;
            // Cycles: radiance L = P / (4 A); uniform area sampling: value = L cos_l A / d^2.
            out.value = color * (0.25f / area) * (cos_l * area / d2);
            out.pdf = d2 / (cos_l * area);
            return true;
        }
    }
    return false;
}

bool intersect_light(const Light& l, const glm::vec3& o, const glm::vec3& d, float tmax, LightHit& out) {
    if (l.type != LightType::AreaRectangle && l.type != LightType::AreaDisk) return false;
    const glm::mat3 a = linear_part(l.light_to_world);
    const glm::vec3 pos = translation_part(l.light_to_world);
    const glm::vec3 ax = a * glm::vec3(l.size_x, 0, 0);
    const glm::vec3 ay = a * glm::vec3(0, l.type == LightType::AreaDisk ? l.size_x : l.size_y, 0);
    const glm::vec3 nrm = glm::cross(ax, ay);
    const float area_par = glm::length(nrm);
    if (!(area_par > 0.0f)) return false;
    const glm::vec3 axis = glm::normalize(a * glm::vec3(0, 0, -1));  // emission direction
    const float cos_l = -glm::dot(d, axis);
    if (cos_l <= 0.0f) return false;  // back side: emits nothing towards o
    const glm::vec3 un = nrm / area_par;
    const float denom = glm::dot(d, un);
    if (std::abs(denom) < 1e-12f) return false;
    const float t = glm::dot(pos - o, un) / denom;
    if (!(t > 0.0f) || !(t < tmax)) return false;
    // Coordinates of the hit in the (ax, ay) parallelogram frame, in [-1/2, 1/2].
    const glm::vec3 q = o + t * d - pos;
    const glm::vec3 ex = glm::cross(ay, un) / area_par, ey = glm::cross(un, ax) / area_par;  // dual basis
    const float sx = glm::dot(q, ex), sy = glm::dot(q, ey);
    float area;
    if (l.type == LightType::AreaRectangle) {
        if (std::abs(sx) > 0.5f || std::abs(sy) > 0.5f) return false;
        area = area_par;
    } else {
        if (sx * sx + sy * sy > 0.25f) return false;
        area = 0.25f * kPi * area_par;
    }
    out.t = t;
    out.radiance = glm::vec3(l.color[0], l.color[1], l.color[2]) * (l.power * 0.25f / area);
    out.pdf = t * t / (cos_l * area);
    return true;
}

}  // namespace raysplats
