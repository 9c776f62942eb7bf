// Private interface between mesh_export.cpp (scene building, dispatch) and the format writers
// (mesh_obj_ply_writer.cpp: OpenMesh; gltf_writer.cpp: tinygltf; draco_encoder.cpp: Draco).
#pragma once

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "core/color_math.h"
#include "raysplats/mesh_export.h"

namespace raysplats {
namespace io {

MeshWriteStats write_obj(const std::string& path, const ExportScene& scene);
MeshWriteStats write_ply(const std::string& path, const ExportScene& scene);
MeshWriteStats write_gltf(const std::string& path, const ExportScene& scene, const MeshWriteOptions& options, bool binary);

// One part of a mesh as a Draco mesh stream (KHR_draco_mesh_compression). Attribute ids in the stream, in
// this order, for the attributes the mesh has: POSITION, NORMAL (if any), TEXCOORD_0 (if any), COLOR_0 (if any).
struct DracoPart {
    std::vector<char> bytes;
    int position_id = -1, normal_id = -1, uv_id = -1, color_id = -1;
};
DracoPart encode_draco_part(const ExportMesh& mesh, const ExportMeshPart& part, const DracoOptions& options);

inline std::uint8_t unit_to_byte(float c) { return std::uint8_t(std::lround(clamp_unit(c) * 255.0f)); }

// 8-bit sRGB of a linear value in [0, 1] by a 4096-entry table (the per-vertex pow() would dominate PLY writing).
class SrgbTable {
public:
    SrgbTable() {
        for (int i = 0; i < kSize; ++i) table_[i] = unit_to_byte(linear_to_srgb_clamped(float(i) / (kSize - 1)));
    }
    std::uint8_t operator()(float linear) const {
        return table_[int(clamp_unit(linear) * (kSize - 1) + 0.5f)];
    }

private:
    static constexpr int kSize = 4096;
    std::uint8_t table_[kSize];
};

}  // namespace io
}  // namespace raysplats
