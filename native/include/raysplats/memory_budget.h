// Memory an import needs and memory the machine has, so that an import too large for the machine is refused
// before it starts with a message that says so, instead of failing half-way with std::bad_alloc.
#pragma once

#include <cstdint>

namespace raysplats {

// Peak bytes of importing `count` Gaussians of SH degree `sh_degree` as polygons of `vertices_per_polygon`
// corners: the larger of the cloud read from the file (twice: the core copies it) with the polygon arrays made from it
// (polygon_bridge.h: SplatPolygons), and those arrays with the host application's mesh filled from them; plus the
// mesh once more (the copy Blender's undo step keeps). An estimate from the array sizes: 1.17 GB for showroom_1.5M.ply
// (1.5 M Gaussians, degree 0) as quadrilaterals, the Auto default, 2.03 GB as octagons; examples/
// benchmark_import_memory.py measures the real peak (blender_tests/test_import_memory.py keeps it under this).
std::uint64_t import_memory_bytes(std::uint64_t count, int sh_degree, int vertices_per_polygon);

// Peak bytes of importing `count` Gaussians as a compact splat object (one point per Gaussian with its attributes,
// Blender 5.3's splat layout): the cloud read from the file, one temporary attribute array, and the host's point
// data (position with its per-point flags, scale, rotation, DC colour + opacity, the other SH coefficients) counted
// twice (the data plus the copy an undo step keeps).
std::uint64_t compact_import_memory_bytes(std::uint64_t count, int sh_degree);

// Bytes that can be allocated without swapping: the kernel's MemAvailable (/proc/meminfo), lowered to the room
// left under this process's cgroup memory limit (cgroup v2 memory.max - memory.current) when there is one.
// 0 when neither can be read (then callers do not refuse anything).
std::uint64_t available_memory_bytes();

}  // namespace raysplats
