// The recovery of design.md §5: polygon meshes -> Gaussians, one per face, by moments (polygon_frame.h) or, where a
// face is exactly the polygon of the Gaussian it was imported from, that Gaussian itself; and the per-face
// attributes recovery reads back from the polygon UVs.
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <mutex>
#include <string>

#include "core/linear_algebra.h"
#include "core/polygon_frame.h"
#include "raysplats/errors.h"
#include "raysplats/polygon_bridge.h"
#include "raysplats/spherical_harmonics.h"

namespace raysplats {
namespace {

using la::Mat3;
using la::Vec3;
using polygon::FaceGaussian;
using polygon::PolygonAngles;

// Applies an affine map x -> A x + t to a Gaussian: m' = A m + t, Σ' = A Σ A^T (design.md §5: exact).
void transform_gaussian(const Mat3& a, const Vec3& t, bool linear_is_identity, FaceGaussian& g) {
    g.center = a * g.center + t;
    if (linear_is_identity) return;
    // Similarity (rotation, uniform scale, possibly a reflection): axes rotate, scales multiply.
    const Mat3 ata = la::transpose(a) * a;
    const double s2 = (ata(0, 0) + ata(1, 1) + ata(2, 2)) / 3;
    double dev = 0;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) dev = std::max(dev, std::abs(ata(i, j) - (i == j ? s2 : 0.0)));
    if (s2 > 0 && dev <= 1e-6 * s2) {
        const double sc = std::sqrt(s2);
        Mat3 r = a * g.r;
        for (double& x : r.m) x /= sc;
        if (la::determinant(r) < 0) r.set_column(2, -r.column(2));  // a Gaussian is symmetric: flip one axis
        g.r = r;
        for (double& s : g.s) s *= sc;
        return;
    }
    Mat3 sigma;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) {
            double acc = 0;
            for (int k = 0; k < 3; ++k) acc += g.r(i, k) * g.s[k] * g.s[k] * g.r(j, k);
            sigma(i, j) = acc;
        }
    sigma = a * sigma * la::transpose(a);
    double values[3];
    la::symmetric_eigen(sigma, values, g.r);
    for (int k = 0; k < 3; ++k) g.s[k] = std::sqrt(std::max(0.0, values[k]));
}

void check_recovery_inputs(const PolygonMeshView& mesh, const SplatFaceAttributesView& attr,
                           const RecoveryOptions& options, const std::uint32_t* faces, std::size_t faces_count) {
    options.polygon.validate();
    if (attr.sh_degree < 0 || attr.sh_degree > 3)
        throw InvalidArgument("SH degree must be 0..3, got " + std::to_string(attr.sh_degree));
    if (mesh.face_count > 0 && (!mesh.face_corner_start || !mesh.face_corner_count))
        throw InvalidArgument("polygon mesh has faces but no face corner arrays");
    for (std::size_t o = 0; faces && o < faces_count; ++o)
        if (faces[o] >= mesh.face_count)
            throw InvalidArgument("face " + std::to_string(faces[o]) + " to recover does not exist (the mesh has " +
                                  std::to_string(mesh.face_count) + ")");
}

// RecoveryOptions::mesh_to_output as x -> A x + t.
struct OutputMap {
    Mat3 a;
    Vec3 t;
    bool identity = true;   // A is the identity (t need not be 0)
    // Reflections reverse the winding; the frame and normals are taken in output space, where the reversed winding
    // is exactly what keeps the recovered rotation proper.
    bool reflects = false;
};

OutputMap output_map(const double mo[16]) {
    for (int i = 0; i < 16; ++i)
        if (!std::isfinite(mo[i])) throw InvalidArgument("the object's transform contains NaN or infinite values");
    OutputMap map;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) map.a(i, j) = mo[4 * i + j];
    map.t = Vec3(mo[3], mo[7], mo[11]);
    for (int i = 0; i < 9; ++i) map.identity = map.identity && map.a.m[i] == Mat3().m[i];
    map.reflects = la::determinant(map.a) < 0.0;
    return map;
}

// What one recovery reads and the cloud it writes (row o of the cloud is face faces[o], or face o without faces).
struct RecoveryJob {
    const PolygonMeshView& mesh;
    const SplatFaceAttributesView& attr;
    const RecoveryOptions& options;
    const std::uint32_t* faces;
    OutputMap map;
    PolygonAngles angles;  // of the K faces were imported with
    GaussianCloud& cloud;
    std::vector<unsigned char>& keep;  // 0 for rows of dropped faces
};

// Per-task buffers of the recovery.
struct FaceScratch {
    Vec3 corners[kMaxPolygonVertices > 256 ? kMaxPolygonVertices : 256];
    std::vector<Vec3> big_corners;  // faces with more than 256 corners (user-made n-gons)
    float rest_polygon[3 * kMaxPolygonVertices];
};

// The corner positions of face f, or null where the face is dropped: fewer than 3 corners, corners outside the
// corner array, a vertex index out of range, or a non-finite coordinate.
Vec3* face_corners(const PolygonMeshView& mesh, std::size_t f, FaceScratch& scratch) {
    const std::int64_t start = mesh.face_corner_start[f];
    const int count = mesh.face_corner_count[f];
    bool valid = count >= 3 && start >= 0 && std::size_t(start) + std::size_t(count) <= mesh.corner_count;
    Vec3* v = scratch.corners;
    if (valid && count > 256) {
        scratch.big_corners.resize(count);
        v = scratch.big_corners.data();
    }
    for (int k = 0; valid && k < count; ++k) {
        const std::int32_t vi = mesh.corner_vertices[start + k];
        if (vi < 0 || std::size_t(vi) >= mesh.vertex_count) {
            valid = false;
            break;
        }
        const float* p = &mesh.vertex_positions[3 * std::size_t(vi)];
        v[k] = Vec3(p[0], p[1], p[2]);
        valid = std::isfinite(v[k].x) && std::isfinite(v[k].y) && std::isfinite(v[k].z);
    }
    return valid ? v : nullptr;
}

// What face f keeps of the Gaussian it was imported from, and whether that may be used.
struct RestFace {
    const float* center = nullptr;    // the rest attributes of the face, null without them
    const float* rotation = nullptr;
    const float* scales = nullptr;
    bool is_added = false;            // a face the user added: default attributes
    float rho = 0.0f;                 // rho_i, which the moments are divided by
    bool usable_rotation = false, usable_scales = false;
};

// Face f's rest attributes; counts rest rotations and scales that are not ones in `counts`.
RestFace rest_of_face(const SplatFaceAttributesView& attr, float object_rho, std::size_t f, RecoveryStats& counts) {
    RestFace rest;
    rest.center = attr.rest_centers ? &attr.rest_centers[3 * f] : nullptr;
    rest.rotation = attr.rest_rotations ? &attr.rest_rotations[4 * f] : nullptr;
    rest.scales = attr.rest_scales ? &attr.rest_scales[3 * f] : nullptr;
    const float* rest_q = rest.rotation;
    const float* rest_s = rest.scales;
    // Without rest attributes every face is taken as a Gaussian; with them, zero rest scales (the value Blender gives
    // new faces) mark a face the user added.
    rest.is_added = rest_s && rest_s[0] == 0 && rest_s[1] == 0 && rest_s[2] == 0;
    // The face's own rho_i (design.md §5); the object's rho where the face has none (0: added by the user).
    rest.rho = object_rho;
    if (attr.polygon_radius && attr.polygon_radius[f] > 0.0f && std::isfinite(attr.polygon_radius[f]))
        rest.rho = attr.polygon_radius[f];
    // A rest rotation that is no rotation must not be passed through: rotation_of() takes it as the identity, so a
    // face shaped like the identity's polygon would match and export the NaN unchanged.
    if (rest_q) {
        const double n2 = double(rest_q[0]) * rest_q[0] + double(rest_q[1]) * rest_q[1] +
                          double(rest_q[2]) * rest_q[2] + double(rest_q[3]) * rest_q[3];
        rest.usable_rotation = std::isfinite(n2) && n2 > 0;
        if (!rest.usable_rotation && !rest.is_added) ++counts.invalid_rest_rotation;
    }
    // Nor a rest scale that is no scale (negative, NaN, Inf): a face built from it matches its polygon exactly (the
    // polygon of -s is that of s turned half a turn), and the scale would be exported as stored.
    if (rest_s && !rest.is_added) {
        rest.usable_scales = true;
        for (int k = 0; k < 3; ++k) rest.usable_scales = rest.usable_scales && rest_s[k] >= 0.0f && std::isfinite(rest_s[k]);
        if (!rest.usable_scales) ++counts.invalid_rest_scale;
    }
    return rest;
}

// The thickness of an edited face's Gaussian: the stored one, else (current imports store none) the one of the face's
// rest scales; 0 for a face the user added.
double face_thickness(const SplatFaceAttributesView& attr, std::size_t f, const RestFace& rest) {
    if (rest.is_added) return 0.0;
    return attr.thickness ? double(attr.thickness[f]) : rest.scales ? double(gaussian_thickness(rest.scales)) : 0.0;
}

// True where face f is unedited: its corners are bit for bit the polygon of its rest Gaussian (rebuilt in
// `rest_polygon`).
bool matches_rest_polygon(const RecoveryJob& job, std::size_t f, const RestFace& rest, float* rest_polygon) {
    const PolygonMeshView& mesh = job.mesh;
    const int count = mesh.face_corner_count[f];
    if (!(rest.usable_rotation && rest.usable_scales && count == job.angles.count && rest.center)) return false;
    polygon::polygon_of_gaussian(rest.center, rest.rotation, rest.scales, job.angles, rest.rho, rest_polygon);
    const std::int64_t start = mesh.face_corner_start[f];
    bool exact_rest = true;
    for (int k = 0; k < count && exact_rest; ++k) {
        const float* p = &mesh.vertex_positions[3 * std::size_t(mesh.corner_vertices[start + k])];
        exact_rest = p[0] == rest_polygon[3 * k] && p[1] == rest_polygon[3 * k + 1] && p[2] == rest_polygon[3 * k + 2];
    }
    return exact_rest;
}

FaceGaussian rest_gaussian(const RestFace& rest) {
    FaceGaussian g;
    g.center = Vec3(rest.center[0], rest.center[1], rest.center[2]);
    g.r = polygon::rotation_of(rest.rotation);
    for (int k = 0; k < 3; ++k) g.s[k] = rest.scales[k];
    return g;
}

// Writes face g to row o in output space (the rest Gaussian bit for bit where the face is unedited and the map has
// no linear part). False where the result does not fit float32 (corners far out, a tiny polygon radius, a transform
// that scales them up: the double result overflows): such a face is dropped, never exported as Inf or NaN.
bool write_face_gaussian(const RecoveryJob& job, std::size_t o, const RestFace& rest, bool exact_rest,
                         FaceGaussian& g) {
    GaussianCloud& cloud = job.cloud;
    const Vec3& t = job.map.t;
    float* out_pos = &cloud.positions[3 * o];
    float* out_rot = &cloud.rotations[4 * o];
    float* out_scale = &cloud.scales[3 * o];
    if (job.map.identity && exact_rest) {
        // Bit-exact pass-through of the imported Gaussian (translation applied if any).
        if (t.x == 0 && t.y == 0 && t.z == 0) {
            std::memcpy(out_pos, rest.center, 3 * sizeof(float));
        } else {
            const Vec3 m = g.center + t;
            out_pos[0] = float(m.x), out_pos[1] = float(m.y), out_pos[2] = float(m.z);
        }
        std::memcpy(out_rot, rest.rotation, 4 * sizeof(float));
        std::memcpy(out_scale, rest.scales, 3 * sizeof(float));
    } else {
        transform_gaussian(job.map.a, t, job.map.identity, g);
        out_pos[0] = float(g.center.x), out_pos[1] = float(g.center.y), out_pos[2] = float(g.center.z);
        double q[4];
        la::matrix_to_quaternion(g.r, q);
        for (int k = 0; k < 4; ++k) out_rot[k] = float(q[k]);
        for (int k = 0; k < 3; ++k) out_scale[k] = float(g.s[k]);
    }
    bool fits = true;
    for (int k = 0; k < 3; ++k) fits = fits && std::isfinite(out_pos[k]) && std::isfinite(out_scale[k]);
    for (int k = 0; k < 4; ++k) fits = fits && std::isfinite(out_rot[k]);
    return fits;
}

// Row o's world SH from face f's local ones: SH_world = D(F_now) SH_local, F_now the frame of the face's corners v
// mapped to output space (v is overwritten with them). Added faces and faces without local SH keep zero SH.
void write_face_sh(const RecoveryJob& job, std::size_t o, std::size_t f, bool is_added, Vec3* v, int count) {
    const SplatFaceAttributesView& attr = job.attr;
    const int degree = attr.sh_degree;
    const int coeffs = sh_coeff_count(degree);
    float* out_sh = &job.cloud.sh[o * coeffs * 3];
    if (!attr.sh_local || is_added) return;
    const float* in_sh = &attr.sh_local[f * coeffs * 3];
    if (degree > 0) {
        Vec3 center;
        for (int k = 0; k < count; ++k) {
            v[k] = job.map.a * v[k] + job.map.t;  // the frame is taken where the colour is seen: output space
            center = center + v[k];
        }
        const Mat3 frame = polygon::polygon_frame(v, count, center * (1.0 / count));
        // polygon_frame() is a proper frame; a reflected face's true frame is improper. A face whose corners a
        // reflection reversed (first corner kept) has frame = true frame · diag(1, -1, 1); a reflection in
        // mesh_to_output, which keeps the corner order, true frame · diag(1, 1, -1).
        const bool flip_y = attr.reflected && attr.reflected[f] != 0.0f;
        if (flip_y || job.map.reflects) {
            float reflected_sh[3 * 16];
            std::memcpy(reflected_sh, in_sh, sizeof(float) * 3 * std::size_t(coeffs));
            reflect_sh(degree, false, flip_y, job.map.reflects, reflected_sh);
            rotate_sh(degree, frame.m, reflected_sh, out_sh);
        } else {
            rotate_sh(degree, frame.m, in_sh, out_sh);
        }
    } else {
        std::memcpy(out_sh, in_sh, 3 * sizeof(float));
    }
    for (int k = 0; k < coeffs * 3; ++k)
        if (!std::isfinite(out_sh[k])) out_sh[k] = 0.0f;
}

// Recovers row o of the job (face faces[o]), counting what became of it in `counts`.
void recover_face(const RecoveryJob& job, std::size_t o, FaceScratch& scratch, RecoveryStats& counts) {
    const std::size_t f = job.faces ? job.faces[o] : o;
    Vec3* v = face_corners(job.mesh, f, scratch);
    if (!v) {
        job.keep[o] = 0;
        ++counts.dropped;
        return;
    }
    const int count = job.mesh.face_corner_count[f];
    const RestFace rest = rest_of_face(job.attr, job.options.polygon.radius, f, counts);
    const bool exact_rest = matches_rest_polygon(job, f, rest, scratch.rest_polygon);
    FaceGaussian g;
    if (exact_rest && job.map.identity)
        g.center = Vec3(rest.center[0], rest.center[1], rest.center[2]);  // (written as stored: only the centre moves)
    else if (exact_rest)
        g = rest_gaussian(rest);
    else if (!polygon::gaussian_of_polygon(v, count, rest.rho, face_thickness(job.attr, f, rest), g))
        ++counts.degenerate;
    if (!write_face_gaussian(job, o, rest, exact_rest, g)) {
        job.keep[o] = 0;
        ++counts.dropped;
        return;
    }
    if (exact_rest) ++counts.unedited;
    else if (rest.is_added) ++counts.added;
    else ++counts.recovered;

    const SplatFaceAttributesView& attr = job.attr;
    float op = rest.is_added ? kNewFaceOpacity : (attr.opacity ? attr.opacity[f] : kNewFaceOpacity);
    job.cloud.opacities[o] = std::isfinite(op) ? std::min(1.0f, std::max(0.0f, op)) : 0.0f;
    write_face_sh(job, o, f, rest.is_added, v, count);
}

void add_counts(const RecoveryStats& part, RecoveryStats& total) {
    total.unedited += part.unedited, total.recovered += part.recovered, total.added += part.added;
    total.degenerate += part.degenerate, total.dropped += part.dropped;
    total.invalid_rest_rotation += part.invalid_rest_rotation;
    total.invalid_rest_scale += part.invalid_rest_scale;
}

// The cloud without the rows of dropped faces (keep[row] == 0), of which there are `dropped`.
GaussianCloud without_dropped(const GaussianCloud& cloud, const std::vector<unsigned char>& keep, std::size_t dropped) {
    const std::size_t coeffs = std::size_t(cloud.coeffs_per_channel());
    GaussianCloud kept;
    kept.resize(cloud.size() - dropped, cloud.sh_degree);
    std::size_t o = 0;
    for (std::size_t f = 0; f < cloud.size(); ++f) {
        if (!keep[f]) continue;
        std::memcpy(&kept.positions[3 * o], &cloud.positions[3 * f], 3 * sizeof(float));
        std::memcpy(&kept.rotations[4 * o], &cloud.rotations[4 * f], 4 * sizeof(float));
        std::memcpy(&kept.scales[3 * o], &cloud.scales[3 * f], 3 * sizeof(float));
        kept.opacities[o] = cloud.opacities[f];
        std::memcpy(&kept.sh[o * coeffs * 3], &cloud.sh[f * coeffs * 3], coeffs * 3 * sizeof(float));
        ++o;
    }
    return kept;
}

}  // namespace

GaussianCloud recover_gaussians_from_polygons(const PolygonMeshView& mesh, const SplatFaceAttributesView& attr,
                                              const RecoveryOptions& options, RecoveryStats* stats_out,
                                              const std::uint32_t* faces, std::size_t faces_count) {
    check_recovery_inputs(mesh, attr, options, faces, faces_count);
    // Output row o is face faces[o] (all faces in order without a subset).
    const std::size_t nf = faces ? faces_count : mesh.face_count;
    const OutputMap map = output_map(options.mesh_to_output);
    const PolygonAngles angles(options.polygon.vertices_per_polygon);
    GaussianCloud cloud;
    cloud.resize(nf, attr.sh_degree);
    std::vector<unsigned char> keep(nf, 1);
    const RecoveryJob job{mesh, attr, options, faces, map, angles, cloud, keep};

    RecoveryStats counts;
    std::mutex counts_mutex;
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nf, polygon::kFacesPerTask),
                      [&](const tbb::blocked_range<std::size_t>& range) {
        RecoveryStats part;
        FaceScratch scratch;
        for (std::size_t o = range.begin(); o != range.end(); ++o) recover_face(job, o, scratch, part);
        const std::lock_guard<std::mutex> lock(counts_mutex);
        add_counts(part, counts);
    });

    if (counts.dropped > 0) cloud = without_dropped(cloud, keep, counts.dropped);
    if (stats_out) *stats_out = counts;
    return cloud;
}

namespace {

// Runs body(f, start, count) in parallel for every face f of at least min_corners corners, all inside the corner
// array.
template <typename Body>
void for_each_face_in_range(const PolygonMeshView& mesh, std::int64_t min_corners, Body&& body) {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, mesh.face_count, polygon::kFacesPerTask),
                      [&](const auto& range) {
        for (std::size_t f = range.begin(); f != range.end(); ++f) {
            const std::int64_t start = mesh.face_corner_start[f], count = mesh.face_corner_count[f];
            if (count < min_corners || start < 0 || std::size_t(start + count) > mesh.corner_count) continue;
            body(f, start, count);
        }
    });
}

}  // namespace

std::vector<float> faces_with_reversed_uvs(const PolygonMeshView& mesh, const float* corner_uvs) {
    std::vector<float> reversed(mesh.face_count, 0.0f);
    for_each_face_in_range(mesh, 3, [&](std::size_t f, std::int64_t start, std::int64_t count) {
        double twice_area = 0.0;  // shoelace
        for (std::int64_t k = 0; k < count; ++k) {
            const float* p = &corner_uvs[2 * std::size_t(start + k)];
            const float* q = &corner_uvs[2 * std::size_t(start + (k + 1) % count)];
            twice_area += double(p[0]) * q[1] - double(q[0]) * p[1];
        }
        reversed[f] = twice_area < 0.0 ? 1.0f : 0.0f;
    });
    return reversed;
}

std::vector<float> polygon_radius_from_uvs(const PolygonMeshView& mesh, const float* corner_uvs) {
    std::vector<float> radius(mesh.face_count, 0.0f);
    for_each_face_in_range(mesh, 1, [&](std::size_t f, std::int64_t start, std::int64_t count) {
        for (std::int64_t k = 0; k < count; ++k) {
            const float* uv = &corner_uvs[2 * std::size_t(start + k)];
            if (uv[1] == 0.0f && uv[0] > 0.0f && std::isfinite(uv[0])) {
                radius[f] = uv[0];
                return;
            }
        }
    });
    return radius;
}

}  // namespace raysplats
