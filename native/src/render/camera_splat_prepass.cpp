#include "camera_splat_prepass.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <mutex>
#include <string>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "core/radix_sort.h"
#include "gaussian_callbacks.h"
#include "gaussian_primitives.h"
#include "pixel_filter.h"
#include "raysplats/errors.h"
#include "render_math.h"
#include "simd.h"

namespace raysplats {

namespace {

constexpr float kDilation = 0.3f;           // px^2 added to the 2D covariance's diagonal (3DGS computeCov2D)
constexpr float kJacobianClamp = 1.3f;      // x/z and y/z clamped to 1.3 x the frustum's half extent (3DGS)
constexpr float kFootprintSigmas = 3.0f;    // square half side in standard deviations (3DGS getRect's radius)
constexpr double kTilePadMargin = 1e-3;     // px added to the samples' pad when binning (a margin for rounding)
constexpr float kLeastPowerMargin = 1e-3f;  // ProjectedSplat::least_power's margin below ln(1/255 / opacity)

// Pixels of the pixel filter's reach around a pixel (PixelFilterSampler::reach), rounded up, plus one: camera samples
// fall within it. A multiple of 4, so that the render loop's 4 x 4 packets of pixels (from the region's corner) each
// lie in one tile.
int filter_margin(const RenderSettings& st) {
    const int reach = (st.jitter ? int(std::ceil(PixelFilterSampler::reach(st.pixel_filter, st.filter_width))) : 0) + 1;
    return (reach + 3) / 4 * 4;
}

// Not a Gaussian's global index (the prepass indexes them in 32 bits), not a key (keys).
constexpr std::uint32_t kNotVisible = 0xffffffffu;
constexpr std::uint64_t kNotVisibleKey = ~std::uint64_t(0);

// floor and ceil of a float or double in int range, without the libm call they are on x86-64's baseline (SSE2 has no
// rounding instruction).
template <typename T>
int floor_int(T x) {
    const int i = int(x);
    return i - (T(i) > x);
}
template <typename T>
int ceil_int(T x) {
    const int i = int(x);
    return i + (T(i) < x);
}

bool is_cancelled(const std::atomic<bool>* cancel) { return cancel && cancel->load(std::memory_order_relaxed); }

// Calls visit(k, set, j) for primitive j of every Gaussian set k of the scene, a set's primitives in parallel; a
// cancel stops it within a block of them.
template <typename Visit>
void for_each_gaussian(const Scene::Impl& scene, const std::atomic<bool>* cancel, const Visit& visit) {
    for (std::size_t k = 0; k < scene.gaussians.size(); ++k) {
        const GaussianSet& set = *scene.gaussians[k];
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, set.prims.size(), 4096),
                          [&](const tbb::blocked_range<std::size_t>& r) {
                              if (is_cancelled(cancel)) return;
                              for (std::size_t j = r.begin(); j != r.end(); ++j) visit(k, set, j);
                          });
    }
}

}  // namespace

CameraSplatPrepass::CameraSplatPrepass(const Scene::Impl& scene, const RenderSettings& settings, const Camera& camera,
                                       const std::atomic<bool>* cancel)
    : s_(scene) {
    if (s_.keep_frame_buffers) {
        const std::lock_guard<std::mutex> lock(s_.frame_buffers_mutex);
        if (s_.frame_buffers) b_ = std::move(*s_.frame_buffers);
        s_.frame_buffers.reset();
    }
    const CameraRayGenerator rays(camera, settings.width, settings.height);
    proj_ = rays.pinhole_projection();
    const glm::mat3 camera_linear = linear_part(camera.camera_to_world);
    world_to_camera_ = glm::inverse(camera_linear);
    camera_origin_ = translation_part(camera.camera_to_world);
    // Depths in camera space: a scaled camera matrix scales them, and its clip distances are in the same units
    // (camera.cpp: the clip range is measured along the unscaled view axis).
    near_ = camera.clip_start;
    far_ = camera.clip_end;
    lim_x_ = kJacobianClamp * proj_.half_width_tan;
    lim_y_ = kJacobianClamp * proj_.half_height_tan;
    set_up_grids(settings);

    // Every Gaussian of the scene has a global index: primitive j of set k is set_base[k] + j.
    std::vector<std::size_t> set_base(s_.gaussians.size() + 1, 0);
    for (std::size_t k = 0; k < s_.gaussians.size(); ++k) set_base[k + 1] = set_base[k] + s_.gaussians[k]->prims.size();
    const std::size_t total = set_base.back();
    if (total >= std::size_t(kNotVisible))
        throw Error("camera-ray splatting: " + std::to_string(total) + " Gaussians are more than it indexes (2^32 - 1)");

    // The camera ray's SH direction is camera -> centre (GaussianSet::display_color with the camera's origin).
    if (!sorted_keys(set_base, settings.blend_space == BlendSpace::Display, cancel) || is_cancelled(cancel)) return;
    gather(set_base, cancel);
    if (is_cancelled(cancel)) return;

    // Tile lists, two levels. A 4 x 4 packet of camera rays reads the list of its 16 px tile, and in a zoomed-out
    // view of a big scene that list holds thousands of splats of a pixel or two, of which the packet's sixteenth of the
    // tile meets a few percent, so splatting such a view cost several times the traced render. Small splats therefore
    // go into lists of the packets' own 4 px tiles; big ones stay in 16 px lists, where they cost 16x fewer entries
    // (4 px tiles alone multiply a big splat's entries, and the pre-pass with them). A packet merges its two lists.
    size_for_overwrite(b_.level, b_.splats.size());
    for (std::size_t i = 0; i < b_.splats.size(); ++i) b_.level[i] = b_.splats[i].half_extent <= kFineSplatMaxHalfExtent;
    bin(b_.coarse, 0, cancel);
    if (is_cancelled(cancel)) return;
    bin(b_.fine, 1, cancel);
    if (!s_.keep_frame_buffers) b_.release_working_arrays();
}

CameraSplatPrepass::~CameraSplatPrepass() {
    if (!s_.keep_frame_buffers) return;
    const std::lock_guard<std::mutex> lock(s_.frame_buffers_mutex);
    // (Of two pre-passes of one scene at once, the storage of the one that ends last is kept.)
    s_.frame_buffers = std::make_unique<CameraSplatBuffers>(std::move(b_));
}

float CameraSplatPrepass::view_depth(const glm::vec3& world_point) const {
    return -(world_to_camera_ * (world_point - camera_origin_)).z;
}

void CameraSplatPrepass::set_up_grids(const RenderSettings& settings) {
    const PixelRect region = render_region_of(settings);
    const int margin = filter_margin(settings);
    grid_x0_ = region.x0 - margin;
    grid_y0_ = region.y0 - margin;
    SplatTileLists& coarse = b_.coarse;
    SplatTileLists& fine = b_.fine;
    coarse.size = kTileSize;
    coarse.nx = (region.width() + 2 * margin + kTileSize - 1) / kTileSize;
    coarse.ny = (region.height() + 2 * margin + kTileSize - 1) / kTileSize;
    // The fine grid subdivides the coarse one exactly, so that a fine tile lies in one coarse tile.
    static_assert(kTileSize % kFineTileSize == 0, "fine tiles subdivide coarse tiles");
    static_assert((kTileSize & (kTileSize - 1)) == 0 && (kFineTileSize & (kFineTileSize - 1)) == 0,
                  "tile sizes are powers of two (tile_square multiplies by their reciprocals)");
    fine.size = kFineTileSize;
    fine.nx = coarse.nx * (kTileSize / kFineTileSize);
    fine.ny = coarse.ny * (kTileSize / kFineTileSize);
    grid_x1_ = float(grid_x0_ + coarse.nx * kTileSize);
    grid_y1_ = float(grid_y0_ + coarse.ny * kTileSize);
    // A packet's samples lie within this of its pixels' squares (jitter: the pixel filter's reach from the centre).
    sample_pad_ = settings.jitter
                      ? std::max(0.0f, PixelFilterSampler::reach(settings.pixel_filter, settings.filter_width) - 0.5f)
                      : 0.0f;
}

bool CameraSplatPrepass::project(const GaussianSet& set, const glm::mat3& wa_t, std::uint32_t prim,
                                 ProjectedSplat& out) const {
    const GaussianPrimitive& g = set.prims[prim];
    if (!(g.opacity >= kMinAlpha)) return false;
    const glm::vec3 p = world_to_camera_ * (set.world_center(prim) - camera_origin_);
    const float z = -p.z;
    if (!(z > near_ && z < far_)) return false;
    // Sigma = L L^T in the cloud's frame, L = M^-1 (M: rows 0..2 of the primitive, GaussianPrimitive), whose
    // columns are the Gaussian's axes times their scales.
    glm::mat3 m;
    m[0] = glm::vec3(g.row0.x, g.row1.x, g.row2.x);
    m[1] = glm::vec3(g.row0.y, g.row1.y, g.row2.y);
    m[2] = glm::vec3(g.row0.z, g.row1.z, g.row2.z);
    glm::mat3 l = glm::inverse(m);
    if (set.flat) {
        // A flat primitive's third row is its unit normal: its column of L is the unit axis, scaled here by the
        // Gaussian's smallest scale (as make_primitive clamps it), so that the footprint is the 3D Gaussian's, as
        // a viewer draws it, in either mode (the mode is the geometry rays trace).
        l[2] *= g.thin_scale;
    }
    // The Jacobian of (X, Y, Z) -> (cx + fx X / z, cy - fy Y / z), z = -Z, at the centre (x/z, y/z clamped
    // about the frustum's centre, forward.cu computeCov2D).
    const float tx = std::clamp(p.x / z, proj_.center_x_tan - lim_x_, proj_.center_x_tan + lim_x_);
    const float ty = std::clamp(p.y / z, proj_.center_y_tan - lim_y_, proj_.center_y_tan + lim_y_);
    const glm::vec3 j0(proj_.fx / z, 0.0f, proj_.fx * tx / z), j1(0.0f, -proj_.fy / z, -proj_.fy * ty / z);
    // Rows of J W A (2 x 3), applied to L's columns: K = J W A L, Sigma' = K K^T.
    const glm::vec3 r0 = wa_t * j0, r1 = wa_t * j1;
    double a = kDilation, b = 0.0, c = kDilation;
    for (int k = 0; k < 3; ++k) {
        const double k0 = glm::dot(r0, l[k]), k1 = glm::dot(r1, l[k]);
        a += k0 * k0;
        b += k0 * k1;
        c += k1 * k1;
    }
    const double det = a * c - b * b;
    if (!(det > 0.0) || !std::isfinite(det)) return false;
    const double mid = 0.5 * (a + c);
    const double lambda_max = mid + std::sqrt(std::max(0.1, mid * mid - det));
    const float half = float(kFootprintSigmas * std::sqrt(lambda_max));
    const float u = proj_.cx + proj_.fx * p.x / z, v = proj_.cy - proj_.fy * p.y / z;
    if (!(u + half >= float(grid_x0_) && u - half < grid_x1_ && v + half >= float(grid_y0_) && v - half < grid_y1_))
        return false;
    out.u = u;
    out.v = v;
    out.conic[0] = float(c / det);
    out.conic[1] = float(-b / det);
    out.conic[2] = float(a / det);
    out.opacity = g.opacity;
    out.depth = z;
    out.half_extent = half;
    out.least_power = std::log(kMinAlpha / g.opacity) - kLeastPowerMargin;
    return true;
}

// project() for primitives prim .. prim + 3 of `set` at once: each lane takes the scalar code's IEEE operations in
// its order (glm's matrix products, inverse and dot products as glm writes them; no fused operations), so each
// projection is bit for bit the scalar one, four to an instruction. Returns the visible lanes, whose `out` it writes.
unsigned CameraSplatPrepass::project4(const GaussianSet& set, const glm::mat3& wa_t, std::uint32_t prim,
                                      ProjectedSplat* out) const {
    const GaussianPrimitive* g = &set.prims[prim];
    // Each primitive is four quads: (centre, opacity), (row 0, -), (row 1, thin scale), (row 2, -). quad(q, v) puts
    // component c of quad q of the four primitives in v[c].
    static_assert(offsetof(GaussianPrimitive, opacity) == 12 && offsetof(GaussianPrimitive, thin_scale) == 44,
                  "the quads of GaussianPrimitive");
    const auto quad = [g](int q, __m128 (&v)[4]) {
        for (int l = 0; l < 4; ++l) v[l] = _mm_loadu_ps(reinterpret_cast<const float*>(&g[l]) + 4 * q);
        _MM_TRANSPOSE4_PS(v[0], v[1], v[2], v[3]);
    };
    __m128 centre[4], row0[4], row1[4], row2[4];
    quad(0, centre);
    quad(1, row0);
    quad(2, row1);
    quad(3, row2);
    const __m128 cx = centre[0], cy = centre[1], cz = centre[2], op = centre[3], thin = row1[3];
    const __m128 r0x = row0[0], r0y = row0[1], r0z = row0[2], r1x = row1[0], r1y = row1[1], r1z = row1[2];
    const __m128 r2x = row2[0], r2y = row2[1], r2z = row2[2];
    // (Sse's operations: each one IEEE instruction; Sse::madd is not used, so nothing is fused on any machine.)
    // (Lambdas, not pointers to the functions: a call through a pointer is not always inlined.)
    using S = Sse;
    const auto set1 = [](float s) { return S::set1(s); };
    const auto add = [](__m128 a, __m128 b) { return S::add(a, b); };
    const auto sub = [](__m128 a, __m128 b) { return S::sub(a, b); };
    const auto mul = [](__m128 a, __m128 b) { return S::mul(a, b); };
    const auto div = [](__m128 a, __m128 b) { return S::div(a, b); };
    const auto neg = [](__m128 a) { return S::neg(a); };
    // glm: (m * v)[i] = m[0][i] v.x + m[1][i] v.y + m[2][i] v.z, summed left to right.
    const auto mat_vec = [&](const glm::mat3& m, int i, __m128 x, __m128 y, __m128 z) {
        return add(add(mul(set1(m[0][i]), x), mul(set1(m[1][i]), y)), mul(set1(m[2][i]), z));
    };
    __m128 visible = _mm_cmpge_ps(op, set1(kMinAlpha));
    // p = W (A c + b - o)
    const __m128 dx = sub(add(mat_vec(set.linear, 0, cx, cy, cz), set1(set.translation.x)), set1(camera_origin_.x));
    const __m128 dy = sub(add(mat_vec(set.linear, 1, cx, cy, cz), set1(set.translation.y)), set1(camera_origin_.y));
    const __m128 dz = sub(add(mat_vec(set.linear, 2, cx, cy, cz), set1(set.translation.z)), set1(camera_origin_.z));
    const __m128 px = mat_vec(world_to_camera_, 0, dx, dy, dz), py = mat_vec(world_to_camera_, 1, dx, dy, dz);
    const __m128 z = neg(mat_vec(world_to_camera_, 2, dx, dy, dz));
    visible = _mm_and_ps(visible, _mm_and_ps(_mm_cmpgt_ps(z, set1(near_)), _mm_cmplt_ps(z, set1(far_))));
    // L = M^-1, M[c][r] = row r's component c (glm's inverse, term for term); l[k] is L's column k.
    const __m128 m00 = r0x, m01 = r1x, m02 = r2x, m10 = r0y, m11 = r1y, m12 = r2y, m20 = r0z, m21 = r1z, m22 = r2z;
    const __m128 one_over_det =
        div(set1(1.0f), add(sub(mul(m00, sub(mul(m11, m22), mul(m21, m12))), mul(m10, sub(mul(m01, m22), mul(m21, m02)))),
                            mul(m20, sub(mul(m01, m12), mul(m11, m02)))));
    __m128 l[3][3];  // [column][row]
    l[0][0] = mul(sub(mul(m11, m22), mul(m21, m12)), one_over_det);
    l[1][0] = mul(neg(sub(mul(m10, m22), mul(m20, m12))), one_over_det);
    l[2][0] = mul(sub(mul(m10, m21), mul(m20, m11)), one_over_det);
    l[0][1] = mul(neg(sub(mul(m01, m22), mul(m21, m02))), one_over_det);
    l[1][1] = mul(sub(mul(m00, m22), mul(m20, m02)), one_over_det);
    l[2][1] = mul(neg(sub(mul(m00, m21), mul(m20, m01))), one_over_det);
    l[0][2] = mul(sub(mul(m01, m12), mul(m11, m02)), one_over_det);
    l[1][2] = mul(neg(sub(mul(m00, m12), mul(m10, m02))), one_over_det);
    l[2][2] = mul(sub(mul(m00, m11), mul(m10, m01)), one_over_det);
    if (set.flat)
        for (int r = 0; r < 3; ++r) l[2][r] = mul(l[2][r], thin);
    // std::clamp(v, lo, hi) = v < lo ? lo : (hi < v ? hi : v)
    const auto clamp = [](__m128 v, float lo, float hi) {
        const __m128 vlo = Sse::set1(lo), vhi = Sse::set1(hi);
        const __m128 below = _mm_cmplt_ps(v, vlo), above = _mm_cmplt_ps(vhi, v);
        const __m128 upper = _mm_or_ps(_mm_and_ps(above, vhi), _mm_andnot_ps(above, v));
        return _mm_or_ps(_mm_and_ps(below, vlo), _mm_andnot_ps(below, upper));
    };
    const __m128 tx = clamp(div(px, z), proj_.center_x_tan - lim_x_, proj_.center_x_tan + lim_x_);
    const __m128 ty = clamp(div(py, z), proj_.center_y_tan - lim_y_, proj_.center_y_tan + lim_y_);
    const __m128 zero = _mm_setzero_ps();
    const __m128 j0x = div(set1(proj_.fx), z), j0z = div(mul(set1(proj_.fx), tx), z);
    const __m128 j1y = div(set1(-proj_.fy), z), j1z = div(mul(set1(-proj_.fy), ty), z);
    __m128 r0[3], r1[3];
    for (int i = 0; i < 3; ++i) {
        r0[i] = mat_vec(wa_t, i, j0x, zero, j0z);
        r1[i] = mat_vec(wa_t, i, zero, j1y, j1z);
    }
    // glm::dot(a, b) = (a.x b.x + a.y b.y) + a.z b.z, in float; the sums in double.
    __m128d a[2], b[2], c[2];
    for (int h = 0; h < 2; ++h) {
        a[h] = c[h] = _mm_set1_pd(double(kDilation));
        b[h] = _mm_setzero_pd();
    }
    for (int k = 0; k < 3; ++k) {
        const __m128 k0 = add(add(mul(r0[0], l[k][0]), mul(r0[1], l[k][1])), mul(r0[2], l[k][2]));
        const __m128 k1 = add(add(mul(r1[0], l[k][0]), mul(r1[1], l[k][1])), mul(r1[2], l[k][2]));
        for (int h = 0; h < 2; ++h) {
            const __m128d k0d = _mm_cvtps_pd(h ? _mm_movehl_ps(k0, k0) : k0);
            const __m128d k1d = _mm_cvtps_pd(h ? _mm_movehl_ps(k1, k1) : k1);
            a[h] = _mm_add_pd(a[h], _mm_mul_pd(k0d, k0d));
            b[h] = _mm_add_pd(b[h], _mm_mul_pd(k0d, k1d));
            c[h] = _mm_add_pd(c[h], _mm_mul_pd(k1d, k1d));
        }
    }
    alignas(16) double det_of[4], conic_of[3][4], half_of[4];
    for (int h = 0; h < 2; ++h) {
        const __m128d det = _mm_sub_pd(_mm_mul_pd(a[h], c[h]), _mm_mul_pd(b[h], b[h]));
        const __m128d mid = _mm_mul_pd(_mm_set1_pd(0.5), _mm_add_pd(a[h], c[h]));
        // std::max(0.1, x) = 0.1 < x ? x : 0.1, as MAXPD(x, 0.1) (which gives 0.1 for NaN too)
        const __m128d spread = _mm_max_pd(_mm_sub_pd(_mm_mul_pd(mid, mid), det), _mm_set1_pd(0.1));
        const __m128d lambda_max = _mm_add_pd(mid, _mm_sqrt_pd(spread));
        _mm_store_pd(half_of + 2 * h, _mm_mul_pd(_mm_set1_pd(double(kFootprintSigmas)), _mm_sqrt_pd(lambda_max)));
        _mm_store_pd(det_of + 2 * h, det);
        _mm_store_pd(conic_of[0] + 2 * h, _mm_div_pd(c[h], det));
        _mm_store_pd(conic_of[1] + 2 * h, _mm_div_pd(_mm_xor_pd(b[h], _mm_set1_pd(-0.0)), det));
        _mm_store_pd(conic_of[2] + 2 * h, _mm_div_pd(a[h], det));
    }
    const __m128 u = add(set1(proj_.cx), div(mul(set1(proj_.fx), px), z));
    const __m128 v = sub(set1(proj_.cy), div(mul(set1(proj_.fy), py), z));
    alignas(16) float u_of[4], v_of[4], z_of[4], op_of[4];
    _mm_store_ps(u_of, u);
    _mm_store_ps(v_of, v);
    _mm_store_ps(z_of, z);
    _mm_store_ps(op_of, op);
    unsigned lanes = unsigned(_mm_movemask_ps(visible));
    for (unsigned live = lanes; live; live &= live - 1) {
        const int lane = __builtin_ctz(live);
        const double det = det_of[lane];
        const float half = float(half_of[lane]), ul = u_of[lane], vl = v_of[lane];
        if (!(det > 0.0) || !std::isfinite(det) ||
            !(ul + half >= float(grid_x0_) && ul - half < grid_x1_ && vl + half >= float(grid_y0_) && vl - half < grid_y1_)) {
            lanes &= ~(1u << lane);
            continue;
        }
        ProjectedSplat& ps = out[lane];
        ps.u = ul;
        ps.v = vl;
        ps.conic[0] = float(conic_of[0][lane]);
        ps.conic[1] = float(conic_of[1][lane]);
        ps.conic[2] = float(conic_of[2][lane]);
        ps.opacity = op_of[lane];
        ps.depth = z_of[lane];
        ps.half_extent = half;
        ps.least_power = std::log(kMinAlpha / op_of[lane]) - kLeastPowerMargin;
    }
    return lanes;
}

bool CameraSplatPrepass::sorted_keys(const std::vector<std::size_t>& set_base, bool display,
                                     const std::atomic<bool>* cancel) {
    // The visible Gaussians' keys, depth above global index (positive floats order as their bit patterns; ties go
    // by scene order), sorted. The projections are kept for the gather, which would otherwise project every visible
    // Gaussian a second time (the projection is most of this pass).
    SplatArray<std::uint64_t>& keys = b_.keys;
    SplatArray<ProjectedSplat>& projected = b_.projected;
    keys.assign(set_base.back(), kNotVisibleKey);
    size_for_overwrite(projected, set_base.back());
    // (W A)^T of each set, W the world-to-camera rotation and A the set's linear part.
    std::vector<glm::mat3> wa_t(s_.gaussians.size());
    for (std::size_t k = 0; k < wa_t.size(); ++k) wa_t[k] = glm::transpose(world_to_camera_ * s_.gaussians[k]->linear);
    // RAYSPLATS_PROJECTION=scalar: project() alone (the tests compare the two).
    const char* path = std::getenv("RAYSPLATS_PROJECTION");
    const bool simd = !(path && std::string(path) == "scalar");
    const glm::vec3 origin = camera_origin_;
    // A visible Gaussian's key, and its colour (the same for every camera sample), computed here in the scene's order
    // so that the Gaussians' data (SH up to 192 bytes each) is read in order, not at random.
    const auto key_of = [&](const GaussianSet& set, std::uint32_t prim, std::size_t index) {
        ProjectedSplat& ps = projected[index];
        ps.color = display ? set.display_color(prim, origin) : set.color(prim, origin);
        std::uint32_t depth_bits;
        std::memcpy(&depth_bits, &ps.depth, sizeof depth_bits);
        return std::uint64_t(depth_bits) << 32 | index;
    };
    for (std::size_t k = 0; k < s_.gaussians.size(); ++k) {
        const GaussianSet& set = *s_.gaussians[k];
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, set.prims.size(), 4096),
                          [&](const tbb::blocked_range<std::size_t>& r) {
                              if (is_cancelled(cancel)) return;
                              std::size_t j = r.begin();
                              for (; simd && j + 4 <= r.end(); j += 4) {
                                  const std::size_t first = set_base[k] + j;
                                  for (unsigned lanes = project4(set, wa_t[k], std::uint32_t(j), &projected[first]);
                                       lanes; lanes &= lanes - 1) {
                                      const unsigned lane = unsigned(__builtin_ctz(lanes));
                                      keys[first + lane] = key_of(set, std::uint32_t(j + lane), first + lane);
                                  }
                              }
                              for (; j != r.end(); ++j)
                                  if (project(set, wa_t[k], std::uint32_t(j), projected[set_base[k] + j]))
                                      keys[set_base[k] + j] = key_of(set, std::uint32_t(j), set_base[k] + j);
                          });
    }
    if (is_cancelled(cancel)) return false;
    keys.erase(std::remove(keys.begin(), keys.end(), kNotVisibleKey), keys.end());
    sort_by_high_word(keys, b_.sort_scratch);  // (the low words are the global indices, ascending)
    if (!s_.keep_frame_buffers) b_.sort_scratch = {};
    return true;
}

void CameraSplatPrepass::gather(const std::vector<std::size_t>& set_base, const std::atomic<bool>* cancel) {
    // The splats in depth order: each rank's projection read from its Gaussian's place (fetched kAhead ranks before
    // its turn: the places are at random), written in order.
    const SplatArray<std::uint64_t>& keys = b_.keys;
    const SplatArray<ProjectedSplat>& projected = b_.projected;
    size_for_overwrite(b_.splats, keys.size());
    size_for_overwrite(b_.sources, keys.size());
    constexpr std::size_t kAhead = 16;
    const std::size_t sets = set_base.size() - 1;
    using Range = tbb::blocked_range<std::size_t>;
    tbb::parallel_for(Range(0, keys.size(), 4096), [&](const Range& r) {
        if (is_cancelled(cancel)) return;
        for (std::size_t i = r.begin(); i != r.end(); ++i) {
            if (i + kAhead < r.end()) __builtin_prefetch(&projected[keys[i + kAhead] & 0xffffffffu]);
            const std::size_t index = keys[i] & 0xffffffffu;
            b_.splats[i] = projected[index];
            // The set holding global index `index`: the last k with set_base[k] <= index (a search without branches,
            // as the sets of consecutive ranks are at random).
            std::size_t k = 0;
            for (std::size_t step = std::size_t(1) << (63 - __builtin_clzll(sets | 1)); step; step >>= 1)
                k = k + step < sets && set_base[k + step] <= index ? k + step : k;
            b_.sources[i] = SplatSource{s_.gaussians[k]->index, std::uint32_t(index - set_base[k])};
        }
    });
    // (The samples do not read the working arrays: a scene that does not keep the storage frees these now.)
    if (!s_.keep_frame_buffers) {
        b_.keys = {};
        b_.projected = {};
    }
}

// The tiles a splat can draw in: those whose samples its square reaches where alpha can reach 1/255, i.e. where
// q(d) = d^T Sigma'^-1 d <= 2 ln(255 a) (a exp(-q / 2) >= 1/255) somewhere on the tile widened by the samples' pad.
// Outside that ellipse every sample skips the splat anyway, so leaving it out of those tiles changes no image; it keeps
// thin and faint Gaussians out of most of their square's tiles. The pad lets a packet read only the lists of its
// pixels' tile, wherever jitter put its samples (a list per tile a sample fell in cost a packet 2-4 reads).
inline CameraSplatPrepass::TileSquare CameraSplatPrepass::tile_square(const SplatTileLists& lists,
                                                               const ProjectedSplat& ps) const {
    // (Tile sizes are powers of two: the product by the reciprocal is the quotient, exactly.)
    const float inv_size = 1.0f / float(lists.size);
    const float reach_x = ps.half_extent + float(sample_pad_ + kTilePadMargin);
    return TileSquare{std::max(0, floor_int((ps.u - reach_x - float(grid_x0_)) * inv_size)),
                      std::max(0, floor_int((ps.v - reach_x - float(grid_y0_)) * inv_size)),
                      std::min(lists.nx - 1, floor_int((ps.u + reach_x - float(grid_x0_)) * inv_size)),
                      std::min(lists.ny - 1, floor_int((ps.v + reach_x - float(grid_y0_)) * inv_size))};
}

template <typename Visit>
void CameraSplatPrepass::for_each_tile(const SplatTileLists& lists, const ProjectedSplat& ps, const TileSquare& sq,
                                       Visit&& visit) const {
    // A square of at most 3 x 3 tiles: each of them. The ellipse would leave out a few of its tiles, but finding them
    // costs more than the test with which those tiles' samples skip the splat (docs/benchmarks.md has the figures).
    if (sq.tx1 - sq.tx0 < 3 && sq.ty1 - sq.ty0 < 3) {
        for (int ty = sq.ty0; ty <= sq.ty1; ++ty)
            for (int tx = sq.tx0; tx <= sq.tx1; ++tx)
                visit(std::size_t(ty) * lists.nx + tx, (ty - sq.ty0) * sq.width() + (tx - sq.tx0));
        return;
    }
    const int size = lists.size;
    const double inv_size = 1.0 / size;  // (a power of two: exact)
    const double pad = sample_pad_ + kTilePadMargin;
    // 2 ln(255 a) with a margin for rounding (a sample whose alpha rounds up to 1/255 must find the splat in its
    // tile). ln(255 a) is -least_power less its margin: the float logarithm that gave it is within 2e-6 of the exact
    // one, which the last term covers.
    const double reach = 2.0 * (-double(ps.least_power) - double(kLeastPowerMargin)) * 1.001 + 1e-3 + 1e-5;
    // A tile is reached when the ellipse meets it, widened by the pad: in its row, when the ellipse's extent within
    // the row's band meets the tile's columns. The ellipse and the extent are widened a little more (kSlack) so that
    // rounding can only add a tile whose samples all skip the splat, never leave one out.
    constexpr double kSlack = 1e-4;  // px
    const SplatEllipse ellipse(ps.conic[0], ps.conic[1], ps.conic[2], reach * (1.0 + 1e-6));
    const double left = double(grid_x0_) - double(ps.u) - pad;  // tile column 0's left edge, widened, from the centre
    // Just around the square: a row's extent is clamped to this first (x0 and x1 can be infinite).
    const double lo = left + double(sq.tx0 - 1) * size, hi = left + double(sq.tx1 + 2) * size;
    for (int ty = sq.ty0; ty <= sq.ty1; ++ty) {
        const double ly = double(grid_y0_ + ty * size) - ps.v - pad, hy = ly + size + 2.0 * pad;
        double x0, x1;
        if (!ellipse.row_extent(ly - kSlack, hy + kSlack, x0, x1)) continue;
        // Column tx spans [left + tx size, left + tx size + size + 2 pad]: it meets [x0, x1] from the first column
        // whose right edge reaches x0 to the last whose left edge is at most x1.
        const double first = (std::clamp(x0 - kSlack, lo, hi) - left - 2.0 * pad) * inv_size - 1.0;
        const double last = (std::clamp(x1 + kSlack, lo, hi) - left) * inv_size;
        const int tx0 = std::max(sq.tx0, ceil_int(first)), tx1 = std::min(sq.tx1, floor_int(last));
        for (int tx = tx0; tx <= tx1; ++tx)
            visit(std::size_t(ty) * lists.nx + tx, (ty - sq.ty0) * sq.width() + (tx - sq.tx0));
    }
}

void CameraSplatPrepass::bin(SplatTileLists& lists, std::uint8_t which, const std::atomic<bool>* cancel) {
    const SplatArray<ProjectedSplat>& splats = b_.splats;
    const SplatArray<std::uint8_t>& level = b_.level;
    const std::size_t tile_count = std::size_t(lists.nx) * std::size_t(lists.ny);
    // A counting sort by tile that keeps the depth order: the splats in chunks of consecutive ranks, each chunk's
    // count per tile, every chunk's start in every list (the lists' offsets plus the counts of the chunks before it),
    // and each chunk fills its splats in rank order from its starts. No atomics, and no list needs sorting after (a
    // zoomed-out view of showroom_1.5M puts 8 M entries in a few hundred tiles, where atomic counters and a sort per
    // list were most of the pre-pass).
    // A cancel (the viewport stops its jobs on the UI thread before an edit reaches the scene) is seen within this
    // many splats of a chunk, since binning a scene of ten million splats takes the order of a second on one thread.
    constexpr std::size_t kCancelCheckInterval = 4096;
    const std::size_t chunks = std::clamp<std::size_t>(splats.size() / 256, 1, 16);
    // Chunk k is ranks [bounds[k], bounds[k + 1]), holding an equal share of this level's splats: the levels are not
    // spread evenly over the depth order (a far view's small splats are the back of it), and chunks of equal rank
    // ranges left one thread binning most of the fine level.
    std::vector<std::size_t> bounds(chunks + 1, splats.size());
    {
        const std::size_t total = std::size_t(std::count(level.begin(), level.end(), which));
        bounds[0] = 0;
        std::size_t seen = 0, k = 1;  // (seen: this level's splats before rank i)
        for (std::size_t i = 0; i < splats.size() && k < chunks; ++i) {
            if (level[i] != which) continue;
            while (k < chunks && k * total / chunks <= seen) bounds[k++] = i;
            ++seen;
        }
    }
    std::vector<std::uint32_t>& starts = b_.starts;
    starts.assign(chunks * tile_count, 0);  // chunk k's count, then its cursor, in tile t: [k * tile_count + t]
    // The tiles each splat reaches are found once: the count pass records them as bits over the splat's square of
    // tiles (row by row), and the fill pass reads the bits instead of testing the ellipse on every tile again (the
    // tests were most of the binning). Every fine splat's square fits in 64 tiles; a bigger square is tested again.
    // The square is kept with the bits, so that the fill pass reads neither the splat nor its square again.
    constexpr int kMaskTiles = 64;
    SplatArray<ReachedTiles>& reached = b_.reached;
    size_for_overwrite(reached, splats.size());
    tbb::parallel_for(std::size_t(0), chunks, [&](std::size_t k) {
        std::uint32_t* count = starts.data() + k * tile_count;
        for (std::size_t i = bounds[k], end = bounds[k + 1]; i < end; ++i) {
            if (i % kCancelCheckInterval == 0 && is_cancelled(cancel)) return;
            if (level[i] != which) continue;
            const TileSquare sq = tile_square(lists, splats[i]);
            std::uint64_t bits = 0;
            for_each_tile(lists, splats[i], sq, [&](std::size_t t, int bit) {
                ++count[t];
                if (bit < kMaskTiles) bits |= std::uint64_t(1) << bit;
            });
            const bool kept = sq.count() <= kMaskTiles && sq.tx0 <= 0xffff && sq.ty0 <= 0xffff;
            reached[i] = ReachedTiles{bits, std::uint16_t(sq.tx0), std::uint16_t(sq.ty0),
                                      std::uint16_t(kept ? sq.width() : 0)};
        }
    });
    if (is_cancelled(cancel)) return;
    lists.offsets.assign(tile_count + 1, 0);
    for (std::size_t t = 0; t < tile_count; ++t) {
        std::uint64_t at = lists.offsets[t];
        for (std::size_t k = 0; k < chunks; ++k) {
            const std::uint32_t n = starts[k * tile_count + t];
            starts[k * tile_count + t] = std::uint32_t(at - lists.offsets[t]);  // (within the list: fits 32 bits)
            at += n;
        }
        lists.offsets[t + 1] = at;
    }
    size_for_overwrite(lists.entries, lists.offsets[tile_count]);
    tbb::parallel_for(std::size_t(0), chunks, [&](std::size_t k) {
        std::uint32_t* cursor = starts.data() + k * tile_count;
        for (std::size_t i = bounds[k], end = bounds[k + 1]; i < end; ++i) {
            if (i % kCancelCheckInterval == 0 && is_cancelled(cancel)) return;  // (the lists unfinished: nothing renders)
            if (level[i] != which) continue;
            auto add = [&](std::size_t t) { lists.entries[lists.offsets[t] + cursor[t]++] = std::uint32_t(i); };
            const ReachedTiles& r = reached[i];
            if (r.width == 0) {  // (not kept: tested again)
                for_each_tile(lists, splats[i], tile_square(lists, splats[i]), [&](std::size_t t, int) { add(t); });
                continue;
            }
            for (std::uint64_t bits = r.bits; bits != 0; bits &= bits - 1) {
                const int bit = __builtin_ctzll(bits);
                add(std::size_t(r.ty0 + bit / r.width) * lists.nx + std::size_t(r.tx0 + bit % r.width));
            }
        }
    });
}

namespace {

template <typename Array>
std::size_t capacity_of(const Array& a) {
    return a.capacity() * sizeof(typename Array::value_type);
}

}  // namespace

std::size_t CameraSplatBuffers::frame_bytes() const {
    return capacity_of(splats) + capacity_of(sources) + capacity_of(coarse.entries) + capacity_of(coarse.offsets) +
           capacity_of(fine.entries) + capacity_of(fine.offsets);
}

std::size_t CameraSplatBuffers::capacity_bytes() const {
    return frame_bytes() + capacity_of(keys) + capacity_of(sort_scratch) + capacity_of(projected) +
           capacity_of(level) + capacity_of(starts) + capacity_of(reached);
}

void CameraSplatBuffers::release_working_arrays() {
    keys = {};
    sort_scratch = {};
    projected = {};
    level = {};
    starts = {};
    reached = {};
}

std::size_t SplatTileLists::tile_of(float x, float y, int x0, int y0) const {
    const int tx = std::clamp(int(std::floor((x - float(x0)) / size)), 0, nx - 1);
    const int ty = std::clamp(int(std::floor((y - float(y0)) / size)), 0, ny - 1);
    return std::size_t(ty) * nx + tx;
}

}  // namespace raysplats
