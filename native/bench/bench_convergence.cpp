// Convergence benchmark: samples and time to reach a noise level, with fixed
// samples per pixel and with adaptive sampling, on showroom_1.5M plus a ground plane and a sun, sorted mode.
//
//   bench_convergence [scene.ply] [--width 960 --height 540] [--reference-samples 512] [--max-samples 256]
//                     [--min-samples 16] [--thresholds 0.04,0.02,0.01,0.005] [--image reference.png]
//                     [--view x --up -y --camera-back 0]   (bench_render's camera by default)
//
// Noise metrics (printed with the numbers), of the linear RGB film I against a reference R rendered with another
// seed at --reference-samples, over every pixel and R, G, B:
//   relative RMS  e = sqrt(sum (I - R)^2 / sum R^2)               (the image's noise energy relative to its own)
//   relMSE        e = sqrt(mean (I - R)^2 / (R^2 + 0.01))         (per pixel relative: dark pixels count as much as
//                                                                   bright ones; Rousselle et al. 2011's measure)
// each with the reference's own noise taken out: for fixed samples n, e^2(n) = a / n + b (independent seeds, b the
// reference's share), fitted by least squares over the fixed-sample curve; every e is reported as sqrt(e^2 - b).
// "1 % noise" is e = 0.01 (0.5 % printed too). Times are the renders' wall times (Film::stats.render_seconds) on the machine as it is;
// the fixed-sample times come from one progressive render (the film after each pass).
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <sstream>
#include <string>
#include <vector>

#include "raysplats/render/renderer.h"
#include "raysplats/splat_io.h"

using namespace raysplats;

namespace {

constexpr int kMetrics = 2;
const char* const kMetricNames[kMetrics] = {"relative RMS", "relMSE"};

// Both metrics' squared values (reference noise included).
std::array<double, kMetrics> squared_errors(const Film& image, const Film& reference) {
    double e = 0.0, r = 0.0, rel = 0.0;
    for (std::size_t p = 0; p < image.pixel_count(); ++p)
        for (int c = 0; c < 3; ++c) {
            const double v = image.rgba()[4 * p + c], ref = reference.rgba()[4 * p + c];
            e += (v - ref) * (v - ref);
            r += ref * ref;
            rel += (v - ref) * (v - ref) / (ref * ref + 0.01);
        }
    return {e / r, rel / (3.0 * double(image.pixel_count()))};
}

struct Point {
    double samples;  // mean per pixel
    double seconds;
    std::array<double, kMetrics> e2;
};

// Samples (and seconds) where metric m's noise crosses `target`, interpolated in log-log between the neighbouring
// points.
bool crossing(const std::vector<Point>& points, int m, double b, double target, double& samples, double& seconds) {
    for (std::size_t i = 1; i < points.size(); ++i) {
        const double e0 = std::sqrt(std::max(points[i - 1].e2[m] - b, 1e-30)),
                     e1 = std::sqrt(std::max(points[i].e2[m] - b, 1e-30));
        if (e0 >= target && e1 <= target) {
            const double t = (std::log(e0) - std::log(target)) / (std::log(e0) - std::log(e1));
            samples = std::exp(std::log(points[i - 1].samples) + t * (std::log(points[i].samples) - std::log(points[i - 1].samples)));
            seconds = std::exp(std::log(points[i - 1].seconds) + t * (std::log(points[i].seconds) - std::log(points[i - 1].seconds)));
            return true;
        }
    }
    return false;
}

}  // namespace

int main(int argc, char** argv) {
    std::setvbuf(stdout, nullptr, _IOLBF, 0);  // each line as it comes, also into a file (the runs are long)
    std::string path = std::string(RAYSPLATS_DATA_DIR) + "/showroom_1.5M.ply", image_path;
    int width = 960, height = 540, reference_samples = 512, max_samples = 256, min_samples = 16;
    float camera_back = 0.0f;
    std::string view = "x", up = "-y";
    std::vector<float> thresholds = {0.04f, 0.02f, 0.01f, 0.005f};
    for (int i = 1; i < argc; ++i) {
        const std::string a = argv[i];
        auto next = [&]() -> std::string {
            if (i + 1 >= argc) {
                std::fprintf(stderr, "bench_convergence: %s needs a value\n", a.c_str());
                std::exit(2);
            }
            return argv[++i];
        };
        if (a == "--width") width = std::stoi(next());
        else if (a == "--height") height = std::stoi(next());
        else if (a == "--reference-samples") reference_samples = std::stoi(next());
        else if (a == "--max-samples") max_samples = std::stoi(next());
        else if (a == "--min-samples") min_samples = std::stoi(next());
        else if (a == "--image") image_path = next();
        else if (a == "--camera-back") camera_back = std::stof(next());
        else if (a == "--view") view = next();
        else if (a == "--up") up = next();
        else if (a == "--thresholds") {
            thresholds.clear();
            std::stringstream list(next());
            for (std::string t; std::getline(list, t, ',');) thresholds.push_back(std::stof(t));
        } else path = a;
    }
    try {
        auto t0 = std::chrono::steady_clock::now();
        const GaussianCloud cloud = read_splat_file(path);
        std::printf("scene      %s: %zu splats (read in %.1f s) + ground plane + sun, %dx%d, sorted, flat\n",
                    path.c_str(), cloud.size(),
                    std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), width, height);

        // bench_render's camera: at the median of the centres, 60 degrees horizontal field of view, looking along
        // +X with -Y up (the scene's COLMAP axes).
        float median[3];
        for (int k = 0; k < 3; ++k) {
            std::vector<float> v(cloud.size());
            for (std::size_t i = 0; i < cloud.size(); ++i) v[i] = cloud.positions[3 * i + k];
            std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
            median[k] = v[v.size() / 2];
        }
        Camera camera;
        camera.sensor_width_mm = 36.0f;
        camera.focal_length_mm = 18.0f / std::tan(30.0f * 3.14159265f / 180.0f);
        camera.clip_start = 0.01f;
        auto axis = [](const std::string& name) -> std::array<float, 3> {
            const float sign = name[0] == '-' ? -1.0f : 1.0f;
            const char c = name.back();
            return {c == 'x' ? sign : 0.0f, c == 'y' ? sign : 0.0f, c == 'z' ? sign : 0.0f};
        };
        const std::array<float, 3> forward = axis(view), up_axis = axis(up);
        const std::array<float, 3> eye = {median[0] - camera_back * forward[0], median[1] - camera_back * forward[1],
                                          median[2] - camera_back * forward[2]};
        camera.camera_to_world = Matrix4::look_at(
            eye, {eye[0] + forward[0], eye[1] + forward[1], eye[2] + forward[2]}, up_axis);

        Scene scene;
        scene.add_gaussians(cloud);
        // A grey diffuse ground 2.5 units below the camera (+Y is down), 60 x 60 units, under the room's far half,
        // and a sun from above and behind the camera: Gaussians shadow the ground (shadow rays through their
        // transmittance), the ground reflects light into the next bounce.
        const float ground_y = median[1] + 2.5f, cx = median[0], cz = median[2], half = 30.0f;
        const std::vector<float> vertices = {cx - half, ground_y, cz - half, cx + half, ground_y, cz - half,
                                             cx + half, ground_y, cz + half, cx - half, ground_y, cz + half, 0.0f};
        const std::vector<std::uint32_t> indices = {0, 2, 1, 0, 3, 2};  // normal -Y (up)
        Material grey;
        grey.base_color = {0.5f, 0.5f, 0.5f};
        MeshDesc ground;
        ground.vertices = vertices.data();
        ground.vertex_count = 4;
        ground.vertices_padded = true;
        ground.indices = indices.data();
        ground.triangle_count = 2;
        ground.material = scene.add_material(grey);
        scene.add_mesh(ground);
        Light sun;
        sun.type = LightType::Sun;
        sun.power = 3.0f;
        sun.sun_angle = 0.00918f;  // Blender's default angle (0.526 degrees)
        // The sun shines along its local -Z: from above (-Y) and behind the camera (-X), down at 50 degrees.
        sun.light_to_world = Matrix4::look_at({0, 0, 0}, {std::cos(0.87f), std::sin(0.87f), 0.3f}, {0, -1, 0});
        scene.add_light(sun);
        std::printf("build      %.2f s\n", scene.build(GaussianMode::Flat));

        RenderSettings base;
        base.width = width;
        base.height = height;
        base.compositing = Compositing::Sorted;
        base.pixel_filter = PixelFilter::BlackmanHarris;  // the add-on's default (Cycles')
        base.filter_width = 1.5f;

        RenderSettings reference_settings = base;
        reference_settings.samples = reference_samples;
        reference_settings.seed = 1;
        const Film reference = render(scene, camera, reference_settings);
        std::printf("reference  %d samples, seed 1: %.1f s (%.3f s per sample)\n", reference_samples,
                    reference.stats.render_seconds, reference.stats.render_seconds / reference_samples);
        if (!image_path.empty()) reference.write_png(image_path);
        const double pixels = double(width) * height;
        std::printf("view       %s, up %s, %.1f back from the median of the centres\n", view.c_str(), up.c_str(), camera_back);

        // Fixed samples: one progressive render, the film after each pass compared with the reference (the
        // comparison's time is taken out of the pass times).
        RenderSettings fixed_settings = base;
        fixed_settings.samples = max_samples;
        std::vector<Point> fixed;
        double compare_seconds = 0.0;
        const auto fixed_start = std::chrono::steady_clock::now();
        auto record = [&](const Film& film) {
            const auto c0 = std::chrono::steady_clock::now();
            const double elapsed = std::chrono::duration<double>(c0 - fixed_start).count() - compare_seconds;
            fixed.push_back({double(film.stats.samples), elapsed, squared_errors(film, reference)});
            compare_seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - c0).count();
        };
        record(render(scene, camera, fixed_settings, {}, nullptr, record));
        // Fit e^2(n) = a / n + b over n >= 4 (least squares, linear in 1/n), per metric.
        std::array<double, kMetrics> a{}, b{};
        for (int k = 0; k < kMetrics; ++k) {
            double sx = 0, sy = 0, sxx = 0, sxy = 0, m = 0;
            for (const Point& p : fixed) {
                if (p.samples < 4) continue;
                const double x = 1.0 / p.samples;
                sx += x, sy += p.e2[k], sxx += x * x, sxy += x * p.e2[k], ++m;
            }
            a[k] = (m * sxy - sx * sy) / (m * sxx - sx * sx);
            b[k] = std::max(0.0, (sy - a[k] * sx) / m);
            std::printf("metric     %-12s reference noise %.4f (fitted, taken out), one sample's noise %.4f\n",
                        kMetricNames[k], std::sqrt(b[k]), std::sqrt(std::max(a[k], 0.0)));
        }
        auto noise = [&](const Point& p, int k) { return std::sqrt(std::max(p.e2[k] - b[k], 0.0)); };
        std::printf("fixed      samples   relative RMS   relMSE    seconds\n");
        for (const Point& p : fixed) {
            const int n = int(p.samples);
            if ((n & (n - 1)) == 0 || n % 16 == 0)
                std::printf("           %5d   %12.4f   %7.4f   %7.1f\n", n, noise(p, 0), noise(p, 1), p.seconds);
        }

        std::printf("adaptive   threshold  min  max   mean samples   relative RMS   relMSE    seconds   "
                    "(Cycles' Noise Threshold)\n");
        std::vector<Point> adaptive;
        for (float t : thresholds) {
            RenderSettings s = base;
            s.samples = max_samples;
            s.adaptive_sampling = true;
            s.adaptive_threshold = t;
            s.adaptive_min_samples = min_samples;
            const Film film = render(scene, camera, s);
            const Point p{double(film.stats.camera_rays) / pixels, film.stats.render_seconds,
                          squared_errors(film, reference)};
            adaptive.push_back(p);
            std::printf("           %8.4f  %4d  %4d   %12.1f   %12.4f   %7.4f   %7.1f\n", t, min_samples, max_samples,
                        p.samples, noise(p, 0), noise(p, 1), p.seconds);
        }
        // Each adaptive render against fixed sampling at the same noise: n = a / e^2 samples (the fitted curve), at
        // the fixed render's seconds per sample.
        const double fixed_seconds_per_sample = fixed.back().seconds / fixed.back().samples;
        std::printf("same noise with fixed samples (n = a / e^2 from the fit; time at %.2f s per sample):\n",
                    fixed_seconds_per_sample);
        for (std::size_t i = 0; i < adaptive.size(); ++i)
            for (int k = 0; k < kMetrics; ++k) {
                const double e2 = std::max(adaptive[i].e2[k] - b[k], 1e-30), n = a[k] / e2;
                std::printf("  threshold %.4f, %-12s fixed %6.1f samples (%6.1f s) vs adaptive %5.1f (%6.1f s): "
                            "%.2fx fewer samples, %.2fx less time\n",
                            thresholds[i], kMetricNames[k], n, n * fixed_seconds_per_sample, adaptive[i].samples,
                            adaptive[i].seconds, n / adaptive[i].samples,
                            n * fixed_seconds_per_sample / adaptive[i].seconds);
            }
        std::sort(adaptive.begin(), adaptive.end(), [](const Point& x, const Point& y) { return x.samples < y.samples; });
        for (int k = 0; k < kMetrics; ++k)
            for (double target : {0.01, 0.005}) {
                double fixed_samples = 0, fixed_seconds = 0, adaptive_samples = 0, adaptive_seconds = 0;
                const bool fixed_reached = crossing(fixed, k, b[k], target, fixed_samples, fixed_seconds);
                const bool adaptive_reached = crossing(adaptive, k, b[k], target, adaptive_samples, adaptive_seconds);
                std::printf("to %.1f %% noise, %s (interpolated in log-log):\n", 100 * target, kMetricNames[k]);
                if (fixed_reached)
                    std::printf("  fixed samples      %6.1f samples per pixel, %6.1f s\n", fixed_samples, fixed_seconds);
                else
                    std::printf("  fixed samples      not bracketed within %d samples\n", max_samples);
                if (adaptive_reached)
                    std::printf("  adaptive sampling  %6.1f samples per pixel (mean), %6.1f s\n", adaptive_samples,
                                adaptive_seconds);
                else
                    std::printf("  adaptive sampling  not bracketed by the thresholds run (its minimum may be above)\n");
            }
    } catch (const std::exception& e) {
        std::fprintf(stderr, "bench_convergence: %s\n", e.what());
        return 1;
    }
    return 0;
}
