// Draco encoding of one export mesh part, for KHR_draco_mesh_compression. Float attributes are quantised
// with the requested bits; colours are 8-bit integers (lossless). No points are merged (the mesh is built
// without deduplication), so the decoded primitive has exactly the part's vertex and triangle counts; the
// Edgebreaker coder may reorder them, which KHR_draco_mesh_compression allows.
#include <draco/compression/encode.h>
#include <draco/mesh/mesh.h>

#include <memory>

#include "io/mesh_writers.h"
#include "raysplats/errors.h"

namespace raysplats {
namespace io {

namespace {

int add_attribute(draco::Mesh& mesh, draco::GeometryAttribute::Type type, int components, draco::DataType data_type,
                  bool normalized, const void* data, std::size_t count) {
    const int element = components * (data_type == draco::DT_UINT8 ? 1 : 4);
    draco::GeometryAttribute attribute;
    attribute.Init(type, nullptr, std::uint8_t(components), data_type, normalized, element, 0);
    const int id = mesh.AddAttribute(attribute, true, std::uint32_t(count));
    mesh.attribute(id)->buffer()->Write(0, data, std::size_t(element) * count);
    return int(mesh.attribute(id)->unique_id());
}

}  // namespace

DracoPart encode_draco_part(const ExportMesh& mesh, const ExportMeshPart& part, const DracoOptions& options) {
    const std::size_t nv = part.vertex_count, v0 = part.vertex_begin;
    draco::Mesh dm;
    dm.set_num_points(std::uint32_t(nv));
    DracoPart out;
    out.position_id = add_attribute(dm, draco::GeometryAttribute::POSITION, 3, draco::DT_FLOAT32, false,
                                    &mesh.positions[3 * v0], nv);
    if (!mesh.normals.empty())
        out.normal_id = add_attribute(dm, draco::GeometryAttribute::NORMAL, 3, draco::DT_FLOAT32, false,
                                      &mesh.normals[3 * v0], nv);
    if (!mesh.uvs.empty())
        out.uv_id = add_attribute(dm, draco::GeometryAttribute::TEX_COORD, 2, draco::DT_FLOAT32, false, &mesh.uvs[2 * v0], nv);
    if (!mesh.colors.empty()) {
        std::vector<std::uint8_t> bytes(4 * nv);
        for (std::size_t k = 0; k < 4 * nv; ++k) bytes[k] = unit_to_byte(mesh.colors[4 * v0 + k]);
        out.color_id = add_attribute(dm, draco::GeometryAttribute::COLOR, 4, draco::DT_UINT8, true, bytes.data(), nv);
    }
    dm.SetNumFaces(part.triangle_count);
    const std::uint32_t* tri = &mesh.triangles[3 * part.triangle_begin];
    for (std::size_t t = 0; t < part.triangle_count; ++t)
        dm.SetFace(draco::FaceIndex(std::uint32_t(t)),
                   {draco::PointIndex(tri[3 * t]), draco::PointIndex(tri[3 * t + 1]), draco::PointIndex(tri[3 * t + 2])});

    draco::Encoder encoder;
    encoder.SetAttributeQuantization(draco::GeometryAttribute::POSITION, options.position_bits);
    encoder.SetAttributeQuantization(draco::GeometryAttribute::NORMAL, options.normal_bits);
    encoder.SetAttributeQuantization(draco::GeometryAttribute::TEX_COORD, options.uv_bits);
    const int speed = 10 - options.compression_level;
    encoder.SetSpeedOptions(speed, speed);
    draco::EncoderBuffer buffer;
    const draco::Status status = encoder.EncodeMeshToBuffer(dm, &buffer);
    if (!status.ok())
        throw Error("Draco could not encode mesh '" + mesh.name + "': " + status.error_msg_string());
    out.bytes.assign(buffer.data(), buffer.data() + buffer.size());
    return out;
}

}  // namespace io
}  // namespace raysplats
