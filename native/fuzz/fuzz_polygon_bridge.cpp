// libFuzzer target: the polygon bridge (raysplats/polygon_bridge.h). Gaussians from the input become polygons
// (gaussians_to_polygons), whose vertices the input may then move, under a transform from the input, as an edit in
// Blender would; or the input is a raw polygon mesh with face attributes (any indices, any floats: a mesh a script
// wrote). Recovery must never crash, and must either throw InvalidArgument or return Gaussians that pass the cloud's
// own checks, with every face accounted for in RecoveryStats (a face it cannot use is reported as dropped, never
// exported as NaN).
#include <cmath>
#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

#include "fuzz_contract.h"
#include "raysplats/polygon_bridge.h"

namespace raysplats {
namespace {

// Consumes the input front to back; past its end everything reads as zero.
struct Input {
    const std::uint8_t* p;
    std::size_t n;
    std::uint8_t byte() {
        if (!n) return 0;
        --n;
        return *p++;
    }
    float f32() {
        std::uint8_t b[4] = {byte(), byte(), byte(), byte()};
        float v;
        std::memcpy(&v, b, 4);
        return v;
    }
    std::int32_t i32() {
        std::uint8_t b[4] = {byte(), byte(), byte(), byte()};
        std::int32_t v;
        std::memcpy(&v, b, 4);
        return v;
    }
};

void check_recovery(const PolygonMeshView& mesh, const SplatFaceAttributesView& attributes, const RecoveryOptions& options) {
    RecoveryStats stats;
    GaussianCloud out;
    try {
        out = recover_gaussians_from_polygons(mesh, attributes, options, &stats);
    } catch (const InvalidArgument&) {
        return;
    } catch (const std::exception& e) {
        fuzz::finding(std::string("recovery threw another exception than InvalidArgument: ") + e.what());
    }
    fuzz::check_cloud(out, "recovered", false);
    if (stats.unedited + stats.recovered + stats.added + stats.dropped != mesh.face_count)
        fuzz::finding("recovery stats do not account for every face");
    if (out.size() != mesh.face_count - stats.dropped) fuzz::finding("recovered cloud size is not faces - dropped");
    if (out.sh_degree != attributes.sh_degree) fuzz::finding("recovered SH degree differs from the attributes'");
}

void round_trip(Input& in, int k, float rho, int degree) {
    GaussianCloud cloud;
    const std::size_t n = in.byte() % 17;
    cloud.resize(n, degree);
    const std::size_t shn = std::size_t(cloud.coeffs_per_channel()) * 3;
    for (std::size_t i = 0; i < n; ++i) {
        for (int j = 0; j < 3; ++j) cloud.positions[3 * i + j] = in.f32();
        for (int j = 0; j < 4; ++j) cloud.rotations[4 * i + j] = in.f32();
        for (int j = 0; j < 3; ++j) cloud.scales[3 * i + j] = in.f32();
        cloud.opacities[i] = in.f32();
        for (std::size_t j = 0; j < shn; ++j) cloud.sh[shn * i + j] = in.f32();
    }
    // What a reader returns (finite values, scales >= 0, opacities in [0, 1]): anything else is refused before the
    // bridge. Rotations are left as the input gives them (zero and unnormalised ones included).
    try {
        cloud.check_values("fuzz");
    } catch (const InvalidArgument&) {
        return;
    }
    for (float& o : cloud.opacities) o = std::fabs(o) > 1.0f ? 1.0f : std::fabs(o);
    PolygonSettings settings;
    settings.vertices_per_polygon = k;
    settings.radius = rho;
    SplatPolygons polygons;
    try {
        polygons = gaussians_to_polygons(cloud, settings);
    } catch (const InvalidArgument&) {
        return;
    }
    RecoveryOptions options;
    options.polygon = settings;
    const PolygonMeshView mesh = mesh_view(polygons);
    const SplatFaceAttributesView attributes = attributes_view(polygons);
    check_recovery(mesh, attributes, options);
    // An edit: some vertices moved, a transform (finite, possibly singular or reflecting), reflected faces by UVs.
    const std::size_t moves = in.byte() % 8;
    for (std::size_t m = 0; m < moves && !polygons.vertex_positions.empty(); ++m) {
        const std::size_t v = std::size_t(in.i32() & 0x7fffffff) % polygons.vertex_positions.size();
        polygons.vertex_positions[v] = in.f32();
    }
    for (int i = 0; i < 12; ++i) {
        const float x = in.f32();
        if (std::isfinite(x)) options.mesh_to_output[i] = x;
    }
    const std::vector<float> reflected = faces_with_reversed_uvs(mesh, polygons.corner_uvs.data());
    SplatFaceAttributesView edited = attributes;
    edited.reflected = reflected.data();
    check_recovery(mesh, edited, options);
}

void raw_mesh(Input& in, int k, float rho, int degree) {
    const std::size_t vertex_count = in.byte() % 33, corner_count = in.byte() % 65, face_count = in.byte() % 9;
    std::vector<float> positions(3 * vertex_count);
    for (float& x : positions) x = in.f32();
    std::vector<std::int32_t> corners(corner_count), starts(face_count), counts(face_count);
    // Small indices mostly (so that faces are used), any int32 when the input says so.
    auto index = [&](int modulo) {
        const std::uint8_t b = in.byte();
        return b == 255 ? in.i32() : std::int32_t(b % modulo) - 1;
    };
    for (auto& c : corners) c = index(int(vertex_count) + 2);
    for (std::size_t f = 0; f < face_count; ++f) starts[f] = index(int(corner_count) + 2), counts[f] = index(k + 3);
    const std::uint8_t present = in.byte();  // which attribute arrays the mesh has
    const std::size_t coeffs = std::size_t(sh_coeff_count(degree));
    auto floats = [&](std::size_t count) {
        std::vector<float> v(count);
        for (float& x : v) x = in.f32();
        return v;
    };
    const std::vector<float> opacity = floats(face_count), thickness = floats(face_count), radius = floats(face_count),
                             sh = floats(face_count * coeffs * 3), centers = floats(3 * face_count),
                             rotations = floats(4 * face_count), scales = floats(3 * face_count),
                             reflected = floats(face_count);
    PolygonMeshView mesh;
    mesh.vertex_positions = positions.data(), mesh.vertex_count = vertex_count;
    mesh.corner_vertices = corners.data(), mesh.corner_count = corner_count;
    mesh.face_corner_start = starts.data(), mesh.face_corner_count = counts.data(), mesh.face_count = face_count;
    SplatFaceAttributesView a;
    a.sh_degree = degree;
    if (present & 1) a.opacity = opacity.data();
    if (present & 2) a.thickness = thickness.data();
    if (present & 4) a.polygon_radius = radius.data();
    if (present & 8) a.sh_local = sh.data();
    if (present & 16) a.rest_centers = centers.data(), a.rest_rotations = rotations.data(), a.rest_scales = scales.data();
    if (present & 32) a.reflected = reflected.data();
    RecoveryOptions options;
    options.polygon.vertices_per_polygon = k;
    options.polygon.radius = rho;
    check_recovery(mesh, a, options);
    // The rest polygon of each face, as the recovery makes it, put in the mesh: an unedited face with the input's rest
    // attributes (where recovery passes the stored Gaussian through unchanged).
    if ((present & 16) && face_count) {
        std::vector<float> rest(3 * std::size_t(k) * face_count);
        std::vector<std::int32_t> rest_corners(std::size_t(k) * face_count), rest_starts(face_count), rest_counts(face_count, k);
        for (std::size_t f = 0; f < face_count; ++f) {
            try {
                gaussian_polygon(&centers[3 * f], &rotations[4 * f], &scales[3 * f], options.polygon, &rest[3 * std::size_t(k) * f]);
            } catch (const InvalidArgument&) {
                return;
            }
            rest_starts[f] = std::int32_t(std::size_t(k) * f);
            for (int c = 0; c < k; ++c) rest_corners[std::size_t(k) * f + std::size_t(c)] = std::int32_t(std::size_t(k) * f + std::size_t(c));
        }
        a.polygon_radius = nullptr;  // rest polygons at the object's rho
        PolygonMeshView m2;
        m2.vertex_positions = rest.data(), m2.vertex_count = std::size_t(k) * face_count;
        m2.corner_vertices = rest_corners.data(), m2.corner_count = std::size_t(k) * face_count;
        m2.face_corner_start = rest_starts.data(), m2.face_corner_count = rest_counts.data(), m2.face_count = face_count;
        check_recovery(m2, a, options);
    }
}

}  // namespace
}  // namespace raysplats

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    using namespace raysplats;
    Input in{data, size};
    const std::uint8_t mode = in.byte();
    const int k = kMinPolygonVertices + in.byte() % (kMaxPolygonVertices - kMinPolygonVertices + 1);
    const int degree = in.byte() % 4;
    const float rho = (mode & 2) ? in.f32() : 0.5f + float(in.byte()) / 32.0f;
    if (mode & 1) raw_mesh(in, k, rho, degree);
    else round_trip(in, k, rho, degree);
    return 0;
}
