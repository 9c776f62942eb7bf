// Import memory estimate and available memory (raysplats/memory_budget.h).
#include "raysplats/memory_budget.h"

#include <algorithm>
#include <fstream>
#include <string>

#ifdef _WIN32
#include "core/windows_api.h"
#include <psapi.h>
#endif

#include "raysplats/gaussian_cloud.h"

namespace raysplats {

std::uint64_t import_memory_bytes(std::uint64_t count, int sh_degree, int vertices_per_polygon) {
    const std::uint64_t k = std::uint64_t(std::max(3, vertices_per_polygon));
    const std::uint64_t coeffs = std::uint64_t(sh_coeff_count(std::min(std::max(sh_degree, 0), 3)));
    // GaussianCloud: position 3, rotation 4, scale 3, opacity 1, SH 3 per coefficient (floats).
    const std::uint64_t cloud = 4 * (11 + 3 * coeffs);
    // SplatPolygons per Gaussian: K vertices (3 floats), K corners (vertex, edge: 2 ints; colour 4 bytes, uv 2 floats),
    // K edges (2 ints); per face start, count, thickness, radius, opacity, rest centre 3, rotation 4, scale 3 (4 bytes
    // each) and the local SH (3 floats per coefficient).
    const std::uint64_t polygons = k * (12 + 8 + 4 + 8 + 8) + 4 * 15 + 12 * coeffs;
    // Blender's mesh (the larger layout, 3.4's structs: vertex 16, edge 12, corner 8, face 12 bytes; 3.6 and newer
    // store 12, 8, 8 and 4): per corner also the byte colour (4) and the UV (3.4's MLoopUV 12, later 8); per face
    // opacity, rest centre 3, rotation 4, scale 3 (floats) and the SH (3 floats per coefficient). No selection layers,
    // no thickness (recomputed from the rest scales), no radius (the UV map holds it).
    const std::uint64_t mesh = k * (16 + 12 + 8 + 4 + 12) + 12 + 4 * 11 + 12 * coeffs;
    // The peak is the larger of making the polygons (the file's cloud, the core's copy of it and the polygons) and
    // filling the mesh (the polygon arrays are freed as Blender copies them: at most all of both), plus the copy of the
    // mesh an undo step keeps (the GUI; none in background mode).
    return count * (std::max(2 * cloud + polygons, polygons + mesh) + mesh);
}

std::uint64_t compact_import_memory_bytes(std::uint64_t count, int sh_degree) {
    const std::uint64_t coeffs = std::uint64_t(sh_coeff_count(std::min(std::max(sh_degree, 0), 3)));
    const std::uint64_t cloud = 4 * (11 + 3 * coeffs);
    // Blender's points: position 12 B plus about 4 B of flags, scale 12, rotation 16, radiance:base 16, 12 B per
    // further SH coefficient.
    const std::uint64_t points = 16 + 12 + 16 + 16 + 12 * (coeffs - 1);
    return count * (cloud + 16 + 2 * points);
}

#ifdef _WIN32

// Physical memory not in use (what Task Manager calls available), capped by the room left under this process's job
// object memory limit, if it has one (Windows' counterpart of a cgroup's memory.max).
std::uint64_t available_memory_bytes() {
    MEMORYSTATUSEX status{};
    status.dwLength = sizeof(status);
    std::uint64_t available = GlobalMemoryStatusEx(&status) ? std::uint64_t(status.ullAvailPhys) : 0;
    JOBOBJECT_EXTENDED_LIMIT_INFORMATION job{};
    PROCESS_MEMORY_COUNTERS_EX counters{};
    counters.cb = sizeof(counters);
    if (QueryInformationJobObject(nullptr, JobObjectExtendedLimitInformation, &job, sizeof(job), nullptr) &&
        (job.BasicLimitInformation.LimitFlags & JOB_OBJECT_LIMIT_PROCESS_MEMORY) &&
        K32GetProcessMemoryInfo(GetCurrentProcess(), reinterpret_cast<PROCESS_MEMORY_COUNTERS*>(&counters),
                                sizeof(counters))) {
        const std::uint64_t limit = job.ProcessMemoryLimit, used = counters.PrivateUsage;
        const std::uint64_t room = limit > used ? limit - used : 0;
        available = available ? std::min(available, room) : room;
    }
    return available;
}

#else

namespace {
// The first number in a file, or `fallback` (for "max" and for files that cannot be read).
std::uint64_t read_number(const std::string& path, std::uint64_t fallback) {
    std::ifstream in(path);
    unsigned long long v = 0;
    if (!(in >> v)) return fallback;
    return v;
}
}  // namespace

std::uint64_t available_memory_bytes() {
    std::uint64_t available = 0;
    std::ifstream meminfo("/proc/meminfo");
    std::string key;
    unsigned long long kb = 0;
    std::string unit;
    while (meminfo >> key >> kb >> unit)
        if (key == "MemAvailable:") {
            available = std::uint64_t(kb) * 1024;
            break;
        }
    // This process's cgroup (v2: the line "0::/path" of /proc/self/cgroup).
    std::string group;
    std::ifstream cgroups("/proc/self/cgroup");
    for (std::string line; std::getline(cgroups, line);)
        if (line.rfind("0::", 0) == 0) group = line.substr(3);
    if (group == "/") group.clear();
    const std::string dir = "/sys/fs/cgroup" + group;
    constexpr std::uint64_t kNone = ~std::uint64_t(0);
    const std::uint64_t limit = read_number(dir + "/memory.max", kNone);
    if (limit != kNone) {
        const std::uint64_t used = read_number(dir + "/memory.current", 0);
        const std::uint64_t room = limit > used ? limit - used : 0;
        available = available ? std::min(available, room) : room;
    }
    return available;
}

#endif

}  // namespace raysplats
