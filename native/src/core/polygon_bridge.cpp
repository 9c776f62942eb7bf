// The forward bridge of design.md §5: Gaussians -> polygon meshes (the polygon of each Gaussian and the per-face
// attributes an import stores). The geometry of one face is in polygon_frame.h, the way back in
// polygon_recovery.cpp, the edit checks in polygon_change_detection.cpp.
#include "raysplats/polygon_bridge.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <string>

#include "core/color_math.h"
#include "core/linear_algebra.h"
#include "core/polygon_frame.h"
#include "raysplats/errors.h"
#include "raysplats/spherical_harmonics.h"

namespace raysplats {
namespace {

using la::Mat3;
using la::Vec3;
using polygon::PolygonAngles;
using polygon::polygon_of_gaussian;

// a / (1/255): something of the Gaussian is visible when it exceeds 1 (then its logarithm is positive).
double visibility_ratio(float opacity) { return double(opacity) / kVisibleOpacity; }

}  // namespace

float gaussian_thickness(const float scales[3]) {
    float sorted[3] = {scales[0], scales[1], scales[2]};
    std::sort(sorted, sorted + 3, [](float a, float b) { return a > b; });
    const double plane = std::sqrt(double(sorted[0]) * sorted[1]);
    return plane > 0 ? float(sorted[2] / plane) : 0.0f;
}

float visible_polygon_radius(float opacity, float rho) {
    // a·exp(-r²/2) >= 1/255  <=>  r² <= 2 ln(a / (1/255)); nothing is visible when the logarithm is not positive.
    const double ratio = visibility_ratio(opacity);
    if (!(ratio > 1.0)) return 0.0f;
    return float(std::min(double(rho), std::sqrt(2 * std::log(ratio))));
}

void PolygonSettings::validate() const {
    if (vertices_per_polygon < kMinPolygonVertices || vertices_per_polygon > kMaxPolygonVertices)
        throw InvalidArgument("polygon vertex count K must be 3..64, got " + std::to_string(vertices_per_polygon));
    if (!(radius > 0.0f) || !std::isfinite(radius))
        throw InvalidArgument("polygon radius rho must be a positive number, got " + std::to_string(radius));
}

void gaussian_polygon(const float center[3], const float rotation_wxyz[4], const float scales[3],
                      const PolygonSettings& settings, float* out) {
    settings.validate();
    polygon_of_gaussian(center, rotation_wxyz, scales, PolygonAngles(settings.vertices_per_polygon), settings.radius,
                        out);
}

void gaussian_polygons(const GaussianCloud& cloud, std::size_t begin, std::size_t end, const PolygonSettings& settings,
                       float* out, std::size_t stride, const float* polygon_radius) {
    settings.validate();
    if (stride < 3 * std::size_t(settings.vertices_per_polygon) || end > cloud.size() || begin > end)
        throw InvalidArgument("gaussian_polygons: bad range or stride");
    const PolygonAngles angles(settings.vertices_per_polygon);
    for (std::size_t i = begin; i < end; ++i) {
        const float rho = polygon_radius ? polygon_radius[i] : settings.radius;
        if (!(rho >= 0.0f) || !std::isfinite(rho))
            throw InvalidArgument("polygon radius of Gaussian " + std::to_string(i) +
                                  " must be a non-negative number, got " + std::to_string(rho));
        polygon_of_gaussian(&cloud.positions[3 * i], &cloud.rotations[4 * i], &cloud.scales[3 * i], angles, rho,
                            out + (i - begin) * stride);
    }
}

namespace {

// The arrays of nf faces of kc corners each, sized (filled by write_face).
void size_polygons(std::size_t nf, int kc, std::size_t sh_per_gaussian, SplatPolygons& out) {
    const std::size_t corners = nf * kc;
    out.vertex_positions.resize(3 * corners);
    out.corner_vertices.resize(corners);
    out.face_corner_start.resize(nf);
    out.face_corner_count.assign(nf, kc);
    out.edge_vertices.resize(2 * corners);
    out.corner_edges.resize(corners);
    out.thickness.resize(nf);
    out.sh_local.resize(nf * sh_per_gaussian);
    out.corner_colors.resize(4 * corners);
    out.corner_uvs.resize(2 * corners);
    out.polygon_radius.resize(nf);
    out.opacity.resize(nf);
    out.rest_centers.resize(3 * nf);
    out.rest_rotations.resize(4 * nf);
    out.rest_scales.resize(3 * nf);
}

// Face f's corners, edges and UVs: an independent K-gon whose corner k is vertex base + k, with UV
// (rho_i cos θ_k, rho_i sin θ_k).
void write_face_topology(std::size_t f, const PolygonAngles& angles, float rho, SplatPolygons& out) {
    const int kc = angles.count;
    const std::int32_t base = std::int32_t(f * kc);
    out.face_corner_start[f] = base;
    for (int k = 0; k < kc; ++k) {
        const std::size_t c = std::size_t(base) + k;
        out.corner_vertices[c] = std::int32_t(c);
        out.edge_vertices[2 * c] = std::int32_t(c);
        out.edge_vertices[2 * c + 1] = base + (k + 1) % kc;
        out.corner_edges[c] = std::int32_t(c);
        out.corner_uvs[2 * c] = float(double(rho) * angles.cos[k]);
        out.corner_uvs[2 * c + 1] = float(double(rho) * angles.sin[k]);
    }
}

// Face f's copy of Gaussian i (what recovery reads back: rest centre, rotation, scales, opacity, thickness, rho_i).
void write_face_rest(const GaussianCloud& cloud, std::size_t i, std::size_t f, float rho, SplatPolygons& out) {
    out.thickness[f] = gaussian_thickness(&cloud.scales[3 * i]);
    out.polygon_radius[f] = rho;
    out.opacity[f] = cloud.opacities[i];
    std::memcpy(&out.rest_centers[3 * f], &cloud.positions[3 * i], 3 * sizeof(float));
    std::memcpy(&out.rest_rotations[4 * f], &cloud.rotations[4 * i], 4 * sizeof(float));
    std::memcpy(&out.rest_scales[3 * f], &cloud.scales[3 * i], 3 * sizeof(float));
}

// Face f's SH in its local frame (SH_local = D(F^T) SH_world, F the frame of its kc vertices `pos`) and its corner
// colour (the DC colour's sRGB bytes and the opacity).
void write_face_colour(const GaussianCloud& cloud, std::size_t i, std::size_t f, const float* pos, int kc,
                       SplatPolygons& out) {
    const std::size_t sh_per_gaussian = std::size_t(cloud.coeffs_per_channel()) * 3;
    const float* sh = &cloud.sh[i * sh_per_gaussian];
    float* local = &out.sh_local[f * sh_per_gaussian];
    if (cloud.sh_degree > 0) {
        Vec3 verts[kMaxPolygonVertices];
        Vec3 center;
        for (int k = 0; k < kc; ++k) {
            verts[k] = Vec3(pos[3 * k], pos[3 * k + 1], pos[3 * k + 2]);
            center = center + verts[k];
        }
        const Mat3 ft = la::transpose(polygon::polygon_frame(verts, kc, center * (1.0 / kc)));
        rotate_sh(cloud.sh_degree, ft.m, sh, local);
    } else {
        std::memcpy(local, sh, sizeof(float) * 3);
    }
    const std::uint8_t rgba[4] = {sh_dc_to_srgb_byte(sh[0]), sh_dc_to_srgb_byte(sh[1]), sh_dc_to_srgb_byte(sh[2]),
                                  unit_to_byte(cloud.opacities[i])};
    for (int k = 0; k < kc; ++k) std::memcpy(&out.corner_colors[4 * (f * kc + k)], rgba, sizeof(rgba));
}

}  // namespace

SplatPolygons gaussians_to_polygons(const GaussianCloud& cloud, const PolygonSettings& settings) {
    settings.validate();
    cloud.check_consistent();
    const std::size_t n = cloud.size();
    // The Gaussians with something visible (rho_i > 0) get a face each.
    std::vector<std::uint32_t> gaussian_of_face;
    gaussian_of_face.reserve(n);
    for (std::size_t i = 0; i < n; ++i)
        if (visibility_ratio(cloud.opacities[i]) > 1.0) gaussian_of_face.push_back(std::uint32_t(i));
    const std::size_t nf = gaussian_of_face.size();

    const int kc = settings.vertices_per_polygon;
    if (nf * kc > std::size_t(INT32_MAX))
        throw InvalidArgument(std::to_string(nf) + " Gaussians with K = " + std::to_string(kc) +
                              " need more polygon corners than a Blender mesh can index");
    SplatPolygons out;
    out.invisible_skipped = n - nf;
    out.sh_degree = cloud.sh_degree;
    size_polygons(nf, kc, std::size_t(cloud.coeffs_per_channel()) * 3, out);

    const PolygonAngles angles(kc);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nf, polygon::kFacesPerTask),
                      [&](const tbb::blocked_range<std::size_t>& range) {
        for (std::size_t f = range.begin(); f != range.end(); ++f) {
            const std::size_t i = gaussian_of_face[f];
            const float rho = visible_polygon_radius(cloud.opacities[i], settings.radius);
            float* pos = &out.vertex_positions[3 * (f * kc)];
            polygon_of_gaussian(&cloud.positions[3 * i], &cloud.rotations[4 * i], &cloud.scales[3 * i], angles, rho, pos);
            write_face_topology(f, angles, rho, out);
            write_face_rest(cloud, i, f, rho, out);
            write_face_colour(cloud, i, f, pos, kc, out);
        }
    });
    return out;
}

PolygonMeshView mesh_view(const SplatPolygons& p) {
    PolygonMeshView v;
    v.vertex_positions = p.vertex_positions.data();
    v.vertex_count = p.vertex_positions.size() / 3;
    v.corner_vertices = p.corner_vertices.data();
    v.corner_count = p.corner_vertices.size();
    v.face_corner_start = p.face_corner_start.data();
    v.face_corner_count = p.face_corner_count.data();
    v.face_count = p.face_corner_start.size();
    return v;
}

SplatFaceAttributesView attributes_view(const SplatPolygons& p) {
    SplatFaceAttributesView a;
    a.opacity = p.opacity.data();
    a.thickness = p.thickness.data();
    a.polygon_radius = p.polygon_radius.data();
    a.sh_degree = p.sh_degree;
    a.sh_local = p.sh_local.data();
    a.rest_centers = p.rest_centers.data();
    a.rest_rotations = p.rest_rotations.data();
    a.rest_scales = p.rest_scales.data();
    return a;
}

}  // namespace raysplats
