// Building export meshes (splat patches, ordinary triangle meshes, raw polygons) and dispatching to the
// format writers. The patch construction is the formula at the top of raysplats/mesh_export.h.
#include "raysplats/mesh_export.h"

#include <glm/gtc/constants.hpp>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <numeric>

#include "io/io_common.h"
#include "io/mesh_writers.h"
#include "raysplats/errors.h"

namespace raysplats {

namespace {

void transform_point(const double m[16], const float in[3], float out[3]) {
    for (int r = 0; r < 3; ++r)
        out[r] = float(m[4 * r] * in[0] + m[4 * r + 1] * in[1] + m[4 * r + 2] * in[2] + m[4 * r + 3]);
}

// Normal matrix: inverse transpose of the linear part (cofactor matrix; the scale does not matter as the
// result is normalised).
void normal_matrix(const double m[16], double n[9]) {
    const double a = m[0], b = m[1], c = m[2], d = m[4], e = m[5], f = m[6], g = m[8], h = m[9], i = m[10];
    const double cof[9] = {e * i - f * h, -(d * i - f * g), d * h - e * g,
                           -(b * i - c * h), a * i - c * g, -(a * h - b * g),
                           b * f - c * e, -(a * f - c * d), a * e - b * d};
    const double det = a * cof[0] + b * cof[1] + c * cof[2];
    for (int k = 0; k < 9; ++k) n[k] = det < 0 ? -cof[k] : cof[k];
}

void transform_normal(const double n[9], const float in[3], float out[3]) {
    double v[3];
    for (int r = 0; r < 3; ++r) v[r] = n[3 * r] * in[0] + n[3 * r + 1] * in[1] + n[3 * r + 2] * in[2];
    const double len = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    for (int r = 0; r < 3; ++r) out[r] = len > 0 ? float(v[r] / len) : (r == 2 ? 1.0f : 0.0f);
}

bool is_identity(const double m[16]) {
    for (int k = 0; k < 16; ++k)
        if (m[k] != ((k % 5 == 0) ? 1.0 : 0.0)) return false;
    return true;
}

}  // namespace

void ExportMesh::check_consistent() const {
    const std::size_t v = vertex_count();
    auto fail = [&](const std::string& what) { throw InvalidArgument("export mesh '" + name + "': " + what); };
    if (positions.size() != 3 * v) fail("positions are not 3 per vertex");
    if (!normals.empty() && normals.size() != 3 * v) fail("normals are not 3 per vertex");
    if (!colors.empty() && colors.size() != 4 * v) fail("colours are not 4 per vertex");
    if (!uvs.empty() && uvs.size() != 2 * v) fail("UVs are not 2 per vertex");
    if (triangles.size() % 3) fail("triangle indices are not 3 per triangle");
    for (const ExportMeshPart& p : parts) {
        if (p.vertex_begin + p.vertex_count > v || p.triangle_begin + p.triangle_count > triangle_count())
            fail("a part lies outside the mesh's arrays");
        for (std::size_t t = 3 * p.triangle_begin; t < 3 * (p.triangle_begin + p.triangle_count); ++t)
            if (triangles[t] >= p.vertex_count)
                fail("triangle " + std::to_string(t / 3) + " indexes vertex " + std::to_string(triangles[t]) +
                     " outside its part of " + std::to_string(p.vertex_count) + " vertices");
    }
}

MeshFileFormat mesh_format_from_path(const std::string& path) {
    const std::string ext = io::lower_extension(path);
    if (ext == ".obj") return MeshFileFormat::Obj;
    if (ext == ".ply") return MeshFileFormat::Ply;
    if (ext == ".gltf") return MeshFileFormat::Gltf;
    if (ext == ".glb") return MeshFileFormat::Glb;
    throw InvalidArgument("'" + path + "': unknown mesh format '" + ext + "'; use .obj, .ply, .gltf or .glb");
}

MeshWriteStats write_mesh_file(const std::string& path, const ExportScene& scene, const MeshWriteOptions& options) {
    const MeshFileFormat format = mesh_format_from_path(path);
    std::size_t triangles = 0, gaussians = 0;
    for (const ExportMesh& m : scene.meshes) {
        m.check_consistent();
        triangles += m.triangle_count();
        for (const ExportMeshPart& p : m.parts)
            if (p.material >= int(scene.materials.size()))
                throw InvalidArgument("export mesh '" + m.name + "': material index " + std::to_string(p.material) +
                                      " out of range");
    }
    for (const ExportGaussians& g : scene.gaussians) g.cloud.check_consistent(), gaussians += g.cloud.size();
    const bool with_gaussians = options.gaussian_splatting_extension &&
                                (format == MeshFileFormat::Gltf || format == MeshFileFormat::Glb) && gaussians > 0;
    if (triangles == 0 && !with_gaussians)
        throw InvalidArgument("'" + path + "': nothing to export (the scene has no triangles)");
    const auto& d = options.draco;
    if (d.enabled && (d.position_bits < 1 || d.position_bits > 30 || d.normal_bits < 1 || d.normal_bits > 30 ||
                      d.uv_bits < 1 || d.uv_bits > 30 ||
                      d.compression_level < 0 || d.compression_level > 10))
        throw InvalidArgument("Draco quantisation bits must be in 1..30 and the compression level in 0..10");
    switch (format) {
        case MeshFileFormat::Obj: return io::write_obj(path, scene);
        case MeshFileFormat::Ply: return io::write_ply(path, scene);
        case MeshFileFormat::Gltf: return io::write_gltf(path, scene, options, false);
        case MeshFileFormat::Glb: return io::write_gltf(path, scene, options, true);
    }
    throw InvalidArgument("unknown mesh format");
}

ExportMesh splat_patches(const GaussianCloud& cloud, const PolygonSettings& settings, const std::string& name,
                         int material) {
    settings.validate();
    cloud.check_consistent();
    const std::size_t n = cloud.size();
    const int K = settings.vertices_per_polygon;
    const std::size_t vpg = std::size_t(K) + 1;  // vertices per Gaussian: centre + rim
    const int coeffs = cloud.coeffs_per_channel();
    // rho_i of every Gaussian: the radius its polygon had on import (polygon_bridge.h).
    std::vector<float> polygon_radius(n);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, io::kGrain), [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i)
            polygon_radius[i] = visible_polygon_radius(cloud.opacities[i], settings.radius);
    });

    ExportMesh mesh;
    mesh.name = name;
    mesh.positions.resize(3 * vpg * n);
    mesh.normals.resize(3 * vpg * n);
    mesh.colors.resize(4 * vpg * n);
    mesh.uvs.resize(2 * vpg * n);
    mesh.triangles.resize(3 * std::size_t(K) * n);

    // Parts of at most 65535 vertices (16-bit indices in glTF); the triangle indices repeat per part.
    const std::size_t per_part = 65535 / vpg;
    for (std::size_t g = 0; g < n; g += per_part) {
        const std::size_t count = std::min(per_part, n - g);
        mesh.parts.push_back({g * vpg, count * vpg, g * K, count * K, material});
    }
    std::vector<double> rim_cos(K), rim_sin(K);
    for (int k = 0; k < K; ++k) {
        const double theta = glm::two_pi<double>() * k / K;  // M_PI is POSIX, not C++
        rim_cos[k] = std::cos(theta);
        rim_sin[k] = std::sin(theta);
    }

    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, io::kGrain / 4), [&](const tbb::blocked_range<std::size_t>& r) {
        // Rim vertices straight into place, after each Gaussian's centre vertex.
        gaussian_polygons(cloud, r.begin(), r.end(), settings, &mesh.positions[3 * (r.begin() * vpg + 1)], 3 * vpg,
                          polygon_radius.data());
        for (std::size_t i = r.begin(); i != r.end(); ++i) {
            const float* m = &cloud.positions[3 * i];
            const float* rim = &mesh.positions[3 * (i * vpg + 1)];
            // Normal by the winding (a1 × a2): (v0 - m) × (v1 - m) over consecutive rim vertices is
            // proportional to it for any K >= 3.
            double e1[3], e2[3];
            for (int c = 0; c < 3; ++c) e1[c] = double(rim[c]) - m[c], e2[c] = double(rim[3 + c]) - m[c];
            double nrm[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]};
            const double len = std::sqrt(nrm[0] * nrm[0] + nrm[1] * nrm[1] + nrm[2] * nrm[2]);
            float normal[3] = {0.0f, 0.0f, 1.0f};
            if (len > 0 && std::isfinite(len))
                for (int c = 0; c < 3; ++c) normal[c] = float(nrm[c] / len);
            const float* sh = &cloud.sh[i * std::size_t(coeffs) * 3];
            float rgb[3];
            for (int c = 0; c < 3; ++c) rgb[c] = sh_dc_to_linear_unit(sh[c]);
            const float a = std::min(1.0f, std::max(0.0f, cloud.opacities[i]));
            const double rho = polygon_radius[i];
            const float rim_alpha = float(a * std::exp(-0.5 * rho * rho));
            const double rim_uv_radius = 0.5 * rho / settings.radius;  // x = rho (2 uv - 1) on every patch

            const std::size_t v0 = i * vpg;
            float* pos = &mesh.positions[3 * v0];
            float* nor = &mesh.normals[3 * v0];
            float* col = &mesh.colors[4 * v0];
            float* uv = &mesh.uvs[2 * v0];
            std::memcpy(pos, m, 3 * sizeof(float));
            for (std::size_t k = 0; k < vpg; ++k) {
                std::memcpy(nor + 3 * k, normal, sizeof(normal));
                std::memcpy(col + 4 * k, rgb, sizeof(rgb));
                col[4 * k + 3] = k == 0 ? a : rim_alpha;
            }
            uv[0] = uv[1] = 0.5f;
            for (int k = 0; k < K; ++k)
                uv[2 + 2 * k] = float(0.5 + rim_uv_radius * rim_cos[k]), uv[3 + 2 * k] = float(0.5 + rim_uv_radius * rim_sin[k]);

            // Fan from the centre, in the polygon's winding (normal = a1 × a2).
            const std::uint32_t local0 = std::uint32_t(v0 % (per_part * vpg));
            std::uint32_t* tri = &mesh.triangles[3 * i * std::size_t(K)];
            for (int k = 0; k < K; ++k) {
                tri[3 * k] = local0;
                tri[3 * k + 1] = local0 + 1 + std::uint32_t(k);
                tri[3 * k + 2] = local0 + 1 + std::uint32_t((k + 1) % K);
            }
        }
    });
    return mesh;
}

ExportMesh triangle_mesh(const TriangleMeshView& view, const double transform[16], const std::vector<int>& material_slots,
                         const std::vector<ExportMaterial>& materials, const std::string& name) {
    const std::size_t nv = view.vertex_count, nt = view.triangle_count;
    for (std::size_t t = 0; t < 3 * nt; ++t)
        if (view.triangles[t] >= nv)
            throw InvalidArgument("mesh '" + name + "': triangle " + std::to_string(t / 3) + " indexes vertex " +
                                  std::to_string(view.triangles[t]) + " of " + std::to_string(nv));
    auto material_of = [&](std::size_t t) -> int {
        if (!view.triangle_materials) return material_slots.empty() ? -1 : material_slots[0];
        const std::int32_t slot = view.triangle_materials[t];
        if (slot < 0 || std::size_t(slot) >= material_slots.size()) return material_slots.empty() ? -1 : material_slots.back();
        return material_slots[std::size_t(slot)];
    };
    for (int m : material_slots)
        if (m >= int(materials.size())) throw InvalidArgument("mesh '" + name + "': material index out of range");

    // Triangles grouped by material (stable), each group with its own compact vertex set.
    std::vector<std::size_t> order(nt);
    std::iota(order.begin(), order.end(), 0);
    std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return material_of(a) < material_of(b); });

    double nmat[9];
    normal_matrix(transform, nmat);
    ExportMesh mesh;
    mesh.name = name;
    mesh.triangles.reserve(3 * nt);
    std::vector<std::int64_t> remap(nv, -1);
    std::size_t start = 0;
    while (start < nt) {
        const int material = material_of(order[start]);
        std::size_t end = start;
        while (end < nt && material_of(order[end]) == material) ++end;
        ExportMeshPart part;
        part.vertex_begin = mesh.vertex_count();
        part.triangle_begin = mesh.triangle_count();
        part.triangle_count = end - start;
        part.material = material;
        std::vector<std::size_t> used;
        for (std::size_t k = start; k < end; ++k)
            for (int c = 0; c < 3; ++c) {
                const std::uint32_t v = view.triangles[3 * order[k] + c];
                if (remap[v] < 0) remap[v] = std::int64_t(used.size()), used.push_back(v);
                mesh.triangles.push_back(std::uint32_t(remap[v]));
            }
        float base[4] = {0.8f, 0.8f, 0.8f, 1.0f};
        if (material >= 0) std::memcpy(base, materials[std::size_t(material)].base_color, sizeof(base));
        for (std::size_t v : used) {
            float p[3], q[3];
            transform_point(transform, &view.positions[3 * v], p);
            mesh.positions.insert(mesh.positions.end(), p, p + 3);
            if (view.normals) {
                transform_normal(nmat, &view.normals[3 * v], q);
                mesh.normals.insert(mesh.normals.end(), q, q + 3);
            }
            if (view.colors)
                mesh.colors.insert(mesh.colors.end(), &view.colors[4 * v], &view.colors[4 * v] + 4);
            else
                mesh.colors.insert(mesh.colors.end(), base, base + 4);
            if (view.uvs) mesh.uvs.insert(mesh.uvs.end(), &view.uvs[2 * v], &view.uvs[2 * v] + 2);
            remap[v] = -1;
        }
        part.vertex_count = used.size();
        mesh.parts.push_back(part);
        start = end;
    }
    return mesh;
}

ExportMesh polygon_mesh(const PolygonMeshView& view, const float* corner_colors, const float* corner_uvs,
                        const double transform[16], const std::string& name, int material) {
    ExportMesh mesh;
    mesh.name = name;
    const std::size_t nf = view.face_count;
    // Faces with fewer than 3 corners have no triangles and are left out.
    std::vector<std::size_t> tri_start(nf + 1, 0);
    for (std::size_t f = 0; f < nf; ++f) {
        const std::int64_t start = view.face_corner_start[f], count = view.face_corner_count[f];
        if (start < 0 || count < 0 || std::size_t(start + count) > view.corner_count)
            throw InvalidArgument("mesh '" + name + "': face " + std::to_string(f) + " has corners outside the mesh");
        tri_start[f + 1] = tri_start[f] + (count >= 3 ? std::size_t(count - 2) : 0);
    }
    for (std::size_t c = 0; c < view.corner_count; ++c)
        if (view.corner_vertices[c] < 0 || std::size_t(view.corner_vertices[c]) >= view.vertex_count)
            throw InvalidArgument("mesh '" + name + "': corner " + std::to_string(c) + " indexes a missing vertex");
    const std::size_t nc = view.corner_count;
    mesh.positions.resize(3 * nc);
    mesh.normals.resize(3 * nc);
    if (corner_colors) mesh.colors.assign(corner_colors, corner_colors + 4 * nc);
    if (corner_uvs) mesh.uvs.assign(corner_uvs, corner_uvs + 2 * nc);
    mesh.triangles.resize(3 * tri_start[nf]);
    const bool identity = is_identity(transform);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nf, io::kGrain), [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t f = r.begin(); f != r.end(); ++f) {
            const std::size_t start = std::size_t(view.face_corner_start[f]), count = std::size_t(view.face_corner_count[f]);
            double nsum[3] = {0, 0, 0};
            for (std::size_t k = 0; k < count; ++k) {
                float* p = &mesh.positions[3 * (start + k)];
                const float* src = &view.vertex_positions[3 * std::size_t(view.corner_vertices[start + k])];
                if (identity) std::memcpy(p, src, 3 * sizeof(float));
                else transform_point(transform, src, p);
            }
            for (std::size_t k = 0; k < count; ++k) {  // Newell's normal
                const float* a = &mesh.positions[3 * (start + k)];
                const float* b = &mesh.positions[3 * (start + (k + 1) % count)];
                nsum[0] += (double(a[1]) - b[1]) * (double(a[2]) + b[2]);
                nsum[1] += (double(a[2]) - b[2]) * (double(a[0]) + b[0]);
                nsum[2] += (double(a[0]) - b[0]) * (double(a[1]) + b[1]);
            }
            const double len = std::sqrt(nsum[0] * nsum[0] + nsum[1] * nsum[1] + nsum[2] * nsum[2]);
            for (std::size_t k = 0; k < count; ++k)
                for (int c = 0; c < 3; ++c)
                    mesh.normals[3 * (start + k) + c] = len > 0 ? float(nsum[c] / len) : (c == 2 ? 1.0f : 0.0f);
            std::uint32_t* tri = &mesh.triangles[3 * tri_start[f]];
            for (std::size_t k = 1; k + 1 < count; ++k) {
                *tri++ = std::uint32_t(start);
                *tri++ = std::uint32_t(start + k);
                *tri++ = std::uint32_t(start + k + 1);
            }
        }
    });
    mesh.parts.push_back({0, nc, 0, tri_start[nf], material});
    return mesh;
}

}  // namespace raysplats
