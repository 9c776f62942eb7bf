// glTF 2.0 export (.gltf + .bin, .glb). tinygltf builds and serialises the JSON document; the binary
// buffer is laid out and filled here in parallel and written once, with the GLB container around it, through
// the atomic writer (tinygltf's own file writers neither write atomically nor avoid copying the buffer).
//
// Layout per mesh: one bufferView per attribute (POSITION, NORMAL, TEXCOORD_0 float; COLOR_0 as normalised
// unsigned bytes, linear as the spec requires) and one for indices; each part is one primitive whose
// accessors are windows into those views. With Draco, each part is one Draco stream in its own bufferView
// and the primitive's accessors have no bufferView (KHR_draco_mesh_compression).
// Axes: the caller gives coordinates in glTF's convention (+Y up, +Z forward, metres).
#define TINYGLTF_IMPLEMENTATION
#define TINYGLTF_NO_STB_IMAGE
#define TINYGLTF_NO_STB_IMAGE_WRITE
#define TINYGLTF_NO_EXTERNAL_IMAGE
#include <tiny_gltf.h>

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cstring>
#include <functional>
#include <limits>
#include <memory>
#include <sstream>

#include "io/io_common.h"
#include "core/os_files.h"
#include "io/mesh_writers.h"

namespace raysplats {
namespace io {

namespace {

constexpr int kArrayBuffer = 34962;
constexpr int kElementArrayBuffer = 34963;
constexpr const char* kDracoExtension = "KHR_draco_mesh_compression";
constexpr const char* kSplatExtension = "KHR_gaussian_splatting";

std::size_t align4(std::size_t n) { return (n + 3) & ~std::size_t(3); }

// A region of the binary buffer and the function that fills it.
struct Region {
    std::size_t offset = 0, size = 0;
    std::function<void(std::uint8_t*)> fill;
};

class BufferLayout {
public:
    // Reserves `size` bytes (4-aligned start) and returns the offset.
    std::size_t add(std::size_t size, std::function<void(std::uint8_t*)> fill) {
        const std::size_t offset = size_;
        regions_.push_back({offset, size, std::move(fill)});
        size_ = align4(offset + size);
        return offset;
    }
    std::size_t size() const { return size_; }
    // Fills every region into `out` (size() bytes) in parallel; padding is zeroed.
    void fill(std::uint8_t* out) const {
        tbb::parallel_for(std::size_t(0), regions_.size(), [&](std::size_t r) {
            const Region& region = regions_[r];
            region.fill(out + region.offset);
            const std::size_t end = region.offset + region.size;
            std::memset(out + end, 0, align4(end) - end);
        });
    }

private:
    std::vector<Region> regions_;
    std::size_t size_ = 0;
};

int add_buffer_view(tinygltf::Model& model, std::size_t offset, std::size_t length, int stride, int target) {
    tinygltf::BufferView view;
    view.buffer = 0;
    view.byteOffset = offset;
    view.byteLength = length;
    view.byteStride = std::size_t(stride);
    view.target = target;
    model.bufferViews.push_back(view);
    return int(model.bufferViews.size() - 1);
}

int add_accessor(tinygltf::Model& model, int view, std::size_t byte_offset, int component, int type, std::size_t count,
                 bool normalized = false) {
    tinygltf::Accessor a;
    a.bufferView = view;
    a.byteOffset = byte_offset;
    a.componentType = component;
    a.type = type;
    a.count = count;
    a.normalized = normalized;
    model.accessors.push_back(a);
    return int(model.accessors.size() - 1);
}

void position_bounds(const ExportMesh& mesh, const ExportMeshPart& part, std::vector<double>& lo, std::vector<double>& hi) {
    float mn[3] = {std::numeric_limits<float>::max(), std::numeric_limits<float>::max(), std::numeric_limits<float>::max()};
    float mx[3] = {-mn[0], -mn[1], -mn[2]};
    const float* p = &mesh.positions[3 * part.vertex_begin];
    for (std::size_t v = 0; v < part.vertex_count; ++v)
        for (int c = 0; c < 3; ++c) mn[c] = std::min(mn[c], p[3 * v + c]), mx[c] = std::max(mx[c], p[3 * v + c]);
    lo.assign(mn, mn + 3);
    hi.assign(mx, mx + 3);
}

tinygltf::Value json_object(std::initializer_list<std::pair<const std::string, tinygltf::Value>> items) {
    return tinygltf::Value(tinygltf::Value::Object(items));
}

void use_extension(tinygltf::Model& model, const std::string& name, bool required) {
    if (std::find(model.extensionsUsed.begin(), model.extensionsUsed.end(), name) == model.extensionsUsed.end())
        model.extensionsUsed.push_back(name);
    if (required && std::find(model.extensionsRequired.begin(), model.extensionsRequired.end(), name) ==
                        model.extensionsRequired.end())
        model.extensionsRequired.push_back(name);
}

int add_material(tinygltf::Model& model, const ExportMaterial& m) {
    tinygltf::Material mat;
    mat.name = m.name;
    mat.pbrMetallicRoughness.baseColorFactor = {m.base_color[0], m.base_color[1], m.base_color[2], m.base_color[3]};
    mat.pbrMetallicRoughness.metallicFactor = m.metallic;
    mat.pbrMetallicRoughness.roughnessFactor = m.roughness;
    mat.alphaMode = m.alpha_blend ? "BLEND" : "OPAQUE";
    mat.doubleSided = m.double_sided;
    model.materials.push_back(mat);
    return int(model.materials.size() - 1);
}

// Writes a mesh's parts as plain (uncompressed) primitives.
void add_plain_mesh(tinygltf::Model& model, BufferLayout& layout, const ExportMesh& mesh, tinygltf::Mesh& out,
                    const std::vector<int>& material_ids) {
    const std::size_t nv = mesh.vertex_count();
    std::size_t max_part = 0;
    for (const ExportMeshPart& p : mesh.parts) max_part = std::max(max_part, p.vertex_count);
    const bool short_indices = max_part <= 65535;
    const std::size_t index_size = short_indices ? 2 : 4;

    const int pos_view = add_buffer_view(model, layout.add(12 * nv, [&mesh](std::uint8_t* d) {
        std::memcpy(d, mesh.positions.data(), mesh.positions.size() * 4);
    }), 12 * nv, 12, kArrayBuffer);
    int normal_view = -1, uv_view = -1, color_view = -1;
    if (!mesh.normals.empty())
        normal_view = add_buffer_view(model, layout.add(12 * nv, [&mesh](std::uint8_t* d) {
            std::memcpy(d, mesh.normals.data(), mesh.normals.size() * 4);
        }), 12 * nv, 12, kArrayBuffer);
    if (!mesh.uvs.empty())
        uv_view = add_buffer_view(model, layout.add(8 * nv, [&mesh](std::uint8_t* d) {
            std::memcpy(d, mesh.uvs.data(), mesh.uvs.size() * 4);
        }), 8 * nv, 8, kArrayBuffer);
    if (!mesh.colors.empty())
        color_view = add_buffer_view(model, layout.add(4 * nv, [&mesh, nv](std::uint8_t* d) {
            tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nv, 1 << 16), [&](const tbb::blocked_range<std::size_t>& r) {
                for (std::size_t k = 4 * r.begin(); k < 4 * r.end(); ++k) d[k] = unit_to_byte(mesh.colors[k]);
            });
        }), 4 * nv, 4, kArrayBuffer);
    const std::size_t nidx = mesh.triangles.size();
    const int index_view = add_buffer_view(model, layout.add(index_size * nidx, [&mesh, short_indices, nidx](std::uint8_t* d) {
        if (!short_indices) {
            std::memcpy(d, mesh.triangles.data(), nidx * 4);
            return;
        }
        auto* out16 = reinterpret_cast<std::uint16_t*>(d);
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nidx, 1 << 16), [&](const tbb::blocked_range<std::size_t>& r) {
            for (std::size_t k = r.begin(); k < r.end(); ++k) out16[k] = std::uint16_t(mesh.triangles[k]);
        });
    }), index_size * nidx, 0, kElementArrayBuffer);

    for (const ExportMeshPart& part : mesh.parts) {
        if (!part.triangle_count) continue;
        tinygltf::Primitive prim;
        prim.mode = TINYGLTF_MODE_TRIANGLES;
        const int pos = add_accessor(model, pos_view, 12 * part.vertex_begin, TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC3,
                                     part.vertex_count);
        position_bounds(mesh, part, model.accessors[pos].minValues, model.accessors[pos].maxValues);
        prim.attributes["POSITION"] = pos;
        if (normal_view >= 0)
            prim.attributes["NORMAL"] = add_accessor(model, normal_view, 12 * part.vertex_begin, TINYGLTF_COMPONENT_TYPE_FLOAT,
                                                     TINYGLTF_TYPE_VEC3, part.vertex_count);
        if (uv_view >= 0)
            prim.attributes["TEXCOORD_0"] = add_accessor(model, uv_view, 8 * part.vertex_begin, TINYGLTF_COMPONENT_TYPE_FLOAT,
                                                         TINYGLTF_TYPE_VEC2, part.vertex_count);
        if (color_view >= 0)
            prim.attributes["COLOR_0"] = add_accessor(model, color_view, 4 * part.vertex_begin,
                                                      TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE, TINYGLTF_TYPE_VEC4,
                                                      part.vertex_count, true);
        prim.indices = add_accessor(model, index_view, index_size * 3 * part.triangle_begin,
                                    short_indices ? TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT : TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT,
                                    TINYGLTF_TYPE_SCALAR, 3 * part.triangle_count);
        prim.material = material_ids[std::size_t(part.material + 1)];
        out.primitives.push_back(prim);
    }
}

// Writes a mesh's parts as Draco-compressed primitives (encoded in parallel, one stream per part).
void add_draco_mesh(tinygltf::Model& model, BufferLayout& layout, const ExportMesh& mesh, tinygltf::Mesh& out,
                    const std::vector<int>& material_ids, const DracoOptions& options,
                    std::vector<std::shared_ptr<DracoPart>>& keep_alive) {
    std::vector<const ExportMeshPart*> parts;
    for (const ExportMeshPart& p : mesh.parts)
        if (p.triangle_count) parts.push_back(&p);
    std::vector<std::shared_ptr<DracoPart>> encoded(parts.size());
    tbb::parallel_for(std::size_t(0), parts.size(), [&](std::size_t i) {
        encoded[i] = std::make_shared<DracoPart>(encode_draco_part(mesh, *parts[i], options));
    });
    use_extension(model, kDracoExtension, true);
    for (std::size_t i = 0; i < parts.size(); ++i) {
        const ExportMeshPart& part = *parts[i];
        const DracoPart& d = *encoded[i];
        keep_alive.push_back(encoded[i]);
        const std::size_t size = d.bytes.size();
        const char* bytes = d.bytes.data();
        const int view = add_buffer_view(model, layout.add(size, [bytes, size](std::uint8_t* dst) { std::memcpy(dst, bytes, size); }),
                                         size, 0, 0);
        tinygltf::Primitive prim;
        prim.mode = TINYGLTF_MODE_TRIANGLES;
        tinygltf::Value::Object draco_attributes;
        const int pos = add_accessor(model, -1, 0, TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC3, part.vertex_count);
        position_bounds(mesh, part, model.accessors[pos].minValues, model.accessors[pos].maxValues);
        prim.attributes["POSITION"] = pos;
        draco_attributes["POSITION"] = tinygltf::Value(d.position_id);
        if (d.normal_id >= 0) {
            prim.attributes["NORMAL"] = add_accessor(model, -1, 0, TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC3, part.vertex_count);
            draco_attributes["NORMAL"] = tinygltf::Value(d.normal_id);
        }
        if (d.uv_id >= 0) {
            prim.attributes["TEXCOORD_0"] = add_accessor(model, -1, 0, TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC2, part.vertex_count);
            draco_attributes["TEXCOORD_0"] = tinygltf::Value(d.uv_id);
        }
        if (d.color_id >= 0) {
            prim.attributes["COLOR_0"] = add_accessor(model, -1, 0, TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE, TINYGLTF_TYPE_VEC4,
                                                      part.vertex_count, true);
            draco_attributes["COLOR_0"] = tinygltf::Value(d.color_id);
        }
        prim.indices = add_accessor(model, -1, 0,
                                    part.vertex_count <= 65535 ? TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT
                                                               : TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT,
                                    TINYGLTF_TYPE_SCALAR, 3 * part.triangle_count);
        prim.material = material_ids[std::size_t(part.material + 1)];
        prim.extensions[kDracoExtension] =
            json_object({{"bufferView", tinygltf::Value(view)}, {"attributes", tinygltf::Value(draco_attributes)}});
        out.primitives.push_back(prim);
    }
}

// Gaussians as a point primitive with the KHR_gaussian_splatting extension, as its ratified text (KhronosGroup/glTF,
// extensions/2.0/Khronos/KHR_gaussian_splatting, "Complete, Ratified by the Khronos Group") defines it:
//   mode POINTS; POSITION (float VEC3, in glTF's +Y-up frame: the caller converts); KHR_gaussian_splatting:ROTATION
//   (unit quaternion "in the order (x, y, z, w), where w is the scalar component"), :SCALE (linear standard
//   deviations, the activated values), :OPACITY ("normalized value between 0.0 and 1.0 ... Out-of-range values are
//   invalid": the sigmoid already applied, clamped here), :SH_DEGREE_l_COEF_n (n = 0 .. 2l, RGB each, the 3DGS basis;
//   degree 0 always, each degree complete); COLOR_0 as the optional point-cloud fallback (diffuse colour, linear as
//   glTF's COLOR_0 is, alpha = opacity); the extension object's required `kernel` ("ellipse") and `colorSpace`
//   ("srgb_rec709_display": 3DGS scenes are trained on display-referred sRGB images).
void add_gaussians(tinygltf::Model& model, BufferLayout& layout, const GaussianCloud& cloud, tinygltf::Mesh& out) {
    const std::size_t n = cloud.size();
    if (!n) return;
    use_extension(model, kSplatExtension, false);
    tinygltf::Primitive prim;
    prim.mode = TINYGLTF_MODE_POINTS;
    auto float_attribute = [&](const std::string& name, int type, int width, std::function<void(std::size_t, float*)> get) {
        const std::size_t size = 4 * std::size_t(width) * n;
        const int view = add_buffer_view(model, layout.add(size, [n, width, get](std::uint8_t* d) {
            auto* f = reinterpret_cast<float*>(d);
            tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 1 << 14), [&](const tbb::blocked_range<std::size_t>& r) {
                for (std::size_t i = r.begin(); i < r.end(); ++i) get(i, f + std::size_t(width) * i);
            });
        }), size, 4 * width, kArrayBuffer);
        const int acc = add_accessor(model, view, 0, TINYGLTF_COMPONENT_TYPE_FLOAT, type, n);
        prim.attributes[name] = acc;
        return acc;
    };
    const int pos = float_attribute("POSITION", TINYGLTF_TYPE_VEC3, 3, [&cloud](std::size_t i, float* o) {
        std::memcpy(o, &cloud.positions[3 * i], 12);
    });
    {
        std::vector<double> lo(3, std::numeric_limits<double>::max()), hi(3, -std::numeric_limits<double>::max());
        for (std::size_t i = 0; i < n; ++i)
            for (int c = 0; c < 3; ++c)
                lo[c] = std::min(lo[c], double(cloud.positions[3 * i + c])), hi[c] = std::max(hi[c], double(cloud.positions[3 * i + c]));
        model.accessors[pos].minValues = lo;
        model.accessors[pos].maxValues = hi;
    }
    const int coeffs = cloud.coeffs_per_channel();
    float_attribute("COLOR_0", TINYGLTF_TYPE_VEC4, 4, [&cloud, coeffs](std::size_t i, float* o) {
        for (int c = 0; c < 3; ++c)
            o[c] = sh_dc_to_linear_unit(cloud.sh[std::size_t(coeffs) * 3 * i + c]);
        o[3] = std::min(1.0f, std::max(0.0f, cloud.opacities[i]));
    });
    float_attribute(std::string(kSplatExtension) + ":ROTATION", TINYGLTF_TYPE_VEC4, 4, [&cloud](std::size_t i, float* o) {
        const float* q = &cloud.rotations[4 * i];  // w x y z -> x y z w
        o[0] = q[1], o[1] = q[2], o[2] = q[3], o[3] = q[0];
    });
    float_attribute(std::string(kSplatExtension) + ":SCALE", TINYGLTF_TYPE_VEC3, 3, [&cloud](std::size_t i, float* o) {
        for (int c = 0; c < 3; ++c) o[c] = std::max(0.0f, cloud.scales[3 * i + std::size_t(c)]);  // "MUST NOT be negative"
    });
    float_attribute(std::string(kSplatExtension) + ":OPACITY", TINYGLTF_TYPE_SCALAR, 1, [&cloud](std::size_t i, float* o) {
        o[0] = std::min(1.0f, std::max(0.0f, cloud.opacities[i]));
    });
    for (int k = 0; k < coeffs; ++k) {
        const int l = k == 0 ? 0 : k < 4 ? 1 : k < 9 ? 2 : 3;
        const int m = k - l * l;
        float_attribute(std::string(kSplatExtension) + ":SH_DEGREE_" + std::to_string(l) + "_COEF_" + std::to_string(m),
                        TINYGLTF_TYPE_VEC3, 3, [&cloud, coeffs, k](std::size_t i, float* o) {
                            std::memcpy(o, &cloud.sh[(std::size_t(coeffs) * i + std::size_t(k)) * 3], 12);
                        });
    }
    prim.extensions[kSplatExtension] = json_object({{"kernel", tinygltf::Value(std::string("ellipse"))},
                                                    {"colorSpace", tinygltf::Value(std::string("srgb_rec709_display"))}});
    out.primitives.push_back(prim);
}

bool is_identity(const double m[16]) {
    for (int k = 0; k < 16; ++k)
        if (m[k] != ((k % 5 == 0) ? 1.0 : 0.0)) return false;
    return true;
}

std::string file_name(const std::string& path) {
    const std::size_t slash = os::last_separator(path);
    return slash == std::string::npos ? path : path.substr(slash + 1);
}

}  // namespace

MeshWriteStats write_gltf(const std::string& path, const ExportScene& scene, const MeshWriteOptions& options, bool binary) {
    tinygltf::Model model;
    model.asset.version = "2.0";
    model.asset.generator = "RaySplats";
    BufferLayout layout;
    std::vector<std::shared_ptr<DracoPart>> draco_parts;
    MeshWriteStats stats;

    // Material ids by ExportMeshPart::material + 1 (slot 0: the default material, created when used).
    std::vector<int> material_ids(scene.materials.size() + 1, -1);
    for (const ExportMesh& mesh : scene.meshes)
        for (const ExportMeshPart& p : mesh.parts)
            if (p.material < 0 && p.triangle_count && material_ids[0] < 0) {
                ExportMaterial def;
                def.name = "RaySplats default";
                material_ids[0] = add_material(model, def);
            }
    for (std::size_t m = 0; m < scene.materials.size(); ++m) material_ids[m + 1] = add_material(model, scene.materials[m]);

    tinygltf::Scene gscene;
    for (const ExportMesh& mesh : scene.meshes) {
        if (!mesh.triangle_count()) continue;
        tinygltf::Mesh gmesh;
        gmesh.name = mesh.name;
        if (options.draco.enabled) add_draco_mesh(model, layout, mesh, gmesh, material_ids, options.draco, draco_parts);
        else add_plain_mesh(model, layout, mesh, gmesh, material_ids);
        stats.vertices += mesh.vertex_count();
        stats.triangles += mesh.triangle_count();
        stats.primitives += gmesh.primitives.size();
        model.meshes.push_back(gmesh);
        tinygltf::Node node;
        node.name = mesh.name;
        node.mesh = int(model.meshes.size() - 1);
        if (!is_identity(mesh.node_matrix))
            for (int c = 0; c < 4; ++c)
                for (int r = 0; r < 4; ++r) node.matrix.push_back(mesh.node_matrix[4 * r + c]);  // column-major
        model.nodes.push_back(node);
        gscene.nodes.push_back(int(model.nodes.size() - 1));
    }
    if (options.gaussian_splatting_extension) {
        for (const ExportGaussians& gaussians : scene.gaussians) {
            if (!gaussians.cloud.size()) continue;
            tinygltf::Mesh gmesh;
            gmesh.name = gaussians.name;
            add_gaussians(model, layout, gaussians.cloud, gmesh);
            model.meshes.push_back(gmesh);
            tinygltf::Node node;
            node.name = gaussians.name;
            node.mesh = int(model.meshes.size() - 1);
            if (!is_identity(gaussians.node_matrix))
                for (int c = 0; c < 4; ++c)
                    for (int r = 0; r < 4; ++r) node.matrix.push_back(gaussians.node_matrix[4 * r + c]);  // column-major
            model.nodes.push_back(node);
            gscene.nodes.push_back(int(model.nodes.size() - 1));
            stats.primitives += 1;
        }
    }
    model.scenes.push_back(gscene);
    model.defaultScene = 0;

    const std::size_t buffer_size = layout.size();
    if (binary && buffer_size + (std::size_t(1) << 24) > std::numeric_limits<std::uint32_t>::max())
        throw FileFormatError(path, "the scene needs " + std::to_string(buffer_size) +
                                    " bytes of binary data; a .glb holds less than 4 GiB (use .gltf)");

    // The JSON document from tinygltf, with the buffer (which tinygltf would copy or base64-embed) added here.
    std::string json_text;
    {
        tinygltf::TinyGLTF writer;
        std::ostringstream json_stream;
        if (!writer.WriteGltfSceneToStream(&model, json_stream, !binary, false))
            throw FileFormatError(path, "tinygltf could not serialise the glTF document");
        nlohmann::json doc = nlohmann::json::parse(json_stream.str());
        nlohmann::json buffer = {{"byteLength", buffer_size}};
        const std::string stem = file_name(path).substr(0, file_name(path).find_last_of('.'));
        if (!binary) buffer["uri"] = stem + ".bin";
        doc["buffers"] = nlohmann::json::array({buffer});
        json_text = binary ? doc.dump() : doc.dump(2);
    }

    std::unique_ptr<std::uint8_t[]> bin(new std::uint8_t[std::max<std::size_t>(buffer_size, 1)]);
    layout.fill(bin.get());

    if (binary) {
        const std::size_t json_padded = align4(json_text.size());
        json_text.append(json_padded - json_text.size(), ' ');
        std::uint8_t header[12 + 8], bin_header[8];
        std::memcpy(header, "glTF", 4);
        store_u32le(header + 4, 2);
        store_u32le(header + 8, std::uint32_t(12 + 8 + json_padded + 8 + buffer_size));
        store_u32le(header + 12, std::uint32_t(json_padded));
        store_u32le(header + 16, 0x4E4F534Au);  // "JSON"
        store_u32le(bin_header, std::uint32_t(buffer_size));
        store_u32le(bin_header + 4, 0x004E4942u);  // "BIN\0"
        AtomicFileWriter file(path);
        file.write(header, sizeof(header));
        file.write(json_text.data(), json_text.size());
        file.write(bin_header, sizeof(bin_header));
        file.write(bin.get(), buffer_size);
        file.commit();
        stats.bytes = sizeof(header) + json_text.size() + sizeof(bin_header) + buffer_size;
    } else {
        const std::size_t slash = os::last_separator(path);
        const std::string stem = file_name(path).substr(0, file_name(path).find_last_of('.'));
        const std::string bin_path = (slash == std::string::npos ? std::string() : path.substr(0, slash + 1)) + stem + ".bin";
        AtomicFileWriter bin_file(bin_path);
        bin_file.write(bin.get(), buffer_size);
        AtomicFileWriter file(path);
        file.write(json_text.data(), json_text.size());
        bin_file.commit();
        file.commit();
        stats.bytes = json_text.size() + buffer_size;
    }
    return stats;
}

}  // namespace io
}  // namespace raysplats
