// Splat file read / write throughput on the real scenes in shared/data (DESIGN §8).
// For each file: read time (best of 3), MB/s of the file size, splats/s; then write time and MB/s of the
// written file for its own format (into the system temp folder; the file is removed afterwards); read-only formats
// (SOG) are only read.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "raysplats/splat_io.h"

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
            const fs::path out = fs::temp_directory_path() / ("raysplats_bench_io" + p.extension().string());
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
    return 0;
}
