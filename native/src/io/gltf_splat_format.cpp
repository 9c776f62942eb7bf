// glTF 2.0 reader of KHR_gaussian_splatting point primitives (.glb, .gltf with its buffers).
//
// Checked against the ratified extension text (KhronosGroup/glTF, extensions/2.0/Khronos/KHR_gaussian_splatting,
// "Status: Complete, Ratified by the Khronos Group"):
//   - a primitive whose `extensions` hold KHR_gaussian_splatting is a Gaussian field; its mode must be POINTS;
//   - POSITION (float VEC3, base glTF), KHR_gaussian_splatting:ROTATION (VEC4 x y z w, unit quaternion; float or
//     normalised signed byte / short), :SCALE (VEC3, linear standard deviations; float, signed byte / short, plain or
//     normalised), :OPACITY (SCALAR in [0, 1], sigmoid already applied; float or normalised unsigned byte / short)
//     and :SH_DEGREE_0_COEF_0 (float VEC3) are required; :SH_DEGREE_l_COEF_n (n = 0 .. 2l) hold the higher SH bands
//     in the 3DGS basis, each degree complete and every lower degree present;
//   - `kernel` ("ellipse") and `colorSpace` ("srgb_rec709_display" or "lin_rec709_display") are required;
//   - positions are in glTF's frame (+Y up, right-handed) and placed by their node's world transform.
// The cloud comes out in the core's RDF like every reader's: glTF -> RDF is F = diag(1, -1, -1), a 180° rotation
// about x (the same as SPZ's RUB), applied after the node transform.
//
// Hostile files: tinygltf parses the JSON and checks buffers against their byteLength (external .bin files must be
// regular files); every accessor read here is bounds-checked against its bufferView and buffer before any splat is
// allocated, so memory stays proportional to the file (a mesh placed by many nodes is capped, see kMaxInstancing).
#define TINYGLTF_NO_STB_IMAGE
#define TINYGLTF_NO_STB_IMAGE_WRITE
#define TINYGLTF_NO_EXTERNAL_IMAGE
#include <tiny_gltf.h>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <array>
#include <cmath>
#include <cstring>
#include <fstream>
#include <functional>

#include "core/linear_algebra.h"
#include "core/os_files.h"
#include "io/io_common.h"
#include "io/splat_formats.h"
#include "raysplats/gltf_contents.h"
#include "raysplats/spherical_harmonics.h"

namespace raysplats {
namespace io {
namespace {

using namespace la;

constexpr const char* kExtension = "KHR_gaussian_splatting";
// The splats placed by all nodes together may be at most this many times those the file stores: beyond it a small
// file could ask for any amount of memory by instancing one mesh.
constexpr std::size_t kMaxInstancing = 16;
constexpr int kMaxNodeDepth = 256;

std::string attribute(const std::string& name) { return std::string(kExtension) + ":" + name; }
std::string sh_attribute(int degree, int coefficient) {
    return attribute("SH_DEGREE_" + std::to_string(degree) + "_COEF_" + std::to_string(coefficient));
}

bool is_splat_primitive(const tinygltf::Primitive& p) { return p.extensions.count(kExtension) != 0; }

// --- File access for tinygltf: regular files only (no /dev/zero, no FIFOs), read whole.
// Exists (whatever kind of file): fs_read then refuses what is not a regular file, with a message that says so.
bool fs_file_exists(const std::string& path, void*) { return os::path_status(path).exists; }
std::string fs_expand(const std::string& path, void*) { return path; }
bool fs_read(std::vector<unsigned char>* out, std::string* err, const std::string& path, void*) {
    if (!os::path_status(path).is_regular_file) {
        if (err) *err += "buffer file '" + path + "' is missing or not a regular file\n";
        return false;
    }
    try {
        FileBytes bytes(path);
        out->assign(bytes.data(), bytes.data() + bytes.size());
    } catch (const FileFormatError& e) {
        if (err) *err += std::string(e.what()) + "\n";
        return false;
    }
    return true;
}
bool fs_write(std::string* err, const std::string&, const std::vector<unsigned char>&, void*) {
    if (err) *err += "writing is not allowed while reading\n";
    return false;
}
// Images are not needed for splats: accept them without decoding.
bool ignore_image(tinygltf::Image*, const int, std::string*, std::string*, int, int, const unsigned char*, int, void*) {
    return true;
}

tinygltf::Model load_model(const std::string& name, const std::uint8_t* data, std::size_t size, const std::string& base_dir,
                           bool allow_files) {
    if (size == 0) throw FileFormatError(name, "file is empty");
    if (size > std::numeric_limits<unsigned int>::max())
        throw FileFormatError(name, "a glTF file larger than 4 GiB cannot be read");
    tinygltf::TinyGLTF loader;
    tinygltf::FsCallbacks fs{};
    // From memory, every external file "exists" so that reading it gives the message below, not "not found".
    fs.FileExists = allow_files ? fs_file_exists : [](const std::string&, void*) { return true; };
    fs.ExpandFilePath = fs_expand;
    fs.ReadWholeFile = allow_files ? fs_read : [](std::vector<unsigned char>*, std::string* err, const std::string& p, void*) {
        if (err) *err += "external buffer '" + p + "' cannot be read from memory\n";
        return false;
    };
    fs.WriteWholeFile = fs_write;
    fs.user_data = nullptr;
    loader.SetFsCallbacks(fs);
    loader.SetImageLoader(ignore_image, nullptr);
    tinygltf::Model model;
    std::string err, warn;
    const bool binary = size >= 4 && std::memcmp(data, "glTF", 4) == 0;
    bool ok = false;
    try {
        ok = binary ? loader.LoadBinaryFromMemory(&model, &err, &warn, data, static_cast<unsigned int>(size), base_dir)
                    : loader.LoadASCIIFromString(&model, &err, &warn, reinterpret_cast<const char*>(data),
                                                 static_cast<unsigned int>(size), base_dir);
    } catch (const std::exception& e) {  // nlohmann::json throws on some malformed documents
        throw FileFormatError(name, std::string("not a valid glTF file: ") + e.what());
    }
    if (!ok) {
        while (!err.empty() && err.back() == '\n') err.pop_back();
        throw FileFormatError(name, "not a valid glTF file: " + (err.empty() ? std::string("tinygltf refused it") : err));
    }
    return model;
}

// A bounds-checked view of one accessor: element i, component c as float (glTF's normalisation rules, glTF 2.0
// §3.11 "Animations"/"Accessor" normalised integer conversion: max(c / (2^(b-1) - 1), -1) signed, c / (2^b - 1)).
struct AccessorReader {
    const std::uint8_t* base = nullptr;
    std::size_t stride = 0, count = 0;
    int component = 0, width = 0;
    bool normalized = false;

    float get(std::size_t i, int c) const {
        const std::uint8_t* p = base + i * stride;
        switch (component) {
            case TINYGLTF_COMPONENT_TYPE_FLOAT: {
                float v;
                std::memcpy(&v, p + 4 * c, 4);
                return v;
            }
            case TINYGLTF_COMPONENT_TYPE_BYTE: {
                const float v = float(std::int8_t(p[c]));
                return normalized ? std::max(v / 127.0f, -1.0f) : v;
            }
            case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: {
                const float v = float(p[c]);
                return normalized ? v / 255.0f : v;
            }
            case TINYGLTF_COMPONENT_TYPE_SHORT: {
                std::int16_t s;
                std::memcpy(&s, p + 2 * c, 2);
                return normalized ? std::max(float(s) / 32767.0f, -1.0f) : float(s);
            }
            case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: {
                std::uint16_t s;
                std::memcpy(&s, p + 2 * c, 2);
                return normalized ? float(s) / 65535.0f : float(s);
            }
        }
        return 0.0f;
    }
};

// What component types an attribute may have (the ratified extension's attribute table), as (type, normalized).
struct AllowedType {
    int component;
    bool normalized;
};

AccessorReader accessor_reader(const std::string& name, const tinygltf::Model& model, int index, const std::string& what,
                               int type, const std::vector<AllowedType>& allowed) {
    if (index < 0 || std::size_t(index) >= model.accessors.size())
        throw FileFormatError(name, what + ": accessor " + std::to_string(index) + " does not exist");
    const tinygltf::Accessor& a = model.accessors[std::size_t(index)];
    const std::string where = what + " (accessor " + std::to_string(index) + ")";
    if (a.sparse.isSparse) throw FileFormatError(name, where + ": sparse accessors are not supported for splats");
    if (a.type != type)
        throw FileFormatError(name, where + ": type must be " + (type == TINYGLTF_TYPE_SCALAR ? "SCALAR" : "VEC" + std::to_string(type)));
    bool type_ok = false;
    for (const AllowedType& t : allowed) type_ok |= t.component == a.componentType && t.normalized == a.normalized;
    if (!type_ok)
        throw FileFormatError(name, where + ": component type " + std::to_string(a.componentType) +
                                        (a.normalized ? " (normalized)" : "") + " is not allowed by KHR_gaussian_splatting");
    if (a.bufferView < 0 || std::size_t(a.bufferView) >= model.bufferViews.size())
        throw FileFormatError(name, where + ": has no valid bufferView (accessors without data are not supported)");
    const tinygltf::BufferView& view = model.bufferViews[std::size_t(a.bufferView)];
    if (view.buffer < 0 || std::size_t(view.buffer) >= model.buffers.size())
        throw FileFormatError(name, where + ": its bufferView names buffer " + std::to_string(view.buffer) + ", which does not exist");
    const std::vector<unsigned char>& buffer = model.buffers[std::size_t(view.buffer)].data;
    const int component_size = tinygltf::GetComponentSizeInBytes(std::uint32_t(a.componentType));
    const int components = tinygltf::GetNumComponentsInType(std::uint32_t(a.type));
    const std::size_t element = std::size_t(component_size) * std::size_t(components);
    const std::size_t stride = view.byteStride ? view.byteStride : element;
    if (stride < element) throw FileFormatError(name, where + ": byteStride is smaller than one element");
    // view range within the buffer, then accessor range within the view (no overflow: each term is checked first).
    if (view.byteOffset > buffer.size() || view.byteLength > buffer.size() - view.byteOffset)
        throw FileFormatError(name, where + ": its bufferView (offset " + std::to_string(view.byteOffset) + ", length " +
                                        std::to_string(view.byteLength) + ") lies beyond its buffer of " +
                                        std::to_string(buffer.size()) + " bytes");
    if (a.count == 0) throw FileFormatError(name, where + ": count is 0");
    const std::size_t available = view.byteLength;
    if (a.byteOffset > available || element > available - a.byteOffset ||
        (a.count - 1) > (available - a.byteOffset - element) / stride)
        throw FileFormatError(name, where + ": " + std::to_string(a.count) + " elements do not fit in its bufferView of " +
                                        std::to_string(view.byteLength) + " bytes");
    AccessorReader r;
    r.base = buffer.data() + view.byteOffset + a.byteOffset;
    r.stride = stride;
    r.count = a.count;
    r.component = a.componentType;
    r.width = components;
    r.normalized = a.normalized;
    return r;
}

// One splat primitive, checked: its accessors and SH degree.
struct SplatPrimitive {
    AccessorReader position, rotation, scale, opacity;
    std::vector<AccessorReader> sh;  // (degree + 1)^2 coefficients
    int degree = 0;
    std::size_t count = 0;
};

SplatPrimitive check_splat_primitive(const std::string& name, const tinygltf::Model& model, const tinygltf::Primitive& p,
                                     const std::string& where, LoadReport* report) {
    if (p.mode != TINYGLTF_MODE_POINTS)
        throw FileFormatError(name, where + ": a KHR_gaussian_splatting primitive must have mode POINTS (0), not " +
                                        std::to_string(p.mode));
    auto index_of = [&](const std::string& semantic, bool required) {
        const auto it = p.attributes.find(semantic);
        if (it == p.attributes.end()) {
            if (required) throw FileFormatError(name, where + ": the required attribute " + semantic + " is missing");
            return -1;
        }
        return it->second;
    };
    const std::vector<AllowedType> floats{{TINYGLTF_COMPONENT_TYPE_FLOAT, false}};
    SplatPrimitive s;
    s.position = accessor_reader(name, model, index_of("POSITION", true), where + " POSITION", TINYGLTF_TYPE_VEC3, floats);
    s.rotation = accessor_reader(name, model, index_of(attribute("ROTATION"), true), where + " ROTATION", TINYGLTF_TYPE_VEC4,
                                 {{TINYGLTF_COMPONENT_TYPE_FLOAT, false},
                                  {TINYGLTF_COMPONENT_TYPE_BYTE, true},
                                  {TINYGLTF_COMPONENT_TYPE_SHORT, true}});
    s.scale = accessor_reader(name, model, index_of(attribute("SCALE"), true), where + " SCALE", TINYGLTF_TYPE_VEC3,
                              {{TINYGLTF_COMPONENT_TYPE_FLOAT, false},
                               {TINYGLTF_COMPONENT_TYPE_BYTE, false},
                               {TINYGLTF_COMPONENT_TYPE_BYTE, true},
                               {TINYGLTF_COMPONENT_TYPE_SHORT, false},
                               {TINYGLTF_COMPONENT_TYPE_SHORT, true}});
    s.opacity = accessor_reader(name, model, index_of(attribute("OPACITY"), true), where + " OPACITY", TINYGLTF_TYPE_SCALAR,
                                {{TINYGLTF_COMPONENT_TYPE_FLOAT, false},
                                 {TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE, true},
                                 {TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT, true}});
    // Degrees: 0 is required; each further one complete, and only on top of the ones below it.
    s.degree = -1;
    for (int l = 0; l <= 3; ++l) {
        int present = 0;
        for (int m = 0; m <= 2 * l; ++m) present += p.attributes.count(sh_attribute(l, m)) ? 1 : 0;
        if (present == 0) break;
        if (present != 2 * l + 1)
            throw FileFormatError(name, where + ": spherical harmonics degree " + std::to_string(l) + " is partially defined (" +
                                            std::to_string(present) + " of " + std::to_string(2 * l + 1) + " coefficients)");
        s.degree = l;
    }
    if (s.degree < 0)
        throw FileFormatError(name, where + ": the required attribute " + sh_attribute(0, 0) +
                                        " is missing (other lighting methods are not supported)");
    for (const auto& kv : p.attributes) {
        const std::string prefix = attribute("SH_DEGREE_");
        if (kv.first.compare(0, prefix.size(), prefix) != 0) continue;
        const int l = kv.first.size() > prefix.size() ? kv.first[prefix.size()] - '0' : -1;
        if (l > s.degree)
            throw FileFormatError(name, where + ": " + kv.first + " is present but a lower spherical harmonics degree is not");
    }
    for (int l = 0; l <= s.degree; ++l)
        for (int m = 0; m <= 2 * l; ++m)
            s.sh.push_back(accessor_reader(name, model, index_of(sh_attribute(l, m), true),
                                           where + " " + sh_attribute(l, m).substr(std::strlen(kExtension) + 1),
                                           TINYGLTF_TYPE_VEC3, floats));
    s.count = s.position.count;
    std::vector<const AccessorReader*> all{&s.rotation, &s.scale, &s.opacity};
    for (const AccessorReader& a : s.sh) all.push_back(&a);
    for (const AccessorReader* a : all)
        if (a->count != s.count)
            throw FileFormatError(name, where + ": its attributes have different counts (" + std::to_string(a->count) +
                                            " and POSITION's " + std::to_string(s.count) + ")");
    // The extension object: kernel and colour space (required by the ratified text; older drafts lack them).
    const tinygltf::Value& ext = p.extensions.at(kExtension);
    auto string_property = [&](const char* key) -> std::string {
        if (!ext.IsObject() || !ext.Has(key) || !ext.Get(key).IsString()) return "";
        return ext.Get(key).Get<std::string>();
    };
    const std::string kernel = string_property("kernel"), color_space = string_property("colorSpace");
    if (report) {
        if (kernel != "ellipse")
            report->warnings.push_back(where + ": kernel '" + kernel + "' is not 'ellipse'; the splats are read as ellipse Gaussians");
        if (color_space == "lin_rec709_display")
            report->warnings.push_back(where + ": colour space lin_rec709_display: the SH are read as they are, which "
                                               "RaySplats treats as srgb_rec709_display (colours look darker)");
        else if (color_space != "srgb_rec709_display")
            report->warnings.push_back(where + ": colour space '" + color_space +
                                       "' (missing or unknown) read as srgb_rec709_display");
    }
    return s;
}

// Row-major 4x4 local matrix of a node (matrix, or T * R * S).
std::array<double, 16> local_matrix(const tinygltf::Node& node) {
    std::array<double, 16> m{1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
    if (node.matrix.size() == 16) {
        for (int r = 0; r < 4; ++r)
            for (int c = 0; c < 4; ++c) m[std::size_t(4 * r + c)] = node.matrix[std::size_t(4 * c + r)];  // column-major
        return m;
    }
    double q[4] = {1, 0, 0, 0};  // w x y z
    if (node.rotation.size() == 4) q[0] = node.rotation[3], q[1] = node.rotation[0], q[2] = node.rotation[1], q[3] = node.rotation[2];
    const double qn = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    if (qn > 0)
        for (double& v : q) v /= qn;
    const std::array<double, 9> rot = quaternion_to_rotation<double>(q[0], q[1], q[2], q[3]);
    const double s[3] = {node.scale.size() == 3 ? node.scale[0] : 1.0, node.scale.size() == 3 ? node.scale[1] : 1.0,
                         node.scale.size() == 3 ? node.scale[2] : 1.0};
    for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c) m[std::size_t(4 * r + c)] = rot[std::size_t(3 * r + c)] * s[c];
        m[std::size_t(4 * r + 3)] = node.translation.size() == 3 ? node.translation[std::size_t(r)] : 0.0;
    }
    return m;
}

std::array<double, 16> multiply(const std::array<double, 16>& a, const std::array<double, 16>& b) {
    std::array<double, 16> m{};
    for (int r = 0; r < 4; ++r)
        for (int c = 0; c < 4; ++c)
            for (int k = 0; k < 4; ++k) m[std::size_t(4 * r + c)] += a[std::size_t(4 * r + k)] * b[std::size_t(4 * k + c)];
    return m;
}

// A splat primitive placed by a node: the primitive and its world matrix (glTF frame).
struct Placement {
    const SplatPrimitive* primitive;
    std::array<double, 16> world;
};

// Writes the splats of `s` placed by `world` and converted to RDF into `cloud` from index `offset`.
void place_splats(const SplatPrimitive& s, const std::array<double, 16>& world, GaussianCloud& cloud, std::size_t offset) {
    // A = F * L (F = diag(1, -1, -1): glTF -> RDF), t' = F * t.
    Mat3 a;
    double t[3];
    for (int r = 0; r < 3; ++r) {
        const double f = r == 0 ? 1.0 : -1.0;
        for (int c = 0; c < 3; ++c) a(r, c) = f * world[std::size_t(4 * r + c)];
        t[r] = f * world[std::size_t(4 * r + 3)];
    }
    // The rotation part Q of A (polar decomposition A = Q P, by Higham's iteration Q <- (Q + Q^-T) / 2), and whether
    // A is a similarity (A^T A = s^2 I): then Gaussians keep their axes, rotated by Q, scaled by s.
    Mat3 q = a;
    for (int it = 0; it < 64; ++it) {
        const double d = determinant(q);
        if (!(std::fabs(d) > 1e-300)) break;
        Mat3 inv_t;  // (Q^-1)^T = cofactor(Q) / det
        inv_t(0, 0) = (q(1, 1) * q(2, 2) - q(1, 2) * q(2, 1)) / d;
        inv_t(0, 1) = (q(1, 2) * q(2, 0) - q(1, 0) * q(2, 2)) / d;
        inv_t(0, 2) = (q(1, 0) * q(2, 1) - q(1, 1) * q(2, 0)) / d;
        inv_t(1, 0) = (q(0, 2) * q(2, 1) - q(0, 1) * q(2, 2)) / d;
        inv_t(1, 1) = (q(0, 0) * q(2, 2) - q(0, 2) * q(2, 0)) / d;
        inv_t(1, 2) = (q(0, 1) * q(2, 0) - q(0, 0) * q(2, 1)) / d;
        inv_t(2, 0) = (q(0, 1) * q(1, 2) - q(0, 2) * q(1, 1)) / d;
        inv_t(2, 1) = (q(0, 2) * q(1, 0) - q(0, 0) * q(1, 2)) / d;
        inv_t(2, 2) = (q(0, 0) * q(1, 1) - q(0, 1) * q(1, 0)) / d;
        double change = 0.0;
        for (int k = 0; k < 9; ++k) {
            const double next = 0.5 * (q.m[k] + inv_t.m[k]);
            change = std::max(change, std::fabs(next - q.m[k]));
            q.m[k] = next;
        }
        if (change < 1e-15) break;
    }
    const bool reflection = determinant(q) < 0;
    Mat3 q_proper = q;  // Q = Q' diag(1, 1, -1) when Q is a reflection
    if (reflection)
        for (int r = 0; r < 3; ++r) q_proper(r, 2) = -q_proper(r, 2);
    const Mat3 ata = transpose(a) * a;
    const double s2 = (ata(0, 0) + ata(1, 1) + ata(2, 2)) / 3.0;
    bool similarity = !reflection && s2 > 0;
    for (int r = 0; r < 3 && similarity; ++r)
        for (int c = 0; c < 3; ++c) similarity &= std::fabs(ata(r, c) - (r == c ? s2 : 0.0)) <= 1e-9 * s2;
    const double uniform = std::sqrt(s2);
    double qa[4];
    matrix_to_quaternion(q_proper, qa);
    double rot_row_major[9];
    for (int k = 0; k < 9; ++k) rot_row_major[k] = q_proper.m[k];
    const int degree = s.degree;
    const std::size_t coeffs = std::size_t(sh_coeff_count(degree));
    const std::size_t out_coeffs = std::size_t(cloud.coeffs_per_channel());

    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, s.count, kGrain), [&](const tbb::blocked_range<std::size_t>& range) {
        float sh[48];
        for (std::size_t i = range.begin(); i != range.end(); ++i) {
            const std::size_t o = offset + i;
            double p[3];
            for (int c = 0; c < 3; ++c) p[c] = s.position.get(i, c);
            for (int r = 0; r < 3; ++r)
                cloud.positions[3 * o + std::size_t(r)] = float(a(r, 0) * p[0] + a(r, 1) * p[1] + a(r, 2) * p[2] + t[r]);
            // glTF x y z w -> w x y z
            double g[4] = {s.rotation.get(i, 3), s.rotation.get(i, 0), s.rotation.get(i, 1), s.rotation.get(i, 2)};
            const double gn = std::sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2] + g[3] * g[3]);
            if (gn > 0)
                for (double& v : g) v /= gn;
            double sc[3] = {s.scale.get(i, 0), s.scale.get(i, 1), s.scale.get(i, 2)};
            float* rq = &cloud.rotations[4 * o];
            float* rs = &cloud.scales[3 * o];
            if (similarity || !(gn > 0)) {
                // q' = qa * g (Hamilton product, w first); scales times the uniform factor.
                const double w = qa[0] * g[0] - qa[1] * g[1] - qa[2] * g[2] - qa[3] * g[3];
                const double x = qa[0] * g[1] + qa[1] * g[0] + qa[2] * g[3] - qa[3] * g[2];
                const double y = qa[0] * g[2] - qa[1] * g[3] + qa[2] * g[0] + qa[3] * g[1];
                const double z = qa[0] * g[3] + qa[1] * g[2] - qa[2] * g[1] + qa[3] * g[0];
                rq[0] = float(w), rq[1] = float(x), rq[2] = float(y), rq[3] = float(z);
                for (int c = 0; c < 3; ++c) rs[c] = float(std::fabs(sc[c]) * uniform);
            } else {
                // Any other linear map: Σ' = A R S² R^T A^T, and its eigen-decomposition gives the new axes.
                const Mat3 r = quaternion_to_matrix(g[0], g[1], g[2], g[3]);
                Mat3 m = a * r;
                for (int row = 0; row < 3; ++row)
                    for (int c = 0; c < 3; ++c) m(row, c) *= sc[c];
                const Mat3 cov = m * transpose(m);
                double values[3];
                Mat3 v;
                symmetric_eigen(cov, values, v);
                double qv[4];
                matrix_to_quaternion(v, qv);
                for (int k = 0; k < 4; ++k) rq[k] = float(qv[k]);
                for (int c = 0; c < 3; ++c) rs[c] = float(std::sqrt(std::max(values[c], 0.0)));
            }
            cloud.opacities[o] = s.opacity.get(i, 0);
            for (std::size_t k = 0; k < coeffs; ++k)
                for (int c = 0; c < 3; ++c) sh[3 * k + std::size_t(c)] = s.sh[k].get(i, c);
            // f'(d) = f(Q^T d): reflect first when Q = Q' diag(1, 1, -1), then rotate by Q'.
            if (reflection) reflect_sh(degree, false, false, true, sh);
            if (degree > 0) rotate_sh(degree, rot_row_major, sh, sh);
            float* out = &cloud.sh[o * out_coeffs * 3];
            std::memcpy(out, sh, coeffs * 3 * sizeof(float));
            std::memset(out + coeffs * 3, 0, (out_coeffs - coeffs) * 3 * sizeof(float));
        }
    });
}

// The splat primitives and where the default scene places them.
struct SplatScene {
    std::vector<SplatPrimitive> primitives;
    std::vector<Placement> placements;
    std::size_t stored = 0, placed = 0;
    int degree = 0;
};

SplatScene collect(const std::string& name, const tinygltf::Model& model, LoadReport* report) {
    SplatScene scene;
    // Primitive index per (mesh, primitive).
    std::vector<std::vector<int>> index(model.meshes.size());
    std::size_t total = 0;
    for (std::size_t m = 0; m < model.meshes.size(); ++m)
        for (const tinygltf::Primitive& p : model.meshes[m].primitives) total += is_splat_primitive(p) ? 1 : 0;
    scene.primitives.reserve(total);
    for (std::size_t m = 0; m < model.meshes.size(); ++m)
        for (std::size_t k = 0; k < model.meshes[m].primitives.size(); ++k) {
            const tinygltf::Primitive& p = model.meshes[m].primitives[k];
            if (!is_splat_primitive(p)) {
                index[m].push_back(-1);
                continue;
            }
            const std::string where = "mesh " + std::to_string(m) +
                                      (model.meshes[m].name.empty() ? "" : " '" + model.meshes[m].name + "'") + " primitive " +
                                      std::to_string(k);
            scene.primitives.push_back(check_splat_primitive(name, model, p, where, report));
            index[m].push_back(int(scene.primitives.size() - 1));
            scene.stored += scene.primitives.back().count;
            scene.degree = std::max(scene.degree, scene.primitives.back().degree);
        }
    if (scene.primitives.empty())
        throw FileFormatError(name, "has no KHR_gaussian_splatting primitives (no Gaussian splats): import it with "
                                    "File > Import > glTF 2.0");
    // Nodes of the default scene (or of scene 0, or every root node when there are no scenes), depth first.
    std::vector<int> roots;
    if (!model.scenes.empty()) {
        const std::size_t s = model.defaultScene >= 0 && std::size_t(model.defaultScene) < model.scenes.size()
                                  ? std::size_t(model.defaultScene) : 0;
        roots = model.scenes[s].nodes;
    } else {
        std::vector<char> is_child(model.nodes.size(), 0);
        for (const tinygltf::Node& n : model.nodes)
            for (int c : n.children)
                if (c >= 0 && std::size_t(c) < model.nodes.size()) is_child[std::size_t(c)] = 1;
        for (std::size_t n = 0; n < model.nodes.size(); ++n)
            if (!is_child[n]) roots.push_back(int(n));
    }
    std::vector<char> on_path(model.nodes.size(), 0);
    const std::size_t cap = kMaxInstancing * scene.stored;
    std::function<void(int, const std::array<double, 16>&, int)> visit = [&](int n, const std::array<double, 16>& parent, int depth) {
        if (n < 0 || std::size_t(n) >= model.nodes.size())
            throw FileFormatError(name, "node " + std::to_string(n) + " does not exist");
        if (on_path[std::size_t(n)] || depth > kMaxNodeDepth)
            throw FileFormatError(name, "the node hierarchy has a cycle or is deeper than " + std::to_string(kMaxNodeDepth) +
                                            " (at node " + std::to_string(n) + ")");
        on_path[std::size_t(n)] = 1;
        const tinygltf::Node& node = model.nodes[std::size_t(n)];
        const std::array<double, 16> world = multiply(parent, local_matrix(node));
        for (double v : world)
            if (!std::isfinite(v)) throw FileFormatError(name, "node " + std::to_string(n) + " has a non-finite transform");
        if (node.mesh >= 0 && std::size_t(node.mesh) < model.meshes.size())
            for (int k : index[std::size_t(node.mesh)]) {
                if (k < 0) continue;
                scene.placed += scene.primitives[std::size_t(k)].count;
                if (scene.placed > cap)
                    throw FileFormatError(name, "its nodes place the file's " + std::to_string(scene.stored) +
                                                    " splats more than " + std::to_string(kMaxInstancing) + " times over");
                scene.placements.push_back({&scene.primitives[std::size_t(k)], world});
            }
        for (int c : node.children) visit(c, world, depth + 1);
        on_path[std::size_t(n)] = 0;
    };
    const std::array<double, 16> identity{1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
    for (int r : roots) visit(r, identity, 0);
    if (scene.placements.empty())
        throw FileFormatError(name, "its KHR_gaussian_splatting primitives are not placed by any node of the scene");
    return scene;
}

GaussianCloud read_model(const std::string& name, const tinygltf::Model& model, const ReadOptions& options, LoadReport* report) {
    LoadReport local;
    SplatScene scene = collect(name, model, &local);
    GaussianCloud cloud;
    cloud.resize(scene.placed, scene.degree);
    std::size_t offset = 0;
    for (const Placement& p : scene.placements) {
        place_splats(*p.primitive, p.world, cloud, offset);
        offset += p.primitive->count;
    }
    std::size_t clamped = 0;
    for (float& o : cloud.opacities)
        if (o < 0.0f || o > 1.0f) o = std::min(1.0f, std::max(0.0f, o)), ++clamped;
    finalize_cloud(cloud, options, report);
    if (report) {
        if (clamped)
            local.warnings.push_back(std::to_string(clamped) + " opacity value(s) outside [0, 1] (invalid in "
                                     "KHR_gaussian_splatting) clamped");
        report->warnings.insert(report->warnings.begin(), local.warnings.begin(), local.warnings.end());
    }
    return cloud;
}

std::string folder_of(const std::string& path) {
    const std::size_t slash = os::last_separator(path);
    return slash == std::string::npos ? std::string(".") : path.substr(0, slash);
}

}  // namespace

// Bytes in memory have no folder: their buffers must be inside them (a .glb, data: URIs).
tinygltf::Model load_model(const FileBytes& f) {
    return f.in_memory() ? load_model(f.path(), f.data(), f.size(), "", false)
                         : load_model(f.path(), f.data(), f.size(), folder_of(f.path()), true);
}

GaussianCloud read_gltf_splats(const FileBytes& f, const ReadOptions& options, LoadReport* report) {
    const tinygltf::Model model = load_model(f);
    return read_model(f.path(), model, options, report);
}

// The binary container's 'glTF' magic (under a .splat name with its version, 2), or a .gltf name (JSON: no magic).
Evidence detect_gltf(const std::uint8_t* d, std::size_t size, const std::string& name, bool headerless_name) {
    const bool glb = headerless_name ? starts_with(d, size, "glTF", 4) && size >= 8 && load_u32le(d + 4) == 2
                                     : starts_with(d, size, "glTF", 4);
    if (glb) return Evidence::Signature;
    return lower_extension(name) == ".gltf" ? Evidence::Name : Evidence::None;
}

SplatFileSummary probe_gltf(const FileBytes& f) {
    const tinygltf::Model model = load_model(f);
    LoadReport ignored;
    const SplatScene scene = collect(f.path(), model, &ignored);
    return {SplatFormat::Gltf, scene.placed, scene.degree};
}

GltfContents gltf_contents_of(const std::string& path) {
    FileBytes f(path);
    const tinygltf::Model model = load_model(path, f.data(), f.size(), folder_of(path), true);
    GltfContents contents;
    for (const tinygltf::Mesh& mesh : model.meshes) {
        std::size_t splats = 0;
        for (const tinygltf::Primitive& p : mesh.primitives) splats += is_splat_primitive(p) ? 1 : 0;
        contents.splat_primitives += splats;
        contents.other_primitives += mesh.primitives.size() - splats;
        if (splats && splats == mesh.primitives.size()) contents.splat_only_meshes.push_back(mesh.name);
    }
    return contents;
}

}  // namespace io

GaussianCloud read_gltf_splats(const std::string& path, const ReadOptions& options, LoadReport* report) {
    return io::read_gltf_splats(io::FileBytes(path), options, report);
}

GaussianCloud read_gltf_splats_from_memory(const std::uint8_t* data, std::size_t size, const std::string& name,
                                           const ReadOptions& options, LoadReport* report) {
    return io::read_gltf_splats(io::FileBytes(data, size, name), options, report);
}

GltfContents gltf_contents(const std::string& path) { return io::gltf_contents_of(path); }

}  // namespace raysplats
