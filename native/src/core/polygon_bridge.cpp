#include "raysplats/polygon_bridge.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <atomic>
#include <cmath>
#include <cstring>
#include <string>

#include "core/color_math.h"
#include "core/linear_algebra.h"
#include "raysplats/errors.h"
#include "raysplats/spherical_harmonics.h"

namespace raysplats {
namespace {

using la::Mat3;
using la::Vec3;

constexpr double kTwoPi = 6.283185307179586;
constexpr std::size_t kGrain = 4096;


}  // namespace

float gaussian_thickness(const float scales[3]) {
    float sorted[3] = {scales[0], scales[1], scales[2]};
    std::sort(sorted, sorted + 3, [](float a, float b) { return a > b; });
    const double plane = std::sqrt(double(sorted[0]) * sorted[1]);
    return plane > 0 ? float(sorted[2] / plane) : 0.0f;
}

namespace {

Mat3 rotation_of(const float q[4]) {
    double w = q[0], x = q[1], y = q[2], z = q[3];
    const double n = std::sqrt(w * w + x * x + y * y + z * z);
    if (!(n > 0)) return Mat3();
    return la::quaternion_to_matrix(w / n, x / n, y / n, z / n);
}

// The Gaussian of one face while it is being recovered: centre, axes (columns of r), scales along them.
struct FaceGaussian {
    Vec3 center;
    Mat3 r;
    double s[3] = {0, 0, 0};
};

// Local SH frame F = [e1, e2, n] of a polygon: e1 from the centre towards vertex 0 (made perpendicular to n),
// n the winding (Newell) normal. Always a proper rotation.
Mat3 polygon_frame(const Vec3* v, int count, const Vec3& center) {
    Vec3 newell;
    for (int k = 0; k < count; ++k) newell = newell + la::cross(v[k] - center, v[(k + 1) % count] - center);
    Vec3 n = la::normalized(newell);
    if (la::norm(n) == 0) n = Vec3(0, 0, 1);
    Vec3 e1 = v[0] - center;
    e1 = la::normalized(e1 - n * la::dot(e1, n));
    if (la::norm(e1) == 0) e1 = la::any_perpendicular(n);
    Mat3 f;
    f.set_column(0, e1);
    f.set_column(1, la::cross(n, e1));
    f.set_column(2, n);
    return f;
}

// Moments recovery of docs/design.md §5. The normal is the eigenvector of C's smallest eigenvalue (from the rows of
// C - λ3 I), oriented by the winding; the two in-plane axes come from the exact 2x2 problem in the plane,
// which stays accurate when λ1 ≈ λ2 (round Gaussians). Returns false for degenerate faces (scales clamped).
bool recover_by_moments(const Vec3* v, int count, double rho, double thickness, FaceGaussian& g) {
    Vec3 m;
    for (int k = 0; k < count; ++k) m = m + v[k];
    m = m * (1.0 / count);
    double c00 = 0, c01 = 0, c02 = 0, c11 = 0, c12 = 0, c22 = 0;
    Vec3 newell;
    for (int k = 0; k < count; ++k) {
        const Vec3 d = v[k] - m;
        c00 += d.x * d.x, c01 += d.x * d.y, c02 += d.x * d.z, c11 += d.y * d.y, c12 += d.y * d.z, c22 += d.z * d.z;
        newell = newell + la::cross(d, v[(k + 1) % count] - m);
    }
    const double inv = 1.0 / count;
    c00 *= inv, c01 *= inv, c02 *= inv, c11 *= inv, c12 *= inv, c22 *= inv;
    g.center = m;

    // Eigenvalues of the symmetric C (trigonometric method, Smith 1961).
    const double q = (c00 + c11 + c22) / 3;
    const double p1 = c01 * c01 + c02 * c02 + c12 * c12;
    const double p2 = (c00 - q) * (c00 - q) + (c11 - q) * (c11 - q) + (c22 - q) * (c22 - q) + 2 * p1;
    const double p = std::sqrt(p2 / 6);
    double lambda_min = q;
    if (p > 0) {
        const double b00 = (c00 - q) / p, b11 = (c11 - q) / p, b22 = (c22 - q) / p, b01 = c01 / p, b02 = c02 / p,
                     b12 = c12 / p;
        const double det_b = b00 * (b11 * b22 - b12 * b12) - b01 * (b01 * b22 - b12 * b02) + b02 * (b01 * b12 - b11 * b02);
        const double r = std::min(1.0, std::max(-1.0, det_b / 2));
        const double phi = std::acos(r) / 3;
        lambda_min = q + 2 * p * std::cos(phi + kTwoPi / 3);
    }
    // Normal: cross products of rows of C - λ3 I span the null direction; take the best conditioned one.
    const Vec3 r0(c00 - lambda_min, c01, c02), r1(c01, c11 - lambda_min, c12), r2(c02, c12, c22 - lambda_min);
    Vec3 best = la::cross(r0, r1);
    for (const Vec3& cand : {la::cross(r0, r2), la::cross(r1, r2)})
        if (la::dot(cand, cand) > la::dot(best, best)) best = cand;
    const double scale2 = (c00 + c11 + c22) * (c00 + c11 + c22);
    Vec3 n;
    if (la::dot(best, best) > 1e-20 * scale2 * scale2 && std::isfinite(la::dot(best, best))) {
        n = la::normalized(best);
    } else if (la::norm(newell) > 0) {
        n = la::normalized(newell);  // eigenvector ill-defined (needle-like polygon): use the winding normal
    } else {
        // Collinear or coincident: any plane containing the principal direction.
        Vec3 axis = la::dot(r0, r0) >= la::dot(r1, r1) ? r0 : r1;
        if (la::dot(r2, r2) > la::dot(axis, axis)) axis = r2;
        n = la::norm(axis) > 0 ? la::any_perpendicular(la::normalized(axis)) : Vec3(0, 0, 1);
    }
    if (la::dot(n, newell) < 0) n = -n;

    // In-plane 2x2 problem in the basis (u, w).
    const Vec3 u = la::any_perpendicular(n), w = la::cross(n, u);
    auto quad = [&](const Vec3& a, const Vec3& b) {
        return a.x * (c00 * b.x + c01 * b.y + c02 * b.z) + a.y * (c01 * b.x + c11 * b.y + c12 * b.z) +
               a.z * (c02 * b.x + c12 * b.y + c22 * b.z);
    };
    const double a = quad(u, u), b = quad(u, w), c = quad(w, w);
    const double mean = 0.5 * (a + c), radius = std::sqrt(0.25 * (a - c) * (a - c) + b * b);
    const double l1 = mean + radius, l2 = std::max(0.0, mean - radius);
    // Eigenvector of [[a, b], [b, c]] for l1: (b, l1 - a) or (l1 - c, b), whichever is better conditioned.
    double eu = b, ew = l1 - a;
    if (std::abs(l1 - c) > std::abs(ew)) eu = l1 - c, ew = b;
    const double en = std::sqrt(eu * eu + ew * ew);
    const Vec3 a1 = en > 0 ? u * (eu / en) + w * (ew / en) : u;
    g.r.set_column(0, a1);
    g.r.set_column(1, la::cross(n, a1));
    g.r.set_column(2, n);

    // s = sqrt(2 λ) / rho (the face's rho_i), because (1/K) Σ cos²θ_k = 1/2 for every regular K-gon with K >= 3.
    double s1 = std::sqrt(2 * l1) / rho, s2 = std::sqrt(2 * l2) / rho;
    bool ok = std::isfinite(s1) && s1 > kMinAbsoluteScale && s2 >= kMinRelativeScale * s1;
    if (!std::isfinite(s1)) s1 = kMinAbsoluteScale;
    s1 = std::max(s1, kMinAbsoluteScale);
    s2 = std::max({s2, kMinRelativeScale * s1, kMinAbsoluteScale});
    g.s[0] = s1, g.s[1] = s2;
    g.s[2] = std::max(kMinAbsoluteScale, (std::isfinite(thickness) ? std::max(0.0, thickness) : 0.0) * std::sqrt(s1 * s2));
    return ok;
}

// Applies an affine map x -> A x + t to a Gaussian: m' = A m + t, Σ' = A Σ A^T (docs/design.md §5: exact).
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

// a / (1/255): something of the Gaussian is visible when it exceeds 1 (then its logarithm is positive).
double visibility_ratio(float opacity) { return double(opacity) / kVisibleOpacity; }

}  // namespace

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

namespace {

// cos θ_k and sin θ_k for every vertex of the polygon, computed once per call.
struct PolygonAngles {
    int count = 0;
    double cos[kMaxPolygonVertices];
    double sin[kMaxPolygonVertices];
    explicit PolygonAngles(int vertices_per_polygon) : count(vertices_per_polygon) {
        for (int k = 0; k < count; ++k) {
            const double theta = kTwoPi * k / count;
            cos[k] = std::cos(theta);
            sin[k] = std::sin(theta);
        }
    }
};

// The polygon of one Gaussian at radius rho (a float, as stored per face). Import, recovery's unedited-face check
// and the mesh exporters all come here, so that the same Gaussian and rho give the same float vertices bit for bit
// (rho·cos θ_k in double, as the angle tables with rho folded in did before per-face radii: old files still match).
void polygon_of_gaussian(const float center[3], const float rotation_wxyz[4], const float scales[3],
                         const PolygonAngles& angles, float rho, float* out) {
    const Mat3 r = rotation_of(rotation_wxyz);
    // The two largest axes span the polygon; ties keep the lower index so the choice is deterministic.
    int first = 0;
    if (scales[1] > scales[first]) first = 1;
    if (scales[2] > scales[first]) first = 2;
    int second = first == 0 ? 1 : 0;
    for (int k = 0; k < 3; ++k)
        if (k != first && scales[k] > scales[second]) second = k;
    const Vec3 a1 = r.column(first) * double(scales[first]);
    const Vec3 a2 = r.column(second) * double(scales[second]);
    for (int k = 0; k < angles.count; ++k) {
        const double c = double(rho) * angles.cos[k], s = double(rho) * angles.sin[k];
        out[3 * k + 0] = float(center[0] + c * a1.x + s * a2.x);
        out[3 * k + 1] = float(center[1] + c * a1.y + s * a2.y);
        out[3 * k + 2] = float(center[2] + c * a1.z + s * a2.z);
    }
}
}  // namespace

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
    const std::size_t corners = nf * kc;
    if (corners > std::size_t(INT32_MAX))
        throw InvalidArgument(std::to_string(nf) + " Gaussians with K = " + std::to_string(kc) +
                              " need more polygon corners than a Blender mesh can index");
    const int coeffs = cloud.coeffs_per_channel();
    const std::size_t sh_per_gaussian = std::size_t(coeffs) * 3;
    SplatPolygons out;
    out.invisible_skipped = n - nf;
    out.sh_degree = cloud.sh_degree;
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

    const PolygonAngles angles(kc);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nf, kGrain), [&](const tbb::blocked_range<std::size_t>& range) {
        Vec3 verts[kMaxPolygonVertices];
        for (std::size_t f = range.begin(); f != range.end(); ++f) {
            const std::size_t i = gaussian_of_face[f];
            const float rho = visible_polygon_radius(cloud.opacities[i], settings.radius);
            const std::int32_t base = std::int32_t(f * kc);
            float* pos = &out.vertex_positions[3 * std::size_t(base)];
            polygon_of_gaussian(&cloud.positions[3 * i], &cloud.rotations[4 * i], &cloud.scales[3 * i], angles, rho, pos);
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
            out.thickness[f] = gaussian_thickness(&cloud.scales[3 * i]);
            out.polygon_radius[f] = rho;
            out.opacity[f] = cloud.opacities[i];
            std::memcpy(&out.rest_centers[3 * f], &cloud.positions[3 * i], 3 * sizeof(float));
            std::memcpy(&out.rest_rotations[4 * f], &cloud.rotations[4 * i], 4 * sizeof(float));
            std::memcpy(&out.rest_scales[3 * f], &cloud.scales[3 * i], 3 * sizeof(float));

            const float* sh = &cloud.sh[i * sh_per_gaussian];
            float* local = &out.sh_local[f * sh_per_gaussian];
            if (cloud.sh_degree > 0) {
                Vec3 center;
                for (int k = 0; k < kc; ++k) {
                    verts[k] = Vec3(pos[3 * k], pos[3 * k + 1], pos[3 * k + 2]);
                    center = center + verts[k];
                }
                const Mat3 ft = la::transpose(polygon_frame(verts, kc, center * (1.0 / kc)));
                rotate_sh(cloud.sh_degree, ft.m, sh, local);
            } else {
                std::memcpy(local, sh, sizeof(float) * 3);
            }
            const std::uint8_t rgba[4] = {sh_dc_to_srgb_byte(sh[0]), sh_dc_to_srgb_byte(sh[1]), sh_dc_to_srgb_byte(sh[2]),
                                          unit_to_byte(cloud.opacities[i])};
            for (int k = 0; k < kc; ++k) std::memcpy(&out.corner_colors[4 * (std::size_t(base) + k)], rgba, sizeof(rgba));
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

GaussianCloud recover_gaussians_from_polygons(const PolygonMeshView& mesh, const SplatFaceAttributesView& attr,
                                              const RecoveryOptions& options, RecoveryStats* stats_out,
                                              const std::uint32_t* faces, std::size_t faces_count) {
    options.polygon.validate();
    if (attr.sh_degree < 0 || attr.sh_degree > 3)
        throw InvalidArgument("SH degree must be 0..3, got " + std::to_string(attr.sh_degree));
    if (mesh.face_count > 0 && (!mesh.face_corner_start || !mesh.face_corner_count))
        throw InvalidArgument("polygon mesh has faces but no face corner arrays");
    for (std::size_t o = 0; faces && o < faces_count; ++o)
        if (faces[o] >= mesh.face_count)
            throw InvalidArgument("face " + std::to_string(faces[o]) + " to recover does not exist (the mesh has " +
                                  std::to_string(mesh.face_count) + ")");
    // Output row o is face faces[o] (all faces in order without a subset).
    const std::size_t nf = faces ? faces_count : mesh.face_count;
    const double* mo = options.mesh_to_output;
    for (int i = 0; i < 16; ++i)
        if (!std::isfinite(mo[i])) throw InvalidArgument("the object's transform contains NaN or infinite values");
    Mat3 a;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) a(i, j) = mo[4 * i + j];
    const Vec3 t(mo[3], mo[7], mo[11]);
    bool identity = true;
    for (int i = 0; i < 9; ++i) identity = identity && a.m[i] == Mat3().m[i];
    const bool reflects = la::determinant(a) < 0.0;
    // Reflections reverse the winding; the frame and normals below are taken in output space, where the
    // reversed winding is exactly what keeps the recovered rotation proper.

    const int degree = attr.sh_degree;
    const int coeffs = sh_coeff_count(degree);
    const int k_rest = options.polygon.vertices_per_polygon;

    const PolygonAngles angles(k_rest);
    GaussianCloud cloud;
    cloud.resize(nf, degree);
    std::vector<unsigned char> keep(nf, 1);
    std::atomic<std::size_t> unedited{0}, recovered{0}, added{0}, degenerate{0}, dropped{0}, invalid_rest{0},
        invalid_rest_scale{0};

    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nf, kGrain), [&](const tbb::blocked_range<std::size_t>& range) {
        std::size_t n_unedited = 0, n_recovered = 0, n_added = 0, n_degenerate = 0, n_dropped = 0, n_invalid_rest = 0,
                    n_invalid_rest_scale = 0;
        Vec3 local[kMaxPolygonVertices > 256 ? kMaxPolygonVertices : 256];
        float rest_polygon[3 * kMaxPolygonVertices];
        std::vector<Vec3> big;  // faces with more than 256 corners (user-made n-gons)
        for (std::size_t o = range.begin(); o != range.end(); ++o) {
            const std::size_t f = faces ? faces[o] : o;
            const std::int64_t start = mesh.face_corner_start[f];
            const int count = mesh.face_corner_count[f];
            bool valid = count >= 3 && start >= 0 && std::size_t(start) + std::size_t(count) <= mesh.corner_count;
            Vec3* v = local;
            if (valid && count > 256) {
                big.resize(count);
                v = big.data();
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
            if (!valid) {
                keep[o] = 0;
                ++n_dropped;
                continue;
            }

            const float* rest_q = attr.rest_rotations ? &attr.rest_rotations[4 * f] : nullptr;
            const float* rest_s = attr.rest_scales ? &attr.rest_scales[3 * f] : nullptr;
            // Without rest attributes every face is taken as a Gaussian; with them, zero rest scales (the value
            // Blender gives new faces) mark a face the user added.
            const bool is_added = rest_s && rest_s[0] == 0 && rest_s[1] == 0 && rest_s[2] == 0;
            // The stored thickness, else (current imports store none) the one of the face's rest scales.
            const double thickness = is_added ? 0.0
                : attr.thickness ? double(attr.thickness[f]) : rest_s ? double(gaussian_thickness(rest_s)) : 0.0;
            // The face's own rho_i (docs/design.md §5); the object's rho where the face has none (0: added by
            // the user).
            float rho = options.polygon.radius;
            if (attr.polygon_radius && attr.polygon_radius[f] > 0.0f && std::isfinite(attr.polygon_radius[f]))
                rho = attr.polygon_radius[f];

            FaceGaussian g;
            bool exact_rest = false;
            // A rest rotation that is no rotation must not be passed through: rotation_of() takes it as the
            // identity, so a face shaped like the identity's polygon would match and export the NaN unchanged.
            bool usable_rest_q = false;
            if (rest_q) {
                const double n2 = double(rest_q[0]) * rest_q[0] + double(rest_q[1]) * rest_q[1] +
                                  double(rest_q[2]) * rest_q[2] + double(rest_q[3]) * rest_q[3];
                usable_rest_q = std::isfinite(n2) && n2 > 0;
                if (!usable_rest_q && !is_added) ++n_invalid_rest;
            }
            // Nor a rest scale that is no scale (negative, NaN, Inf): a face built from it matches its polygon exactly
            // (the polygon of -s is that of s turned half a turn), and the scale would be exported as stored.
            bool usable_rest_s = false;
            if (rest_s && !is_added) {
                usable_rest_s = true;
                for (int k = 0; k < 3; ++k) usable_rest_s = usable_rest_s && rest_s[k] >= 0.0f && std::isfinite(rest_s[k]);
                if (!usable_rest_s) ++n_invalid_rest_scale;
            }
            if (usable_rest_q && usable_rest_s && count == k_rest && attr.rest_centers) {
                polygon_of_gaussian(&attr.rest_centers[3 * f], rest_q, &attr.rest_scales[3 * f], angles, rho,
                                    rest_polygon);
                exact_rest = true;
                for (int k = 0; k < count && exact_rest; ++k) {
                    const float* p = &mesh.vertex_positions[3 * std::size_t(mesh.corner_vertices[start + k])];
                    exact_rest = p[0] == rest_polygon[3 * k] && p[1] == rest_polygon[3 * k + 1] && p[2] == rest_polygon[3 * k + 2];
                }
            }
            if (exact_rest) {
                const float* c = &attr.rest_centers[3 * f];
                g.center = Vec3(c[0], c[1], c[2]);
                g.r = rotation_of(rest_q);
                for (int k = 0; k < 3; ++k) g.s[k] = attr.rest_scales[3 * f + k];
                ++n_unedited;
            } else {
                if (!recover_by_moments(v, count, rho, thickness, g)) ++n_degenerate;
                if (is_added) ++n_added; else ++n_recovered;
            }

            // Output: centre, rotation, scales.
            float* out_pos = &cloud.positions[3 * o];
            float* out_rot = &cloud.rotations[4 * o];
            float* out_scale = &cloud.scales[3 * o];
            if (identity && exact_rest) {
                // Bit-exact pass-through of the imported Gaussian (translation applied if any).
                if (t.x == 0 && t.y == 0 && t.z == 0) {
                    std::memcpy(out_pos, &attr.rest_centers[3 * f], 3 * sizeof(float));
                } else {
                    const Vec3 m = g.center + t;
                    out_pos[0] = float(m.x), out_pos[1] = float(m.y), out_pos[2] = float(m.z);
                }
                std::memcpy(out_rot, rest_q, 4 * sizeof(float));
                std::memcpy(out_scale, &attr.rest_scales[3 * f], 3 * sizeof(float));
            } else {
                transform_gaussian(a, t, identity, g);
                out_pos[0] = float(g.center.x), out_pos[1] = float(g.center.y), out_pos[2] = float(g.center.z);
                double q[4];
                la::matrix_to_quaternion(g.r, q);
                for (int k = 0; k < 4; ++k) out_rot[k] = float(q[k]);
                for (int k = 0; k < 3; ++k) out_scale[k] = float(g.s[k]);
            }
            // A Gaussian that does not fit float32 (corners far out, a tiny polygon_radius, a transform that scales
            // them up: the double result overflows) is dropped and counted like a face with non-finite corners,
            // never exported as Inf or NaN.
            bool fits = true;
            for (int k = 0; k < 3; ++k) fits = fits && std::isfinite(out_pos[k]) && std::isfinite(out_scale[k]);
            for (int k = 0; k < 4; ++k) fits = fits && std::isfinite(out_rot[k]);
            if (!fits) {
                keep[o] = 0;
                ++n_dropped;
                if (exact_rest) --n_unedited;  // counted above as what it would have been
                else if (is_added) --n_added;
                else --n_recovered;
                continue;
            }

            float op = is_added ? kNewFaceOpacity : (attr.opacity ? attr.opacity[f] : kNewFaceOpacity);
            cloud.opacities[o] = std::isfinite(op) ? std::min(1.0f, std::max(0.0f, op)) : 0.0f;

            float* out_sh = &cloud.sh[o * coeffs * 3];
            if (attr.sh_local && !is_added) {
                const float* in_sh = &attr.sh_local[f * coeffs * 3];
                if (degree > 0) {
                    Vec3 center;
                    for (int k = 0; k < count; ++k) {
                        v[k] = a * v[k] + t;  // the frame is taken where the colour is seen: output space
                        center = center + v[k];
                    }
                    const Mat3 frame = polygon_frame(v, count, center * (1.0 / count));
                    // polygon_frame() is a proper frame; a reflected face's true frame is improper. A face whose
                    // corners a reflection reversed (first corner kept) has frame = true frame · diag(1, -1, 1); a
                    // reflection in mesh_to_output, which keeps the corner order, true frame · diag(1, 1, -1).
                    const bool flip_y = attr.reflected && attr.reflected[f] != 0.0f;
                    if (flip_y || reflects) {
                        float reflected_sh[3 * 16];
                        std::memcpy(reflected_sh, in_sh, sizeof(float) * 3 * std::size_t(coeffs));
                        reflect_sh(degree, false, flip_y, reflects, reflected_sh);
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
        }
        unedited += n_unedited, recovered += n_recovered, added += n_added, degenerate += n_degenerate,
            dropped += n_dropped, invalid_rest += n_invalid_rest, invalid_rest_scale += n_invalid_rest_scale;
    });

    if (dropped > 0) {  // compact: dropped faces are left out of the output
        GaussianCloud kept;
        kept.resize(nf - dropped, degree);
        std::size_t o = 0;
        for (std::size_t f = 0; f < nf; ++f) {
            if (!keep[f]) continue;
            std::memcpy(&kept.positions[3 * o], &cloud.positions[3 * f], 3 * sizeof(float));
            std::memcpy(&kept.rotations[4 * o], &cloud.rotations[4 * f], 4 * sizeof(float));
            std::memcpy(&kept.scales[3 * o], &cloud.scales[3 * f], 3 * sizeof(float));
            kept.opacities[o] = cloud.opacities[f];
            std::memcpy(&kept.sh[o * coeffs * 3], &cloud.sh[f * coeffs * 3], coeffs * 3 * sizeof(float));
            ++o;
        }
        cloud = std::move(kept);
    }
    if (stats_out) {
        stats_out->unedited = unedited, stats_out->recovered = recovered, stats_out->added = added;
        stats_out->degenerate = degenerate, stats_out->dropped = dropped;
        stats_out->invalid_rest_rotation = invalid_rest;
        stats_out->invalid_rest_scale = invalid_rest_scale;
    }
    return cloud;
}

namespace {

std::vector<std::uint32_t> indices_of_set_flags(const std::vector<unsigned char>& flags) {
    std::vector<std::uint32_t> indices;
    for (std::size_t i = 0; i < flags.size(); ++i)
        if (flags[i]) indices.push_back(std::uint32_t(i));
    return indices;
}

}  // namespace

std::vector<std::uint32_t> faces_with_moved_vertices(const PolygonMeshView& mesh, const float* previous_positions) {
    std::vector<unsigned char> moved(mesh.vertex_count);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, mesh.vertex_count, 1 << 16), [&](const auto& range) {
        for (std::size_t v = range.begin(); v != range.end(); ++v)
            moved[v] = std::memcmp(&mesh.vertex_positions[3 * v], &previous_positions[3 * v], 3 * sizeof(float)) != 0;
    });
    std::vector<unsigned char> face_moved(mesh.face_count);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, mesh.face_count, kGrain), [&](const auto& range) {
        for (std::size_t f = range.begin(); f != range.end(); ++f) {
            const std::int64_t start = mesh.face_corner_start[f];
            const std::int64_t end = start + mesh.face_corner_count[f];
            if (start < 0 || end > std::int64_t(mesh.corner_count))
                throw InvalidArgument("face " + std::to_string(f) + " has corners outside the corner array");
            bool any = false;
            for (std::int64_t k = start; k < end && !any; ++k) {
                const std::int32_t vi = mesh.corner_vertices[k];
                if (vi < 0 || std::size_t(vi) >= mesh.vertex_count)
                    throw InvalidArgument("face " + std::to_string(f) + " uses vertex " + std::to_string(vi) + " of " +
                                          std::to_string(mesh.vertex_count));
                any = moved[std::size_t(vi)] != 0;
            }
            face_moved[f] = any;
        }
    });
    return indices_of_set_flags(face_moved);
}

std::vector<std::uint32_t> rows_that_differ(const float* previous, const float* current, std::size_t rows,
                                            std::size_t width) {
    std::vector<unsigned char> differs(rows);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, rows, 1 << 15), [&](const auto& range) {
        for (std::size_t r = range.begin(); r != range.end(); ++r)
            differs[r] = std::memcmp(&previous[r * width], &current[r * width], width * sizeof(float)) != 0;
    });
    return indices_of_set_flags(differs);
}

std::vector<float> faces_with_reversed_uvs(const PolygonMeshView& mesh, const float* corner_uvs) {
    std::vector<float> reversed(mesh.face_count, 0.0f);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, mesh.face_count, kGrain), [&](const auto& range) {
        for (std::size_t f = range.begin(); f != range.end(); ++f) {
            const std::int64_t start = mesh.face_corner_start[f], count = mesh.face_corner_count[f];
            if (count < 3 || start < 0 || std::size_t(start + count) > mesh.corner_count) continue;
            double twice_area = 0.0;  // shoelace
            for (std::int64_t k = 0; k < count; ++k) {
                const float* p = &corner_uvs[2 * std::size_t(start + k)];
                const float* q = &corner_uvs[2 * std::size_t(start + (k + 1) % count)];
                twice_area += double(p[0]) * q[1] - double(q[0]) * p[1];
            }
            reversed[f] = twice_area < 0.0 ? 1.0f : 0.0f;
        }
    });
    return reversed;
}

std::vector<float> polygon_radius_from_uvs(const PolygonMeshView& mesh, const float* corner_uvs) {
    std::vector<float> radius(mesh.face_count, 0.0f);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, mesh.face_count, kGrain), [&](const auto& range) {
        for (std::size_t f = range.begin(); f != range.end(); ++f) {
            const std::int64_t start = mesh.face_corner_start[f], count = mesh.face_corner_count[f];
            if (count < 1 || start < 0 || std::size_t(start + count) > mesh.corner_count) continue;
            for (std::int64_t k = 0; k < count; ++k) {
                const float* uv = &corner_uvs[2 * std::size_t(start + k)];
                if (uv[1] == 0.0f && uv[0] > 0.0f && std::isfinite(uv[0])) {
                    radius[f] = uv[0];
                    break;
                }
            }
        }
    });
    return radius;
}

}  // namespace raysplats
