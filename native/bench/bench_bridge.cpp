// Benchmark of the polygon bridge on a real scene: Gaussians -> polygons (import) and polygons -> Gaussians
// (recovery, every render and export), both for unedited faces (bit-exact path) and for edited ones
// (moments). Prints the time of each stage and the rate in splats per second, and what the opacity-aware radius
// did (docs/design.md §5): Gaussians skipped below 1/255, faces with rho_i < rho, the mean rho_i, the mesh's vertex
// memory.
//   bench_bridge [file.ply] [K]
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <string>

#include "raysplats/polygon_bridge.h"
#include "raysplats/splat_io.h"

namespace {
double seconds_since(std::chrono::steady_clock::time_point t0) {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}
template <typename F>
double best_of(int runs, F&& f) {
    double best = 1e30;
    for (int i = 0; i < runs; ++i) {
        const auto t0 = std::chrono::steady_clock::now();
        f();
        best = std::min(best, seconds_since(t0));
    }
    return best;
}
}  // namespace

int main(int argc, char** argv) {
    const std::string path = argc > 1 ? argv[1] : std::string(RAYSPLATS_DATA_DIR) + "/showroom_1.5M.ply";
    raysplats::PolygonSettings settings;
    if (argc > 2) settings.vertices_per_polygon = std::stoi(argv[2]);
    try {
        raysplats::GaussianCloud cloud;
        const double t_read = best_of(1, [&] { cloud = raysplats::read_splat_file(path); });
        const double n = double(cloud.size());
        std::printf("%s: %zu splats, SH degree %d, K = %d\n", path.c_str(), cloud.size(), cloud.sh_degree,
                    settings.vertices_per_polygon);
        std::printf("  read file               %8.3f s  %6.2f M splats/s\n", t_read, n / t_read / 1e6);

        raysplats::SplatPolygons polygons;
        const double t_poly = best_of(3, [&] { polygons = raysplats::gaussians_to_polygons(cloud, settings); });
        std::printf("  gaussians -> polygons   %8.3f s  %6.2f M splats/s\n", t_poly, n / t_poly / 1e6);
        const std::size_t faces = polygons.polygon_radius.size();
        double radius_sum = 0;
        std::size_t smaller = 0;
        for (float r : polygons.polygon_radius) radius_sum += r, smaller += r < settings.radius;
        std::printf("  faces %zu (%zu Gaussians below 1/255 skipped), rho_i < rho = %.1f on %zu (%.1f %%), mean rho_i "
                    "%.4f\n", faces, polygons.invisible_skipped, double(settings.radius), smaller,
                    100.0 * double(smaller) / double(std::max<std::size_t>(faces, 1)), radius_sum / double(std::max<std::size_t>(faces, 1)));
        std::printf("  vertices %zu (K per face), %.1f MB of float32 positions\n", polygons.vertex_positions.size() / 3,
                    double(polygons.vertex_positions.size() * sizeof(float)) / 1e6);

        const raysplats::PolygonMeshView mesh = raysplats::mesh_view(polygons);
        // Without the rest Gaussians first: every face goes through the moments.
        raysplats::SplatFaceAttributesView attr = raysplats::attributes_view(polygons);
        const raysplats::SplatFaceAttributesView stored = attr;
        attr.rest_centers = attr.rest_rotations = attr.rest_scales = nullptr;
        raysplats::RecoveryOptions options;
        options.polygon = settings;
        // A rotation about X by -90° (the usual import axis conversion) as the object transform.
        const double rotate[16] = {1, 0, 0, 0, 0, 0, 1, 0, 0, -1, 0, 0, 0, 0, 0, 1};

        raysplats::GaussianCloud out;
        const double t_moments = best_of(3, [&] { out = raysplats::recover_gaussians_from_polygons(mesh, attr, options); });
        std::printf("  recovery, moments       %8.3f s  %6.2f M splats/s\n", t_moments, n / t_moments / 1e6);
        std::copy(rotate, rotate + 16, options.mesh_to_output);
        const double t_moments_rot = best_of(3, [&] { out = raysplats::recover_gaussians_from_polygons(mesh, attr, options); });
        std::printf("  recovery, moments + rotated object %8.3f s  %6.2f M splats/s\n", t_moments_rot, n / t_moments_rot / 1e6);

        attr = stored;
        const double t_rest = best_of(3, [&] { out = raysplats::recover_gaussians_from_polygons(mesh, attr, options); });
        std::printf("  recovery, unedited (bit-exact path) + rotated object %8.3f s  %6.2f M splats/s\n", t_rest,
                    n / t_rest / 1e6);

        const std::string out_path = "/tmp/raysplats_bench_bridge.ply";
        const double t_write = best_of(1, [&] { raysplats::write_splat_file(out_path, out); });
        std::printf("  write .ply              %8.3f s  %6.2f M splats/s\n", t_write, n / t_write / 1e6);
        std::remove(out_path.c_str());
    } catch (const std::exception& e) {
        std::fprintf(stderr, "bench_bridge: %s\n", e.what());
        return 1;
    }
    return 0;
}
