// Render benchmark on a real scene (docs/design.md §8): BVH build, sorted and stochastic frames, rays per second,
// Gaussian hits per ray, the ratio to Embree's plain closest-hit query on the same proxy geometry (the traversal
// floor), and frame time against scene size.
//
//   bench_render [scene.ply] [width height]
//
// The file is read by a small local reader of INRIA binary little-endian PLY with float properties (the splat IO
// library lives on another branch); it reads x y z, rot_0..3, scale_0..2 (log), opacity (logit), f_dc_0..2.
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <map>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include <sys/resource.h>

#include <embree3/rtcore.h>
#include <tbb/parallel_for.h>

#include "raysplats/render/renderer.h"

using namespace raysplats;
using Clock = std::chrono::steady_clock;

namespace {

double seconds_since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

// CPU seconds of the whole process (all threads): robust against other jobs sharing the machine.
double cpu_seconds() {
    rusage u;
    getrusage(RUSAGE_SELF, &u);
    return u.ru_utime.tv_sec + u.ru_stime.tv_sec + 1e-6 * (u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

GaussianCloud read_inria_ply(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    if (!in) throw std::runtime_error("cannot open " + path);
    std::string line;
    std::size_t count = 0;
    std::vector<std::string> props;
    while (std::getline(in, line)) {
        std::istringstream ls(line);
        std::string a, b, c;
        ls >> a >> b >> c;
        if (a == "element" && b == "vertex") count = std::stoull(c);
        if (a == "property") {
            if (b != "float") throw std::runtime_error("bench reader handles float properties only");
            props.push_back(c);
        }
        if (a == "end_header") break;
    }
    std::map<std::string, int> col;
    for (std::size_t i = 0; i < props.size(); ++i) col[props[i]] = int(i);
    for (const char* need : {"x", "y", "z", "rot_0", "rot_1", "rot_2", "rot_3", "scale_0", "scale_1", "scale_2",
                             "opacity", "f_dc_0", "f_dc_1", "f_dc_2"})
        if (!col.count(need)) throw std::runtime_error(std::string("missing property ") + need);
    std::vector<float> data(count * props.size());
    in.read(reinterpret_cast<char*>(data.data()), std::streamsize(data.size() * sizeof(float)));
    if (!in) throw std::runtime_error("file is truncated");
    GaussianCloud c;
    c.resize(count, 0);
    const std::size_t stride = props.size();
    int ix[3], is[3], ic[3], ir[4];
    for (int k = 0; k < 3; ++k) {
        ix[k] = col[std::string(1, char('x' + k))];
        is[k] = col["scale_" + std::to_string(k)];
        ic[k] = col["f_dc_" + std::to_string(k)];
    }
    for (int k = 0; k < 4; ++k) ir[k] = col["rot_" + std::to_string(k)];
    const int io = col["opacity"];
    tbb::parallel_for(std::size_t(0), count, [&](std::size_t i) {
        const float* r = &data[i * stride];
        for (int k = 0; k < 3; ++k) {
            c.positions[3 * i + k] = r[ix[k]];
            c.scales[3 * i + k] = std::exp(r[is[k]]);
            c.sh[3 * i + k] = r[ic[k]];
        }
        float q[4], n = 0;
        for (int k = 0; k < 4; ++k) {
            q[k] = r[ir[k]];
            n += q[k] * q[k];
        }
        n = std::sqrt(n);
        for (int k = 0; k < 4; ++k) c.rotations[4 * i + k] = n > 0 ? q[k] / n : (k == 0 ? 1.0f : 0.0f);
        c.opacities[i] = 1.0f / (1.0f + std::exp(-r[io]));
    });
    return c;
}

GaussianCloud subset(const GaussianCloud& c, std::size_t m) {
    if (m >= c.size()) return c;
    GaussianCloud s;
    s.resize(m, c.sh_degree);
    const int k = c.coeffs_per_channel() * 3;
    for (std::size_t j = 0; j < m; ++j) {
        const std::size_t i = j * c.size() / m;  // spread over the whole scene
        std::copy_n(&c.positions[3 * i], 3, &s.positions[3 * j]);
        std::copy_n(&c.rotations[4 * i], 4, &s.rotations[4 * j]);
        std::copy_n(&c.scales[3 * i], 3, &s.scales[3 * j]);
        s.opacities[j] = c.opacities[i];
        std::copy_n(&c.sh[i * k], k, &s.sh[j * k]);
    }
    return s;
}

// Embree's plain closest hit on the flat proxies (one quad over each Gaussian's 3-sigma disk, as two triangles),
// for the same camera rays: the floor under any traversal of this geometry.
double embree_floor_seconds(const GaussianCloud& c, const Camera& cam, int w, int h, double& build_seconds,
                            double& cpu) {
    const std::string config = default_embree_config();  // the same device as the renderer's
    RTCDevice dev = rtcNewDevice(config.empty() ? nullptr : config.c_str());
    if (!dev) throw std::runtime_error("Embree refuses the device configuration \"" + config + "\"");
    RTCScene scene = rtcNewScene(dev);
    RTCGeometry geom = rtcNewGeometry(dev, RTC_GEOMETRY_TYPE_TRIANGLE);
    const std::size_t n = c.size();
    float* v = static_cast<float*>(rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                                           3 * sizeof(float), 4 * n));
    unsigned* idx = static_cast<unsigned*>(rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                                                   3 * sizeof(unsigned), 2 * n));
    tbb::parallel_for(std::size_t(0), n, [&](std::size_t i) {
        const float w_ = c.rotations[4 * i], x = c.rotations[4 * i + 1], y = c.rotations[4 * i + 2], z = c.rotations[4 * i + 3];
        const float ax[3][3] = {{1 - 2 * (y * y + z * z), 2 * (x * y + w_ * z), 2 * (x * z - w_ * y)},
                                {2 * (x * y - w_ * z), 1 - 2 * (x * x + z * z), 2 * (y * z + w_ * x)},
                                {2 * (x * z + w_ * y), 2 * (y * z - w_ * x), 1 - 2 * (x * x + y * y)}};
        const float* s = &c.scales[3 * i];
        int o[3] = {0, 1, 2};
        std::sort(o, o + 3, [&](int a, int b) { return s[a] > s[b]; });
        for (int k = 0; k < 4; ++k) {
            const float su = (k == 0 || k == 3) ? -3.0f : 3.0f, sv = k < 2 ? -3.0f : 3.0f;
            for (int d = 0; d < 3; ++d)
                v[3 * (4 * i + k) + d] = c.positions[3 * i + d] + su * s[o[0]] * ax[o[0]][d] + sv * s[o[1]] * ax[o[1]][d];
        }
        const unsigned b = unsigned(4 * i);
        const unsigned t[6] = {b, b + 1, b + 2, b, b + 2, b + 3};
        std::copy_n(t, 6, &idx[6 * i]);
    });
    rtcCommitGeometry(geom);
    rtcAttachGeometry(scene, geom);
    rtcReleaseGeometry(geom);
    auto t0 = Clock::now();
    rtcCommitScene(scene);
    build_seconds = seconds_since(t0);
    t0 = Clock::now();
    const double cpu0 = cpu_seconds();
    tbb::parallel_for(tbb::blocked_range<int>(0, h, 4), [&](const tbb::blocked_range<int>& r) {
        RTCIntersectContext ctx;
        rtcInitIntersectContext(&ctx);
        for (int y = r.begin(); y != r.end(); ++y)
            for (int x = 0; x < w; ++x) {
                const CameraRay cr = generate_camera_ray(cam, w, h, x + 0.5f, y + 0.5f);
                RTCRayHit rh;
                rh.ray.org_x = cr.origin[0];
                rh.ray.org_y = cr.origin[1];
                rh.ray.org_z = cr.origin[2];
                rh.ray.dir_x = cr.direction[0];
                rh.ray.dir_y = cr.direction[1];
                rh.ray.dir_z = cr.direction[2];
                rh.ray.tnear = cr.t_min;
                rh.ray.tfar = cr.t_max;
                rh.ray.mask = ~0u;
                rh.ray.flags = 0;
                rh.ray.time = 0;
                rh.ray.id = 0;
                rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
                rtcIntersect1(scene, &ctx, &rh);
            }
    });
    const double s = seconds_since(t0);
    cpu = cpu_seconds() - cpu0;
    rtcReleaseScene(scene);
    rtcReleaseDevice(dev);
    return s;
}

}  // namespace

int main(int argc, char** argv) {
    const std::string path = argc > 1 ? argv[1] : std::string(RAYSPLATS_DATA_DIR) + "/showroom_1.5M.ply";
    const int width = argc > 3 ? std::atoi(argv[2]) : 1920, height = argc > 3 ? std::atoi(argv[3]) : 1080;
    try {
        auto t0 = Clock::now();
        const GaussianCloud cloud = read_inria_ply(path);
        std::printf("scene           %s: %zu splats (read in %.2f s, bench-local reader)\n", path.c_str(), cloud.size(),
                    seconds_since(t0));

        // Camera at the median of the centres, 60 degree horizontal field of view, looking along +Z with -Y up
        // (COLMAP convention of the scene).
        std::array<float, 3> median;
        for (int k = 0; k < 3; ++k) {
            std::vector<float> v(cloud.size());
            for (std::size_t i = 0; i < cloud.size(); ++i) v[i] = cloud.positions[3 * i + k];
            std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
            median[k] = v[v.size() / 2];
        }
        Camera cam;
        cam.sensor_width_mm = 36.0f;
        cam.focal_length_mm = 18.0f / std::tan(30.0f * 3.14159265f / 180.0f);
        cam.clip_start = 0.01f;
        // Looks along +X by default: along +Z the median sits inside a few large splats that fill the view
        // (about 5 Gaussians per ray), along +X it sees the room (about 34). RAYSPLATS_BENCH_AXIS=z for the other.
        const char* axis_env = std::getenv("RAYSPLATS_BENCH_AXIS");
        const bool along_x = !(axis_env && std::string(axis_env) == "z");
        const std::array<float, 3> target = along_x ? std::array<float, 3>{median[0] + 1, median[1], median[2]}
                                                    : std::array<float, 3>{median[0], median[1], median[2] + 1};
        cam.camera_to_world = Matrix4::look_at(median, target, {0, -1, 0});
        std::printf("camera          at median (%.3f %.3f %.3f), looking %s, up -Y, hfov 60 deg, %dx%d\n", median[0],
                    median[1], median[2], along_x ? "+X" : "+Z", width, height);

        RenderSettings st;
        st.width = width;
        st.height = height;
        st.samples = 1;
        st.max_bounces = 0;
        st.jitter = false;
        st.transparent_background = true;
        if (const char* k = std::getenv("RAYSPLATS_BENCH_K")) st.gather_buffer_size = std::atoi(k);
        if (const char* t = std::getenv("RAYSPLATS_BENCH_TILE")) st.tile_size = std::atoi(t);
        // RAYSPLATS_BENCH_BLEND=linear|display: the blend space (default: the settings' default).
        if (const char* b = std::getenv("RAYSPLATS_BENCH_BLEND"))
            st.blend_space = std::string(b) == "linear" ? BlendSpace::Linear : BlendSpace::Display;
        std::printf("blend space     %s\n", st.blend_space == BlendSpace::Linear ? "linear" : "display");
        {
            const EmbreeDeviceInfo dev = Scene().embree_device();
            std::printf("embree device   config \"%s\" (RAYSPLATS_EMBREE_CONFIG), native packets of 16: %s, of 8: %s\n",
                        dev.config.c_str(), dev.native_ray16 ? "yes" : "no", dev.native_ray8 ? "yes" : "no");
        }
        const double rays = double(width) * height;

        auto run = [&](const GaussianCloud& c, Compositing comp, GaussianMode mode, double& build, bool print) {
            Scene scene;
            scene.add_gaussians(c);
            build = scene.build(mode);
            st.compositing = comp;
            st.gaussian_mode = mode;
            render(scene, cam, st);  // warm-up (page faults, TBB threads)
            const double cpu0 = cpu_seconds();
            const Film f = render(scene, cam, st);
            const double cpu = cpu_seconds() - cpu0;
            const double s = f.stats.render_seconds;
            if (print)
                std::printf("%-10s %-10s  build %.3f s | frame %.3f s | %.2f Mrays/s | %.1f Gaussian hits/ray | "
                            "%.2f traversals/ray | %.0f candidates/ray (%.0f groups) | %.2f us CPU/ray\n",
                            comp == Compositing::Sorted ? "sorted" : "stochastic",
                            mode == GaussianMode::Flat ? "flat" : "volumetric", build, s, rays / s / 1e6,
                            double(f.stats.gaussian_hits) / rays, double(f.stats.traced_rays) / rays,
                            double(f.stats.gaussian_candidates) / rays, double(f.stats.gaussian_group_candidates) / rays,
                            cpu / rays * 1e6);
            return s;
        };

        if (const char* only = std::getenv("RAYSPLATS_BENCH_ONLY")) {
            // One configuration, for profilers: sorted | stochastic (flat mode).
            double bb;
            run(cloud, std::string(only) == "stochastic" ? Compositing::Stochastic : Compositing::Sorted,
                GaussianMode::Flat, bb, true);
            return 0;
        }
        double build_flat, build_vol, b;
        if (const char* out = std::getenv("RAYSPLATS_BENCH_IMAGE")) {
            // Writes the sorted frame for a look at what the benchmark sees.
            Scene scene;
            scene.add_gaussians(cloud);
            render(scene, cam, st).write_png(out);
        }
        const double sorted_flat = run(cloud, Compositing::Sorted, GaussianMode::Flat, build_flat, true);
        const double stoch_flat = run(cloud, Compositing::Stochastic, GaussianMode::Flat, b, true);
        const double sorted_vol = run(cloud, Compositing::Sorted, GaussianMode::Volumetric, build_vol, true);
        const double stoch_vol = run(cloud, Compositing::Stochastic, GaussianMode::Volumetric, b, true);

        double floor_build, floor_cpu;
        embree_floor_seconds(cloud, cam, width, height, floor_build, floor_cpu);  // warm-up
        const double floor = embree_floor_seconds(cloud, cam, width, height, floor_build, floor_cpu);
        std::printf("embree floor    closest hit on the quad proxies: build %.3f s, %.3f s/frame, %.2f Mrays/s, "
                    "%.2f us CPU/ray\n",
                    floor_build, floor, rays / floor / 1e6, floor_cpu / rays * 1e6);
        std::printf("ratio to floor  (wall time) sorted flat %.1fx, stochastic flat %.1fx, sorted vol %.1fx, "
                    "stochastic vol %.1fx; compare the CPU us/ray figures when the machine is shared\n",
                    sorted_flat / floor, stoch_flat / floor, sorted_vol / floor, stoch_vol / floor);
        std::printf("targets         build <= 1 s: %.3f s (flat), %.3f s (volumetric); sorted <= 2 s: %.3f s; "
                    "stochastic <= 0.5 s: %.3f s\n",
                    build_flat, build_vol, sorted_flat, stoch_flat);

        std::printf("scaling (flat)  splats     build     sorted    stochastic\n");
        for (std::size_t m : {std::size_t(100000), std::size_t(400000), cloud.size()}) {
            const GaussianCloud c = subset(cloud, m);
            double bb;
            const double s1 = run(c, Compositing::Sorted, GaussianMode::Flat, bb, false);
            const double s2 = run(c, Compositing::Stochastic, GaussianMode::Flat, b, false);
            std::printf("                %8zu   %.3f s   %.3f s    %.3f s\n", c.size(), bb, s1, s2);
        }
    } catch (const std::exception& e) {
        std::fprintf(stderr, "bench_render: %s\n", e.what());
        return 1;
    }
    return 0;
}
