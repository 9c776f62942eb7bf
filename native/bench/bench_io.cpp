// Splat file read / write throughput on the real scenes in shared/data (docs/design.md §8).
// For each file: read time (best of 3), MB/s of the file size, splats/s; then write time and MB/s of the
// written file for its own format (into the system temp folder; the file is removed afterwards); read-only formats
// (SOG) are only read. A second table: the up-axis estimate (raysplats/up_axis.h) and a KHR_gaussian_splatting .glb
// written (mesh export) and read back.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "raysplats/mesh_export.h"
#include "raysplats/splat_io.h"
#include "raysplats/up_axis.h"

namespace fs = std::filesystem;

int main(int argc, char** argv) {
    const fs::path dir = argc > 1 ? fs::path(argv[1]) : fs::path(RAYSPLATS_DATA_DIR);
    std::vector<fs::path> files;
    for (const auto& e : fs::directory_iterator(dir)) {
        const std::string ext = e.path().extension().string();
        if (ext == ".ply" || ext == ".splat" || ext == ".spz" || ext == ".sog") files.push_back(e.path());
    }
    std::sort(files.begin(), files.end());
    using clock = std::chrono::steady_clock;
    std::printf("%-28s %9s %10s %10s %9s %10s %10s %9s\n", "file", "splats", "MB", "read ms", "read MB/s", "write ms",
                "out MB", "wrt MB/s");
    for (const auto& p : files) {
        try {
            const double mb = double(fs::file_size(p)) / 1e6;
            double best_read = 1e30;
            raysplats::GaussianCloud cloud;
            for (int rep = 0; rep < 3; ++rep) {
                const auto t0 = clock::now();
                cloud = raysplats::read_splat_file(p.string());
                best_read = std::min(best_read, std::chrono::duration<double>(clock::now() - t0).count());
            }
            if (raysplats::splat_format_from_extension(p.string()) == raysplats::SplatFormat::Sog) {
                std::printf("%-28s %9zu %10.2f %10.1f %9.0f %10s\n", p.filename().string().c_str(), cloud.size(), mb,
                            best_read * 1e3, mb / best_read, "read only");
                continue;
            }
            // The file's own format (a .compressed.ply is written as one, not as the .ply its last dot names).
            const raysplats::SplatFormat format = raysplats::probe_splat_file(p.string()).format;
            std::string extension = p.extension().string();
            for (const raysplats::SplatFormatInfo& f : raysplats::splat_formats())
                if (f.format == format) extension = f.extensions.front();
            const fs::path out = fs::temp_directory_path() / ("raysplats_bench_io" + extension);
            double best_write = 1e30;
            for (int rep = 0; rep < 3; ++rep) {
                const auto t0 = clock::now();
                raysplats::write_splat_file(out.string(), cloud);
                best_write = std::min(best_write, std::chrono::duration<double>(clock::now() - t0).count());
            }
            const double out_mb = double(fs::file_size(out)) / 1e6;
            fs::remove(out);
            std::printf("%-28s %9zu %10.2f %10.1f %9.0f %10.1f %10.2f %9.0f\n", p.filename().string().c_str(), cloud.size(), mb,
                        best_read * 1e3, mb / best_read, best_write * 1e3, out_mb, out_mb / best_write);
        } catch (const std::exception& e) {
            std::printf("%-28s error: %s\n", p.filename().string().c_str(), e.what());
        }
    }
    std::printf("\n%-28s %9s %12s %6s %7s %10s %10s %10s\n", "file", "splats", "up axis ms", "up", "margin", "glb MB",
                "glb wrt ms", "glb read ms");
    for (const auto& p : files) {
        try {
            raysplats::ExportScene scene;
            scene.gaussians.emplace_back();
            scene.gaussians.back().cloud = raysplats::read_splat_file(p.string());
            const raysplats::GaussianCloud& cloud = scene.gaussians.back().cloud;
            double best_up = 1e30, best_write = 1e30, best_read = 1e30;
            raysplats::UpAxisEstimate estimate;
            for (int rep = 0; rep < 3; ++rep) {
                const auto t0 = clock::now();
                estimate = raysplats::estimate_up_axis(cloud);
                best_up = std::min(best_up, std::chrono::duration<double>(clock::now() - t0).count());
            }
            const fs::path out = fs::temp_directory_path() / "raysplats_bench_io.glb";
            raysplats::MeshWriteOptions options;
            options.gaussian_splatting_extension = true;
            for (int rep = 0; rep < 3; ++rep) {
                const auto t0 = clock::now();
                raysplats::write_mesh_file(out.string(), scene, options);
                best_write = std::min(best_write, std::chrono::duration<double>(clock::now() - t0).count());
            }
            for (int rep = 0; rep < 3; ++rep) {
                const auto t0 = clock::now();
                raysplats::read_splat_file(out.string());
                best_read = std::min(best_read, std::chrono::duration<double>(clock::now() - t0).count());
            }
            const double glb_mb = double(fs::file_size(out)) / 1e6;
            fs::remove(out);
            std::printf("%-28s %9zu %12.1f %6s %7.3f %10.2f %10.1f %10.1f\n", p.filename().string().c_str(), cloud.size(),
                        best_up * 1e3, estimate.decided ? estimate.axis() : "-", estimate.margin, glb_mb, best_write * 1e3,
                        best_read * 1e3);
        } catch (const std::exception& e) {
            std::printf("%-28s error: %s\n", p.filename().string().c_str(), e.what());
        }
    }
    return 0;
}
