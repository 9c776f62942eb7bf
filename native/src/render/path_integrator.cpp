#include "path_integrator.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include "bsdf.h"
#include "mist.h"

namespace raysplats {

namespace {

// a / b per channel, 0 where b is 0 (Cycles' safe_divide): the share of a lobe in an evaluation.
glm::vec3 share(const glm::vec3& a, const glm::vec3& b) {
    return {b.x != 0.0f ? a.x / b.x : 0.0f, b.y != 0.0f ? a.y / b.y : 0.0f, b.z != 0.0f ? a.z / b.z : 0.0f};
}

// Adds `light` to the Direct or Indirect passes of the three lobes in the shares given (transmission: the rest, as
// Cycles computes it).
void add_to_lobes(std::array<glm::vec3, kLightPassCount>& passes, const glm::vec3& light, bool direct,
                  const glm::vec3& diffuse_share, const glm::vec3& glossy_share) {
    const std::size_t diffuse = std::size_t(direct ? LightPass::DiffuseDirect : LightPass::DiffuseIndirect);
    const std::size_t glossy = std::size_t(direct ? LightPass::GlossyDirect : LightPass::GlossyIndirect);
    const std::size_t transmission =
        std::size_t(direct ? LightPass::TransmissionDirect : LightPass::TransmissionIndirect);
    passes[diffuse] += light * diffuse_share;
    passes[glossy] += light * glossy_share;
    passes[transmission] += light * (glm::vec3(1.0f) - diffuse_share - glossy_share);
}

}  // namespace

inline Surface PathIntegrator::surface(const Segment& seg, const Ray& ray) const {
    const MeshRecord& m = *s_.meshes[s_.top[seg.top_geom].index];
    const std::uint32_t* idx = m.desc.indices + 3 * std::size_t(seg.prim);
    // (With deformation, the triangle where the ray's time puts it: the geometric normal turns with it.)
    const glm::vec3 v0 = m.vertex_at(idx[0], ray.time), v1 = m.vertex_at(idx[1], ray.time),
                    v2 = m.vertex_at(idx[2], ray.time);
    Surface sf;
    sf.p = ray.o + seg.t * ray.d;
    const glm::mat3 normal_matrix = m.normal_matrix_at(ray.time);
    sf.ng = glm::normalize(normal_matrix * glm::cross(v1 - v0, v2 - v0));
    const float b0 = 1.0f - seg.u - seg.v, b1 = seg.u, b2 = seg.v;
    sf.ns = sf.ng;
    if (m.desc.normals) {
        const float* n = m.desc.normals;
        auto nrm = [&](std::uint32_t i) { return glm::vec3(n[3 * i], n[3 * i + 1], n[3 * i + 2]); };
        const glm::vec3 ni = normal_matrix * (b0 * nrm(idx[0]) + b1 * nrm(idx[1]) + b2 * nrm(idx[2]));
        const float len = glm::length(ni);
        if (len > 0.0f) sf.ns = ni / len;
        if (glm::dot(sf.ns, sf.ng) < 0.0f) sf.ns = -sf.ns;
    }
    if (m.desc.uvs) {
        const float* t = m.desc.uvs;
        auto uv = [&](std::uint32_t i) { return glm::vec2(t[2 * i], t[2 * i + 1]); };
        sf.uv = b0 * uv(idx[0]) + b1 * uv(idx[1]) + b2 * uv(idx[2]);
    }
    sf.material = m.desc.face_materials ? m.desc.face_materials[seg.prim] : m.desc.material;
    return sf;
}

// How far a ray leaves a surface point `p` (against self-intersection): relative to its coordinates' magnitude.
inline float offset_epsilon(const glm::vec3& p) {
    return 1e-4f * std::max(1.0f, std::max(std::abs(p.x), std::max(std::abs(p.y), std::abs(p.z))));
}

// The nearest area light that `ray` sees before its tmax (Cycles lights_intersect); -1 if none.
inline int PathIntegrator::nearest_light_hit(const Ray& ray, LightHit& hit) const {
    int best = -1;
    float tmax = ray.tmax;
    for (std::size_t i = 0; i < s_.lights.size(); ++i) {
        LightHit h;
        if (intersect_light(s_.lights[i], ray.o, ray.d, tmax, h) && h.t > ray.tmin) {
            hit = h;
            tmax = h.t;
            best = int(i);
        }
    }
    return best;
}

// Display blend space (BlendSpace::Display, docs/design.md §4 and §6): a run of Gaussians along a ray (one
// segment) is composited in display space as trained, D = sum T_i a_i c_i with display colours c_i, and meets what
// lies behind it, the linear radiance L_behind (the mesh it ends on, shaded with its lights and bounces, or the
// world), in that space too:
//     L = linear(D + T * display(L_behind)).
// So an unedited splat scene looks as in a splat viewer (its background the world's colour), and a mesh seen through
// haze is tinted as a viewer would tint it. Everything else stays linear light: mesh shading, lights, BSDFs, the
// film. Reflections and refractions see the splats the same way (each run on a secondary ray is combined with its own
// L_behind, innermost first: a perfect mirror shows the viewer's image), and shadow rays take only transmittance,
// which is not a colour. An area light hit inside a run is added in linear light, weighted by the transmittance in
// front of it, like the run's front (not composited into D). The camera ray's first run is not combined per sample:
// the film combines the means of D, T and T L_behind over the pixel's samples (SampleRecord), so that stochastic
// compositing, whose sample is one display colour or what lies behind, converges to the sorted image, and noise in
// L_behind is averaged in linear light.
struct PathIntegrator::DisplayRun {
    glm::vec3 outer_radiance;  // the path's radiance before the run (at the enclosing run's level)
    glm::vec3 outer_beta;      // the throughput at the run, relative to the enclosing run
    glm::vec3 display;         // D
    float transmittance;       // T
    // Light passes: the path's light before the run, as outer_radiance, and the scatterings before it (the run's
    // own light is emitted light seen at that level: close_run_light).
    std::array<glm::vec3, kLightPassCount> outer_light;
    int level;
};

// One path as path() follows it: the ray it traces next, its radiance and throughput, and what the camera segment
// gives the film.
struct PathIntegrator::PathState {
    PathState(const Ray& r, Sampler& sampler, std::vector<DisplayRun>& display_runs, bool display_blend)
        : ray(r), rng(sampler), runs(display_runs), display(display_blend) {}
    Ray ray;
    Sampler& rng;
    glm::vec3 radiance{0.0f}, beta{1.0f};
    bool camera_segment = true;
    float alpha = 0.0f;
    float depth = kInf;
    glm::vec3 normal{0.0f};
    glm::vec3 position{0.0f};  // the data passes at the depth (SampleRecord)
    float object_index = 0.0f, material_index = 0.0f;
    const FrameMotion* depth_motion = nullptr;  // how the depth's object moves between frames (the Vector pass)
    // A deforming mesh's depth point at the previous and the next frame (world), when depth_deformed (the Vector
    // pass; Scene::set_mesh_frame_deformation).
    bool depth_deformed = false;
    glm::vec3 depth_previous{0.0f}, depth_next{0.0f};
    // The Mist pass's sum (SampleRecord::mist) and the camera ray's transmittance in front of the current segment
    // (surfaces it passed through stochastically).
    float mist_clearance = 0.0f, camera_transmittance = 1.0f;
    // The denoiser's guides (SampleRecord::denoising_albedo, RenderSettings::denoising_data), summed like mist.
    glm::vec3 guide_albedo{0.0f}, guide_normal{0.0f};
    // The Cryptomatte passes' coverage (SampleRecord::cryptomatte), weighted like mist.
    CryptomatteCoverage cryptomatte;
    // The held-out fraction, the Environment pass and the Shadow Catcher pass (SampleRecord::holdout, environment,
    // shadow_catcher).
    float holdout = 0.0f;
    glm::vec3 environment{0.0f};
    glm::vec3 shadow_catcher{1.0f};
    std::uint32_t camera_gaussians = 0;  // composited or accepted along the camera segment
    // depth is the camera segment's mesh hit, whose normal, object and material the surface gives (mesh_data_passes)
    bool normal_at_mesh = false;
    int bounce = 0, passes = 0;
    // Light passes (RenderSettings::light_passes; SampleRecord::light): the path's light split by pass, relative to
    // the open display run as `radiance` is (its Color rows unused); the Color passes' sums (diffuse, glossy,
    // transmission; absolute); the scatterings so far (0: the camera still sees what it meets); and the first
    // scattering's shares of its diffuse and glossy lobes (the rest: transmission), per channel.
    std::array<glm::vec3, kLightPassCount> light{};
    glm::vec3 colors[3] = {glm::vec3(0.0f), glm::vec3(0.0f), glm::vec3(0.0f)};
    int scatters = 0;
    glm::vec3 diffuse_share{0.0f}, glossy_share{0.0f};
    bool after_diffuse = false;  // Cycles PATH_RAY_DIFFUSE: the last bounce was diffuse
    bool last = false;           // the ray leaving the last vertex: emission only
    float mis_pdf = 0.0f;        // pdf of the BSDF sample that made `ray` (0: camera or delta)
    // Display blend space: the runs of Gaussians whose composite waits for the radiance behind them, innermost last.
    // While one is open, `radiance` and `beta` are relative to it (beta_outer: the product of the enclosing betas).
    std::vector<DisplayRun>& runs;
    const bool display;
    bool first_trace = true, camera_run = false;  // camera_run: runs[0] is the camera ray's first segment
    glm::vec3 beta_outer{1.0f};
};

// A diffuse bounce off a segment's LIT or BAKED_SHADOWED Gaussians, when the path takes one.
struct PathIntegrator::GaussianBounce {
    bool taken = false;
    Ray ray{};
    float pdf = 0.0f;
    glm::vec3 beta{0.0f};
};

// The segment of `ray`, adding the emission of an area light in front of its mesh hit (lights do not
// occlude: the ray goes on behind the light, as in Cycles). `mis_pdf` > 0: the ray was sampled from a
// non-delta BSDF with that pdf and the light's emission is weighted against next-event estimation.
inline Segment PathIntegrator::trace_with_lights(const Ray& ray, const Segment* first, float mis_pdf,
                                                 const glm::vec3& beta, PathState& p, Sampler& rng,
                                                 Counters& c) const {
    LightHit lh{};  // (set by nearest_light_hit; initialised for GCC's maybe-uninitialized)
    if (s_.lights.empty() || nearest_light_hit(ray, lh) < 0) return first ? *first : tracer_.trace(ray, rng, c);
    if (first && (first->mesh || first->terminated) && first->t < lh.t) return *first;
    Ray near = ray;
    near.tmax = lh.t;
    Segment s1 = tracer_.trace(near, rng, c);
    if (s1.mesh || s1.terminated) return s1;
    const float w = mis_pdf > 0.0f ? power_heuristic(mis_pdf, lh.pdf) : 1.0f;
    p.radiance += beta * s1.transmittance * lh.radiance * w;
    if (st_.light_passes) add_emitted(p, beta * s1.transmittance * lh.radiance * w, p.scatters);
    Ray far = ray;
    far.tmin = lh.t;
    const Segment s2 = trace_with_lights(far, nullptr, mis_pdf, beta * s1.transmittance, p, rng, c);
    Segment seg = s2;
    seg.radiance = s1.radiance + s1.transmittance * s2.radiance;
    seg.shading = s1.shading;
    seg.shading.append_behind(s2.shading, s1.transmittance, rng);
    seg.transmittance = s1.transmittance * s2.transmittance;
    seg.mist_clearance = s1.mist_clearance + s1.transmittance * s2.mist_clearance;
    seg.guide_albedo = s1.guide_albedo + s1.transmittance * s2.guide_albedo;
    seg.guide_normal = s1.guide_normal + s1.transmittance * s2.guide_normal;
    seg.holdout = s1.holdout + s1.transmittance * s2.holdout;
    if (cryptomatte_) {
        seg.cryptomatte = s1.cryptomatte;
        seg.cryptomatte.add_scaled(s2.cryptomatte, s1.transmittance);
    }
    if (s1.depth < kInf) {
        seg.depth = s1.depth;
        seg.normal = s1.normal;
        seg.depth_at_mesh = s1.depth_at_mesh;
        seg.depth_set = s1.depth_set;
    }
    return seg;
}

// After a bounce: the next ray is the last one (emission only) past max_bounces; false when Russian roulette
// ends the path.
bool PathIntegrator::next_vertex(PathState& p) const {
    if (p.bounce >= st_.max_bounces) {
        p.last = true;
    } else {
        ++p.bounce;
        if (p.bounce > 3) {
            // Russian roulette keeps long paths unbiased and cheap.
            const glm::vec3 b = p.beta * p.beta_outer;  // the whole path's throughput
            const float q = std::min(0.95f, std::max(b.x, std::max(b.y, b.z)));
            if (p.rng.next() >= q) return false;
            p.beta /= q;
        }
    }
    return true;
}

// The Gaussians of a segment: their radiance added to the path's (or a display run opened on them), and on the
// camera segment their count and the coverage's first depth and normal. Returns what the radiance behind the segment
// is weighted with here (a display run applies its own T later).
float PathIntegrator::add_gaussians(PathState& p, Segment& seg) const {
    float behind_weight = seg.transmittance;
    // A segment holding LIT or BAKED_SHADOWED Gaussians is combined in linear light: their shaded radiance is
    // linear and is added below at this level, and a bounce off them replaces what lies behind. Its baked
    // Gaussians' display composite D is then taken to linear on its own (L = linear(D) + T L_behind), an
    // approximation only where baked and shaded splats overlap along a ray.
    const bool display_run = p.display && seg.gaussians > 0 && seg.shading.empty();
    if (p.display && seg.gaussians > 0 && !display_run)
        for (int ch = 0; ch < 3; ++ch) seg.radiance[ch] = srgb_to_linear_tabulated(seg.radiance[ch]);
    if (display_run) {
        // Splat radiance is baked reflected light: seen from the last vertex it would be one bounce too many
        // (the ray still takes their transmittance).
        p.runs.push_back({p.radiance, p.beta, p.last ? glm::vec3(0.0f) : seg.radiance, seg.transmittance, p.light,
                          p.scatters});
        p.camera_run = p.camera_run || p.first_trace;
        p.radiance = glm::vec3(0.0f);
        if (st_.light_passes) p.light = {};
        p.beta_outer *= p.beta;
        p.beta = glm::vec3(1.0f);
        behind_weight = 1.0f;
    } else if (!p.last) {
        p.radiance += p.beta * seg.radiance;
        if (st_.light_passes) add_emitted(p, p.beta * seg.radiance, p.scatters);
    }
    p.first_trace = false;
    if (p.camera_segment) {
        p.camera_gaussians += seg.gaussians;
        p.mist_clearance += p.camera_transmittance * seg.mist_clearance;
        p.guide_albedo += p.camera_transmittance * seg.guide_albedo;
        p.guide_normal += p.camera_transmittance * seg.guide_normal;
        if (cryptomatte_) p.cryptomatte.add_scaled(seg.cryptomatte, p.camera_transmittance);
        p.holdout += p.camera_transmittance * seg.holdout;
        if (p.depth == kInf && seg.depth < kInf) {
            p.depth = seg.depth;
            p.normal = seg.normal;
            p.normal_at_mesh = seg.depth_at_mesh;
            p.position = p.ray.o + seg.depth * p.ray.d;
            if (seg.depth_set) {
                p.depth_motion = &seg.depth_set->frame_motion;
                p.depth_deformed = false;
                p.object_index = float(seg.depth_set->object_pass_index);
                p.material_index = float(seg.depth_set->material_pass_index);
            }
        }
    }
    return behind_weight;
}

// LIT and BAKED_SHADOWED Gaussians (gaussian_shading.h): next-event estimation at the segment's shading point, and a
// diffuse bounce off it. Where a mesh lies behind semi-transparent Gaussians the path goes on either way: it bounces
// with probability p = a / (a + T) (a: the largest channel of the composited albedo) and the chosen branch's weight
// is divided by its probability.
PathIntegrator::GaussianBounce PathIntegrator::shade_gaussians(PathState& p, const Segment& seg, Counters& c) const {
    GaussianBounce bounce;
    if (p.last || seg.shading.empty()) return bounce;
    const GaussianShadingPoint& sp = seg.shading;
    float p_bounce = 0.0f;
    if (sp.lit()) {
        const float a = std::max(sp.albedo_sum.x, std::max(sp.albedo_sum.y, sp.albedo_sum.z));
        p_bounce = seg.mesh && !seg.terminated ? a / (a + seg.transmittance) : 1.0f;
    }
    const glm::vec3 shaded = tracer_.shader().direct(sp, p_bounce, p.rng, c);
    p.radiance += p.beta * shaded;
    if (st_.light_passes) {
        // Both kinds are diffuse-like: a LIT Gaussian is Lambertian (albedo its delit colour), a BAKED_SHADOWED one
        // shows its colour times the lights' visibility (Diffuse Direct is then that visibility).
        if (p.scatters == 0) add_colors(p, sp.albedo_sum + sp.shadowed_sum, glm::vec3(0.0f), glm::vec3(0.0f));
        add_scattered(p, p.beta * shaded, glm::vec3(1.0f), glm::vec3(0.0f));
    }
    if (p_bounce > 0.0f) {
        if (p_bounce >= 1.0f || p.rng.next() < p_bounce) {
            bounce.taken = true;
            bounce.ray = tracer_.shader().bounce_ray(sp, p.rng, bounce.pdf);
            bounce.pdf *= p_bounce;
            bounce.beta = p.beta * sp.albedo_sum / p_bounce;
        } else {
            p.beta /= 1.0f - p_bounce;
        }
    }
    return bounce;
}

// Where the segment ends other than on a mesh the path shades: it stopped in the Gaussians (opaque), or escaped to
// the world. Returns whether the path ends there (it goes on when it bounces off the segment's Gaussians).
bool PathIntegrator::end_segment(PathState& p, const Segment& seg, float behind_weight, bool gaussian_bounce,
                                 Counters& c) const {
    if (seg.terminated) {
        if (p.camera_segment) p.alpha = 1.0f;
        return !gaussian_bounce;
    }
    if (!seg.mesh) {
        if (p.camera_segment) {
            p.alpha = 1.0f - (1.0f - p.alpha) * seg.transmittance;
            // The Environment pass: the world the camera ray reaches, times its transmittance (Cycles writes the
            // background times the path's throughput, with or without a transparent film).
            p.environment += (p.camera_transmittance * seg.transmittance) * world_;
            if (!st_.transparent_background) {
                p.radiance += p.beta * behind_weight * world_;
                // The world's colour joins the denoising albedo of an escaping camera ray, as in Cycles
                // (path_radiance_accum_background adds the background's value to it).
                if (st_.denoising_data)
                    p.guide_albedo += p.camera_transmittance * seg.transmittance *
                                      glm::clamp(world_, glm::vec3(0.0f), glm::vec3(1.0f));
            }
        } else {
            p.radiance += p.beta * behind_weight * world_;
            if (st_.light_passes) add_emitted(p, p.beta * behind_weight * world_, p.scatters, true);
        }
        return !gaussian_bounce;
    }
    if (gaussian_bounce && p.camera_segment) {
        p.alpha = 1.0f;  // the mesh behind covers the pixel
        const MeshDesc& mesh = s_.meshes[s_.top[seg.top_geom].index]->desc;
        if (mesh.holdout) p.holdout += p.camera_transmittance * seg.transmittance;
        // What a held-out mesh or a shadow catcher gives the pixel's alpha and the Shadow Catcher pass does not
        // depend on the branch the path takes, so this branch adds it as mesh_hit does in the other; a catcher's world
        // colour is radiance, which only the other branch adds (weighted by its probability).
        if (mesh.shadow_catcher) catch_shadows(p, seg, surface(seg, p.ray), false, c);
        add_mesh_mist(p, seg);
        if (st_.denoising_data || p.normal_at_mesh || cryptomatte_) {
            const Surface sf = surface(seg, p.ray);
            const bool entering = glm::dot(sf.ng, p.ray.d) < 0.0f;
            if (st_.denoising_data) add_mesh_guides(p, seg, sf, entering);
            if (cryptomatte_) add_mesh_cryptomatte(p, seg, sf);
            if (p.normal_at_mesh) {
                p.normal = entering ? sf.ng : -sf.ng;
                mesh_data_passes(p, seg, sf);
            }
        }
    }
    return false;
}

// The camera segment's mesh hit `seg` joins the Mist pass's sum (when the render has it) with the transmittance in
// front of it (the path stops on it: its alpha is 1 in the sum, as Cycles' is for an opaque surface).
void PathIntegrator::add_mesh_mist(PathState& p, const Segment& seg) const {
    if (!st_.mist_pass) return;
    p.mist_clearance += p.camera_transmittance * seg.transmittance *
                        mist_clearance(s_.world, p.ray.camera_distance + seg.t);
}

// The camera segment's mesh hit `seg` (surface `sf`) joins the Cryptomatte passes' coverage with the same weight as
// mist: its object's, its face's material's and its asset's ids.
void PathIntegrator::add_mesh_cryptomatte(PathState& p, const Segment& seg, const Surface& sf) const {
    const MeshRecord& mesh = *s_.meshes[s_.top[seg.top_geom].index];
    const float material = s_.materials.empty() ? 0.0f : s_.materials[sf.material].cryptomatte_id;
    p.cryptomatte.add({mesh.cryptomatte_object, material, mesh.cryptomatte_asset},
                      p.camera_transmittance * seg.transmittance);
}

// The camera segment's mesh hit `seg` (surface `sf`) joins the denoiser's guides with the transmittance in front of
// it: its material's base colour (the diffuse albedo; a metal's or glass's base colour too, as their tint) and its
// shading normal facing the ray.
void PathIntegrator::add_mesh_guides(PathState& p, const Segment& seg, const Surface& sf, bool entering) const {
    const Material& mat = s_.materials.empty() ? default_material_ : s_.materials[sf.material];
    const float weight = p.camera_transmittance * seg.transmittance;
    p.guide_albedo += weight * glm::clamp(material_base_color(mat, sf.uv), glm::vec3(0.0f), glm::vec3(1.0f));
    p.guide_normal += weight * (entering ? sf.ns : -sf.ns);
}

// The data passes of the camera segment's mesh hit `seg` (surface `sf`) at the depth: its point, its object's pass
// index and its face's material's.
void PathIntegrator::mesh_data_passes(PathState& p, const Segment& seg, const Surface& sf) const {
    p.position = sf.p;
    const MeshRecord& mesh = *s_.meshes[s_.top[seg.top_geom].index];
    p.object_index = float(mesh.desc.pass_index);
    p.depth_motion = &mesh.frame_motion;
    p.depth_deformed = !mesh.frame_previous.empty();
    if (p.depth_deformed) {
        // The point of the same triangle and barycentric coordinates at each frame, placed by that frame's matrix
        // (M_frame = to_frame M, FrameMotion).
        const std::uint32_t* idx = mesh.desc.indices + 3 * std::size_t(seg.prim);
        const float b[3] = {1.0f - seg.u - seg.v, seg.u, seg.v};
        auto at_frame = [&](const std::vector<float>& vertices, const glm::mat4& to_frame) {
            glm::vec3 local(0.0f);
            for (int k = 0; k < 3; ++k)
                local += b[k] * glm::vec3(vertices[3 * idx[k]], vertices[3 * idx[k] + 1], vertices[3 * idx[k] + 2]);
            return glm::vec3(to_frame * glm::vec4(mesh.linear * local + mesh.translation, 1.0f));
        };
        const bool moves = mesh.frame_motion.set;
        p.depth_previous = at_frame(mesh.frame_previous, moves ? mesh.frame_motion.to_previous : glm::mat4(1.0f));
        p.depth_next = at_frame(mesh.frame_next, moves ? mesh.frame_motion.to_next : glm::mat4(1.0f));
    }
    p.material_index = s_.materials.empty() ? 0.0f : float(s_.materials[sf.material].pass_index);
    p.normal_at_mesh = false;
}

// The path's next ray from a bounce off Gaussians; false when Russian roulette ends the path.
bool PathIntegrator::bounce_off_gaussians(PathState& p, const GaussianBounce& bounce) const {
    p.camera_segment = false;
    p.beta = bounce.beta;
    p.after_diffuse = true;
    if (p.scatters++ == 0) p.diffuse_share = glm::vec3(1.0f), p.glossy_share = glm::vec3(0.0f);
    p.mis_pdf = bounce.pdf;
    if (!next_vertex(p)) return false;
    p.ray = bounce.ray;
    return true;
}

// The mesh hit a segment ends on: stochastic coverage (the ray goes on straight through), else the camera segment's
// coverage, depth and normal, then shade_hit. Returns whether the path goes on.
bool PathIntegrator::mesh_hit(PathState& p, const Segment& seg, Counters& c) const {
    const Surface sf = surface(seg, p.ray);
    const Material& mat = s_.materials.empty() ? default_material_ : s_.materials[sf.material];
    const bool entering = glm::dot(sf.ng, p.ray.d) < 0.0f;
    const glm::vec3 ng = entering ? sf.ng : -sf.ng;  // facing the incoming ray
    if (p.normal_at_mesh) {
        p.normal = ng;
        mesh_data_passes(p, seg, sf);
    }
    const float eps = offset_epsilon(sf.p);
    if (mat.alpha < 1.0f && p.rng.next() >= mat.alpha && ++p.passes < 256) {
        // Stochastic coverage: continue straight through.
        float camera_distance = -1.0f;
        if (p.camera_segment) {
            p.alpha = 1.0f - (1.0f - p.alpha) * seg.transmittance;
            p.camera_transmittance *= seg.transmittance;
            camera_distance = p.ray.camera_distance + seg.t;
        }
        p.ray = Ray{sf.p - ng * eps, p.ray.d, 0.0f, kInf, camera_distance, p.ray.time};
        return true;
    }
    if (p.camera_segment) {
        p.alpha = 1.0f;
        add_mesh_mist(p, seg);
        if (st_.denoising_data) add_mesh_guides(p, seg, sf, entering);
        if (cryptomatte_) add_mesh_cryptomatte(p, seg, sf);
        if (p.depth == kInf) {
            p.depth = seg.t;
            p.normal = ng;
            mesh_data_passes(p, seg, sf);
        }
        p.camera_segment = false;
        const MeshDesc& mesh = s_.meshes[s_.top[seg.top_geom].index]->desc;
        if (mesh.holdout) {
            // Cycles (shade_surface.h, integrate_surface_holdout): a held-out surface seen by the camera ray adds
            // the path's throughput to the pixel's transparency and, held out entirely, ends the path: no colour.
            p.holdout += p.camera_transmittance * seg.transmittance;
            return false;
        }
        if (mesh.shadow_catcher) {
            catch_shadows(p, seg, sf, true, c);
            return false;
        }
    }
    return shade_hit(p, sf, mat, entering, ng, eps, c);
}

// The camera segment's shadow catcher `seg` (surface `sf`; MeshDesc::shadow_catcher): the ratio r of the lights'
// direct light at the point with their visibility (meshes and Gaussians) to that without, per channel, 1 where none
// reaches it (Cycles' safe_divide_shadow_catcher); then, with T the transmittance in front and m = mean(r): the
// Shadow Catcher pass 1 - T (1 - r), the ratio alpha-overed on white; and Combined as Cycles' (kernel/film/read.h):
// with the pass written, the catcher held out (transparent, the shadow being the pass's), else its approximate shadow
// catcher (film_calculate_shadow_catcher_matte_with_shadow): alpha T (1 - m) and no colour with a transparent
// background, else (`add_world`) the world's colour times T m.
void PathIntegrator::catch_shadows(PathState& p, const Segment& seg, const Surface& sf, bool add_world,
                                   Counters& c) const {
    const Material& mat = s_.materials.empty() ? default_material_ : s_.materials[sf.material];
    const bool entering = glm::dot(sf.ng, p.ray.d) < 0.0f;
    const glm::vec3 ng = entering ? sf.ng : -sf.ng;
    glm::vec3 ns = entering ? sf.ns : -sf.ns;
    const glm::vec3 wo = -p.ray.d;
    if (glm::dot(ns, wo) <= 0.0f) ns = ng;
    const Bsdf bsdf(mat, material_base_color(mat, sf.uv), ns, wo, entering, LobeFilter{});
    const glm::vec3 p_out = sf.p + ng * offset_epsilon(sf.p);
    glm::vec3 shadowed(0.0f), unshadowed(0.0f);
    for (const Light& l : s_.lights) {
        LightSample ls;
        if (!sample_light(l, p_out, p.rng, ls) || glm::dot(ls.wi, ng) <= 0.0f) continue;
        float pdf;
        const glm::vec3 light = bsdf.eval(wo, ls.wi, pdf) * std::max(glm::dot(ns, ls.wi), 0.0f) * ls.value;
        if (!(light.x > 0.0f || light.y > 0.0f || light.z > 0.0f)) continue;
        unshadowed += light;
        shadowed += light * shadow_.shadow(p_out, ls.wi, ls.distance, p.ray.time, false, c);
    }
    glm::vec3 ratio(1.0f);
    for (int k = 0; k < 3; ++k)
        if (unshadowed[k] > 0.0f) ratio[k] = shadowed[k] / unshadowed[k];
    const float t = p.camera_transmittance * seg.transmittance;
    const float lit = (ratio.x + ratio.y + ratio.z) / 3.0f;
    p.shadow_catcher = glm::vec3(1.0f) - t * (glm::vec3(1.0f) - ratio);
    if (st_.shadow_catcher_pass) p.holdout += t;
    else if (st_.transparent_background) p.holdout += t * lit;
    else if (add_world) p.radiance += p.beta * world_ * lit;
}

// Shading at a mesh hit: its emission, next-event estimation with the lights, then the next bounce. Returns whether
// the path goes on.
bool PathIntegrator::shade_hit(PathState& p, const Surface& sf, const Material& mat, bool entering,
                               const glm::vec3& ng, float eps, Counters& c) const {
    p.radiance += p.beta * glm::vec3(mat.emission_color[0], mat.emission_color[1], mat.emission_color[2]) *
                  mat.emission_strength;
    if (st_.light_passes)
        add_emitted(p, p.beta * glm::vec3(mat.emission_color[0], mat.emission_color[1], mat.emission_color[2]) *
                           mat.emission_strength, p.scatters);
    if (p.last) return false;
    glm::vec3 ns = entering ? sf.ns : -sf.ns;
    const glm::vec3 wo = -p.ray.d;
    if (glm::dot(ns, wo) <= 0.0f) ns = ng;
    LobeFilter filter;
    if (p.after_diffuse) {
        filter.reflective = st_.caustics_reflective;
        filter.refractive = st_.caustics_refractive;
    }
    const Bsdf bsdf(mat, material_base_color(mat, sf.uv), ns, wo, entering, filter);
    if (st_.light_passes && p.scatters == 0) {
        const LobeColors lobes = bsdf.colors(wo);
        add_colors(p, lobes.diffuse, lobes.glossy, lobes.transmission);
    }
    if (bsdf.absorbs()) return false;
    if (bsdf.has_non_delta()) add_direct_lighting(p, bsdf, sf.p + ng * eps, ng, ns, wo, c);
    return next_bounce(p, bsdf, sf.p, ng, wo, eps);
}

// Next-event estimation at `p_out` (the hit, offset along ng): one sample of every light, each weighted against
// BSDF sampling when rays can hit it.
void PathIntegrator::add_direct_lighting(PathState& p, const Bsdf& bsdf, const glm::vec3& p_out, const glm::vec3& ng,
                                         const glm::vec3& ns, const glm::vec3& wo, Counters& c) const {
    for (const Light& l : s_.lights) {
        LightSample ls;
        if (!sample_light(l, p_out, p.rng, ls)) continue;
        if (glm::dot(ls.wi, ng) <= 0.0f) continue;
        float pdf;
        glm::vec3 f_diffuse;
        const glm::vec3 f = bsdf.eval(wo, ls.wi, pdf, st_.light_passes ? &f_diffuse : nullptr);
        const float cos_i = glm::dot(ns, ls.wi);
        if (cos_i <= 0.0f || (f.x <= 0.0f && f.y <= 0.0f && f.z <= 0.0f)) continue;
        const float vis = shadow_.shadow(p_out, ls.wi, ls.distance, p.ray.time, false, c);
        // Lights that rays can hit share the estimate with BSDF sampling (power heuristic).
        const float w = ls.pdf > 0.0f ? power_heuristic(ls.pdf, pdf) : 1.0f;
        if (vis > 0.0f) p.radiance += p.beta * f * cos_i * ls.value * (vis * w);
        if (vis > 0.0f && st_.light_passes)
            add_scattered(p, p.beta * f * cos_i * ls.value * (vis * w), share(f_diffuse, f), share(f - f_diffuse, f));
    }
}

// The next bounce from the mesh hit at `hit_p`: a BSDF sample, then Russian roulette (next_vertex). Returns whether
// the path goes on.
bool PathIntegrator::next_bounce(PathState& p, const Bsdf& bsdf, const glm::vec3& hit_p, const glm::vec3& ng,
                                 const glm::vec3& wo, float eps) const {
    BsdfSample bs;
    if (!bsdf.sample(wo, p.rng, bs)) return false;
    p.beta *= bs.weight;
    if (!(p.beta.x > 0.0f || p.beta.y > 0.0f || p.beta.z > 0.0f)) return false;
    p.after_diffuse = bs.diffuse;
    p.mis_pdf = bs.delta ? 0.0f : bs.pdf;
    if (p.scatters++ == 0) {
        // The lobes that carry the path on (Cycles' pass weights at bounce 0): a delta sample is the glass' refraction
        // (transmission) or a mirror-like reflection (glossy); a non-delta one splits as its evaluation does.
        p.diffuse_share = bs.delta ? glm::vec3(0.0f) : share(bs.f_diffuse, bs.f);
        p.glossy_share = bs.delta ? glm::vec3(bs.transmitted ? 0.0f : 1.0f) : share(bs.f - bs.f_diffuse, bs.f);
    }
    if (!next_vertex(p)) return false;
    const bool below = glm::dot(bs.wi, ng) < 0.0f;
    p.ray = Ray{hit_p + (below ? -ng : ng) * eps, bs.wi, 0.0f, kInf, -1.0f, p.ray.time};
    return true;
}

// The film's sample from a finished path. Its display runs close innermost first: L = linear(D + T display(L_behind));
// the camera run goes to the film as its parts (see SampleRecord), and a path without one is all behind (D = 0,
// T = 1).
SampleRecord PathIntegrator::sample_record(PathState& p) const {
    const std::size_t kept = p.camera_run ? 1 : 0;
    while (p.runs.size() > kept) {
        const DisplayRun& r = p.runs.back();
        glm::vec3 l;
        for (int ch = 0; ch < 3; ++ch)
            l[ch] = srgb_to_linear_tabulated(r.display[ch] + r.transmittance * linear_to_srgb(p.radiance[ch]));
        if (st_.light_passes) close_run_light(p, r, l);
        p.radiance = r.outer_radiance + r.outer_beta * l;
        p.runs.pop_back();
    }
    SampleRecord record;
    if (p.display) {
        glm::vec3 front(0.0f), d(0.0f), behind = p.radiance;
        float t = 1.0f;
        if (p.camera_run) {
            front = p.runs[0].outer_radiance;
            d = p.runs[0].display;
            t = p.runs[0].transmittance;
            behind = t * p.radiance;
        }
        p.radiance = front;
        record.display_radiance = {d.x, d.y, d.z};
        record.display_transmittance = t;
        record.behind_radiance = {behind.x, behind.y, behind.z};
        record.display_blend = true;
        if (st_.light_passes && p.camera_run) {
            // The passes behind the camera run, as `behind`; what lies in front of it is emission (area lights).
            const std::array<glm::vec3, kLightPassCount>& front_light = p.runs[0].outer_light;
            for (std::size_t k = 0; k < kLightPassCount; ++k) p.light[k] = front_light[k] + t * p.light[k];
            const glm::vec3& e = front_light[std::size_t(LightPass::Emission)];
            record.front_emission = {e.x, e.y, e.z};
        }
    }
    if (st_.light_passes) {
        record.light_passes = true;
        p.light[std::size_t(LightPass::DiffuseColor)] = p.colors[0];
        p.light[std::size_t(LightPass::GlossyColor)] = p.colors[1];
        p.light[std::size_t(LightPass::TransmissionColor)] = p.colors[2];
        for (std::size_t k = 0; k < kLightPassCount; ++k) record.light[k] = {p.light[k].x, p.light[k].y, p.light[k].z};
    }
    record.radiance = {p.radiance.x, p.radiance.y, p.radiance.z};
    record.alpha = p.alpha;
    record.depth = p.depth;
    record.normal = {p.normal.x, p.normal.y, p.normal.z};
    record.position = {p.position.x, p.position.y, p.position.z};
    record.object_index = p.object_index;
    record.material_index = p.material_index;
    if (p.depth < kInf && vectors_.active())
        record.vector = p.depth_deformed ? vectors_.vector_between(p.position, p.depth_previous, p.depth_next)
                                         : vectors_.vector(p.position, p.depth_motion);
    record.mist = 1.0f - p.mist_clearance;
    record.denoising_albedo = {p.guide_albedo.x, p.guide_albedo.y, p.guide_albedo.z};
    record.denoising_normal = {p.guide_normal.x, p.guide_normal.y, p.guide_normal.z};
    record.gaussian_count = float(p.camera_gaussians);
    if (cryptomatte_) record.cryptomatte = p.cryptomatte;
    record.holdout = p.holdout;
    record.environment = {p.environment.x, p.environment.y, p.environment.z};
    record.shadow_catcher = {p.shadow_catcher.x, p.shadow_catcher.y, p.shadow_catcher.z};
    return record;
}

// Light emitted towards a path vertex after `level` scatterings (a mesh's emission, an area light, the world, BAKED
// Gaussians' radiance; Cycles, kernel/film/light_passes.h, film_write_emission_or_background_pass): seen before any
// scattering it is Emission (the world: Cycles' Environment, none of these passes); one scattering later Direct,
// later Indirect, each in the first scattering's lobe shares.
void PathIntegrator::add_emitted(PathState& p, const glm::vec3& light, int level, bool world) const {
    if (level == 0) {
        if (!world) p.light[std::size_t(LightPass::Emission)] += light;
        return;
    }
    add_to_lobes(p.light, light, level == 1, p.diffuse_share, p.glossy_share);
}

// Light scattered towards the camera at the path's current vertex by next-event estimation or the shading of LIT and
// BAKED_SHADOWED Gaussians (Cycles' film_write_direct_light): at the first scattering surface Direct light in the
// shares of that evaluation's lobes, later Indirect in the first scattering's shares.
void PathIntegrator::add_scattered(PathState& p, const glm::vec3& light, const glm::vec3& diffuse_share,
                                   const glm::vec3& glossy_share) const {
    if (p.scatters == 0)
        add_to_lobes(p.light, light, true, diffuse_share, glossy_share);
    else
        add_to_lobes(p.light, light, false, p.diffuse_share, p.glossy_share);
}

// The lobes' albedos of a surface the camera sees (before the first scattering), weighted by the throughput to it
// (Cycles' film_write_data_passes): in display blend space the open runs' transmittances included, linearly.
void PathIntegrator::add_colors(PathState& p, const glm::vec3& diffuse, const glm::vec3& glossy,
                                const glm::vec3& transmission) const {
    glm::vec3 throughput = p.beta * p.beta_outer;
    for (const DisplayRun& r : p.runs) throughput *= r.transmittance;
    p.colors[0] += throughput * diffuse;
    p.colors[1] += throughput * glossy;
    p.colors[2] += throughput * transmission;
}

// A display run closes (sample_record): L = linear(D + T display(L_behind)). The light behind keeps its passes,
// attenuated as the display blend attenuates it, linear(T display(L_behind)) = T_eff L_behind (per channel, T_eff <=
// T); the rest, L - T_eff L_behind >= 0, is the run's Gaussians' own light, emitted light seen at the run's level.
void PathIntegrator::close_run_light(PathState& p, const DisplayRun& r, const glm::vec3& l) const {
    glm::vec3 through(0.0f), attenuation(0.0f);
    for (int ch = 0; ch < 3; ++ch) {
        through[ch] = srgb_to_linear_tabulated(r.transmittance * linear_to_srgb(p.radiance[ch]));
        attenuation[ch] = p.radiance[ch] > 0.0f ? through[ch] / p.radiance[ch] : r.transmittance;
    }
    for (std::size_t k = 0; k < kLightPassCount; ++k)
        p.light[k] = r.outer_light[k] + r.outer_beta * attenuation * p.light[k];
    add_emitted(p, r.outer_beta * (l - through), r.level);
}

// Bounces follow Cycles: NEE at the camera hit and after each of max_bounces bounces, and the ray leaving the
// last vertex still collects the emitters it sees (world, area lights, mesh emission) without further shading
// (Cycles' PATH_RAY_TERMINATE_AFTER_TRANSPARENT).
SampleRecord PathIntegrator::path(Ray ray, Sampler& rng, Counters& c, const Segment* first) const {
    thread_local std::vector<DisplayRun> runs;
    runs.clear();
    PathState p(ray, rng, runs, st_.blend_space == BlendSpace::Display);
    for (;;) {
        Segment seg = trace_with_lights(p.ray, first, p.mis_pdf, p.beta, p, rng, c);
        first = nullptr;
        const float behind_weight = add_gaussians(p, seg);
        const GaussianBounce gaussian_bounce = shade_gaussians(p, seg, c);
        if (end_segment(p, seg, behind_weight, gaussian_bounce.taken, c)) break;
        if (gaussian_bounce.taken) {
            if (!bounce_off_gaussians(p, gaussian_bounce)) break;
            continue;
        }
        p.beta *= behind_weight;
        if (!mesh_hit(p, seg, c)) break;
    }
    return sample_record(p);
}

}  // namespace raysplats
