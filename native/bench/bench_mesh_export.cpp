// Mesh export benchmark (docs/design.md §7, §8): splat file -> splat patches -> GLB, Draco GLB, PLY (and OBJ with
// --obj), with times, output sizes and the Draco size as a fraction of the plain GLB.
//   bench_mesh_export [file] [output-dir] [--obj] [--only glb|draco|ply|obj] [--level N]
// Default file: showroom_1.5M.ply in RAYSPLATS_DATA_DIR; default output dir: /tmp.
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>

#include "raysplats/errors.h"
#include "raysplats/mesh_export.h"
#include "raysplats/splat_io.h"

namespace {

double seconds_since(std::chrono::steady_clock::time_point t0) {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

int main(int argc, char** argv) {
    std::string file = std::string(RAYSPLATS_DATA_DIR) + "/showroom_1.5M.ply";
    std::string out_dir = "/tmp";
    bool obj = false;
    std::string only;  // --only glb|draco|ply|obj
    int level = 7;
    int positional = 0;
    for (int i = 1; i < argc; ++i) {
        const std::string a = argv[i];
        if (a == "--obj") obj = true;
        else if (a == "--only" && i + 1 < argc) only = argv[++i];
        else if (a == "--level" && i + 1 < argc) level = std::atoi(argv[++i]);
        else if (positional == 0) file = a, ++positional;
        else out_dir = a, ++positional;
    }
    try {
        using clock = std::chrono::steady_clock;
        auto t0 = clock::now();
        const raysplats::GaussianCloud cloud = raysplats::read_splat_file(file);
        std::printf("read      %-28s %9zu Gaussians  %6.2f s\n", std::filesystem::path(file).filename().c_str(), cloud.size(),
                    seconds_since(t0));

        raysplats::PolygonSettings polygon;  // K = 8, rho = 3
        auto export_to = [&](const std::string& name, bool draco) {
            const std::string path = out_dir + "/" + name;
            const auto t = clock::now();
            raysplats::ExportScene scene;
            raysplats::ExportMaterial material;
            material.name = "Gaussian splats";
            material.base_color[0] = material.base_color[1] = material.base_color[2] = material.base_color[3] = 1.0f;
            material.alpha_blend = true;
            material.double_sided = true;
            scene.materials.push_back(material);
            scene.meshes.push_back(raysplats::splat_patches(cloud, polygon, "splats", 0));
            const double t_patches = seconds_since(t);
            raysplats::MeshWriteOptions options;
            options.draco.enabled = draco;
            options.draco.compression_level = level;
            const auto stats = raysplats::write_mesh_file(path, scene, options);
            const double total = seconds_since(t);
            const auto size = std::filesystem::file_size(path);
            std::printf("export    %-28s %9zu vertices %9zu triangles  %6.2f s (patches %.2f s, %.1f M Gaussians/s)  %8.1f MB\n",
                        name.c_str(), stats.vertices, stats.triangles, total, t_patches, cloud.size() / total / 1e6,
                        double(size) / 1e6);
            return double(size);
        };
        auto run = [&](const std::string& what) { return only.empty() || only == what; };
        const double glb = run("glb") ? export_to("bench_mesh_export.glb", false) : 0;
        const double draco = run("draco") ? export_to("bench_mesh_export_draco.glb", true) : 0;
        if (run("ply")) export_to("bench_mesh_export.ply", false);
        if (obj || only == "obj") export_to("bench_mesh_export.obj", false);
        if (glb > 0 && draco > 0)
            std::printf("Draco GLB / plain GLB = %.3f (compression level %d)\n", draco / glb, level);
    } catch (const raysplats::Error& e) {
        std::fprintf(stderr, "bench_mesh_export: %s\n", e.what());
        return 1;
    }
    return 0;
}
