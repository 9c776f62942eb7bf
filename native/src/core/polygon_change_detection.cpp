// Which faces of a polygon mesh an edit changed, bit for bit (design.md §5): the viewport recovers only those.
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <cstring>
#include <string>

#include "core/polygon_frame.h"
#include "raysplats/errors.h"
#include "raysplats/polygon_bridge.h"

namespace raysplats {
namespace {

std::vector<std::uint32_t> indices_of_set_flags(const std::vector<unsigned char>& flags) {
    std::vector<std::uint32_t> indices;
    for (std::size_t i = 0; i < flags.size(); ++i)
        if (flags[i]) indices.push_back(std::uint32_t(i));
    return indices;
}

}  // namespace

std::vector<std::uint32_t> faces_with_moved_vertices(const PolygonMeshView& mesh, const float* previous_positions) {
    std::vector<unsigned char> moved(mesh.vertex_count);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, mesh.vertex_count, 1 << 16), [&](const auto& range) {
        for (std::size_t v = range.begin(); v != range.end(); ++v)
            moved[v] = std::memcmp(&mesh.vertex_positions[3 * v], &previous_positions[3 * v], 3 * sizeof(float)) != 0;
    });
    std::vector<unsigned char> face_moved(mesh.face_count);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, mesh.face_count, polygon::kFacesPerTask),
                      [&](const auto& range) {
        for (std::size_t f = range.begin(); f != range.end(); ++f) {
            const std::int64_t start = mesh.face_corner_start[f];
            const std::int64_t end = start + mesh.face_corner_count[f];
            if (start < 0 || end > std::int64_t(mesh.corner_count))
                throw InvalidArgument("face " + std::to_string(f) + " has corners outside the corner array");
            bool any = false;
            for (std::int64_t k = start; k < end && !any; ++k) {
                const std::int32_t vi = mesh.corner_vertices[k];
                if (vi < 0 || std::size_t(vi) >= mesh.vertex_count)
                    throw InvalidArgument("face " + std::to_string(f) + " uses vertex " + std::to_string(vi) + " of " +
                                          std::to_string(mesh.vertex_count));
                any = moved[std::size_t(vi)] != 0;
            }
            face_moved[f] = any;
        }
    });
    return indices_of_set_flags(face_moved);
}

std::vector<std::uint32_t> rows_that_differ(const float* previous, const float* current, std::size_t rows,
                                            std::size_t width) {
    std::vector<unsigned char> differs(rows);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, rows, 1 << 15), [&](const auto& range) {
        for (std::size_t r = range.begin(); r != range.end(); ++r)
            differs[r] = std::memcmp(&previous[r * width], &current[r * width], width * sizeof(float)) != 0;
    });
    return indices_of_set_flags(differs);
}

}  // namespace raysplats
