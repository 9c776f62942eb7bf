// OBJ (+MTL) and binary PLY export with OpenMesh's writers. The writers read meshes through OpenMesh's
// BaseExporter interface; SceneExporter implements it directly over the ExportScene's flat arrays, because
// building a half-edge mesh first (add_face per triangle) would cost more than the whole write for millions
// of splat patches. All meshes of the scene go into one file (neither format has a scene graph); OBJ keeps
// them apart as `o` groups with a `usemtl` per material, inserted between OpenMesh's face lines.
#include <OpenMesh/Core/IO/Options.hh>
#include <OpenMesh/Core/IO/exporter/BaseExporter.hh>
#include <OpenMesh/Core/IO/writer/OBJWriter.hh>
#include <OpenMesh/Core/IO/writer/PLYWriter.hh>
#include <OpenMesh/Core/Mesh/BaseKernel.hh>
#include <OpenMesh/Core/System/omstream.hh>

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cstdio>
#include <exception>
#include <cstring>
#include <mutex>
#include <ostream>
#include <sstream>

#include "io/io_common.h"
#include "core/os_files.h"
#include "io/mesh_writers.h"

namespace raysplats {
namespace io {

namespace {

using OpenMesh::EdgeHandle;
using OpenMesh::FaceHandle;
using OpenMesh::HalfedgeHandle;
using OpenMesh::VertexHandle;
using OpenMesh::Vec2f;
using OpenMesh::Vec3d;
using OpenMesh::Vec3f;
using OpenMesh::Vec3uc;
using OpenMesh::Vec3ui;
using OpenMesh::Vec4f;
using OpenMesh::Vec4uc;
using OpenMesh::Vec4ui;
using StatusInfo = OpenMesh::Attributes::StatusInfo;

// OpenMesh's writer singletons keep per-call state (OBJ materials): one export at a time.
std::mutex g_openmesh_mutex;

// A run of faces with one mesh and material, in file order.
struct FaceGroup {
    std::size_t face_begin = 0, vertex_base = 0;  // global first face; global index of the part's vertex 0
    const ExportMesh* mesh = nullptr;
    const ExportMeshPart* part = nullptr;
};

class SceneExporter : public OpenMesh::IO::BaseExporter {
public:
    explicit SceneExporter(const ExportScene& scene) {
        std::size_t vbase = 0, fbase = 0;
        for (const ExportMesh& m : scene.meshes) {
            mesh_vertex_begin_.push_back(vbase);
            meshes_.push_back(&m);
            for (const ExportMeshPart& p : m.parts) {
                if (p.triangle_count) groups_.push_back({fbase, vbase + p.vertex_begin, &m, &p});
                fbase += p.triangle_count;
            }
            vbase += m.vertex_count();
            has_normals_ = has_normals_ || !m.normals.empty();
            has_colors_ = has_colors_ || !m.colors.empty();
            has_uvs_ = has_uvs_ || !m.uvs.empty();
        }
        n_vertices_ = vbase;
        n_faces_ = fbase;
    }

    const std::vector<FaceGroup>& groups() const { return groups_; }

    // Restricts the exporter to vertices [v0, v0 + nv) and faces [f0, f0 + nf), renumbered from 0, while face
    // vertex indices stay global: OpenMesh then writes one slice of the records, so slices can be written in
    // parallel and concatenated (write_ply).
    void set_window(std::size_t v0, std::size_t nv, std::size_t f0, std::size_t nf) {
        vertex_window_ = v0, face_window_ = f0, n_vertices_ = nv, n_faces_ = nf;
    }

    // Vertices
    Vec3f point(VertexHandle vh) const override {
        const float* p = attr(vh, 0, 3);
        return Vec3f(p[0], p[1], p[2]);
    }
    Vec3d pointd(VertexHandle vh) const override { const Vec3f p = point(vh); return Vec3d(p[0], p[1], p[2]); }
    bool is_point_double() const override { return false; }
    Vec3f normal(VertexHandle vh) const override {
        const float* n = attr(vh, 1, 3);
        return n ? Vec3f(n[0], n[1], n[2]) : Vec3f(0, 0, 0);
    }
    Vec3d normald(VertexHandle vh) const override { const Vec3f n = normal(vh); return Vec3d(n[0], n[1], n[2]); }
    bool is_normal_double() const override { return false; }
    Vec4f colorAf(VertexHandle vh) const override {
        const float* c = attr(vh, 2, 4);
        if (!c) return Vec4f(1, 1, 1, 1);
        return Vec4f(linear_to_srgb_clamped(c[0]), linear_to_srgb_clamped(c[1]), linear_to_srgb_clamped(c[2]),
                     std::min(1.0f, std::max(0.0f, c[3])));
    }
    Vec4uc colorA(VertexHandle vh) const override {
        const float* c = attr(vh, 2, 4);
        if (!c) return Vec4uc(255, 255, 255, 255);
        return Vec4uc(srgb_(c[0]), srgb_(c[1]), srgb_(c[2]), unit_to_byte(c[3]));
    }
    Vec3uc color(VertexHandle vh) const override { const Vec4uc c = colorA(vh); return Vec3uc(c[0], c[1], c[2]); }
    Vec3ui colori(VertexHandle vh) const override { const Vec4uc c = colorA(vh); return Vec3ui(c[0], c[1], c[2]); }
    Vec4ui colorAi(VertexHandle vh) const override { const Vec4uc c = colorA(vh); return Vec4ui(c[0], c[1], c[2], c[3]); }
    Vec3f colorf(VertexHandle vh) const override { const Vec4f c = colorAf(vh); return Vec3f(c[0], c[1], c[2]); }
    Vec2f texcoord(VertexHandle vh) const override {
        const float* t = attr(vh, 3, 2);
        return t ? Vec2f(t[0], t[1]) : Vec2f(0, 0);
    }
    Vec2f texcoord(HalfedgeHandle) const override { return Vec2f(0, 0); }
    StatusInfo status(VertexHandle) const override { return StatusInfo(); }

    // Faces
    unsigned int get_vhandles(FaceHandle fh, std::vector<VertexHandle>& out) const override {
        const std::size_t f = face_window_ + std::size_t(fh.idx());
        const FaceGroup& g = group_of(f);
        const std::size_t t = g.part->triangle_begin + (f - g.face_begin);
        out.resize(3);
        for (int c = 0; c < 3; ++c) out[c] = VertexHandle(int(g.vertex_base + g.mesh->triangles[3 * t + c]));
        return 3;
    }
    HalfedgeHandle getHeh(FaceHandle, VertexHandle) const override { return HalfedgeHandle(); }
    unsigned int get_face_texcoords(std::vector<Vec2f>&) const override { return 0; }
    Vec3f normal(FaceHandle) const override { return Vec3f(0, 0, 0); }
    Vec3d normald(FaceHandle) const override { return Vec3d(0, 0, 0); }
    Vec3uc color(FaceHandle) const override { return Vec3uc(255, 255, 255); }
    Vec4uc colorA(FaceHandle) const override { return Vec4uc(255, 255, 255, 255); }
    Vec3ui colori(FaceHandle) const override { return Vec3ui(255, 255, 255); }
    Vec4ui colorAi(FaceHandle) const override { return Vec4ui(255, 255, 255, 255); }
    Vec3f colorf(FaceHandle) const override { return Vec3f(1, 1, 1); }
    Vec4f colorAf(FaceHandle) const override { return Vec4f(1, 1, 1, 1); }
    StatusInfo status(FaceHandle) const override { return StatusInfo(); }

    // Edges and half-edges: not written by the OBJ and PLY writers.
    Vec3uc color(EdgeHandle) const override { return Vec3uc(0, 0, 0); }
    Vec4uc colorA(EdgeHandle) const override { return Vec4uc(0, 0, 0, 0); }
    Vec3ui colori(EdgeHandle) const override { return Vec3ui(0, 0, 0); }
    Vec4ui colorAi(EdgeHandle) const override { return Vec4ui(0, 0, 0, 0); }
    Vec3f colorf(EdgeHandle) const override { return Vec3f(0, 0, 0); }
    Vec4f colorAf(EdgeHandle) const override { return Vec4f(0, 0, 0, 0); }
    StatusInfo status(EdgeHandle) const override { return StatusInfo(); }
    int get_halfedge_id(VertexHandle) override { return -1; }
    int get_halfedge_id(FaceHandle) override { return -1; }
    int get_next_halfedge_id(HalfedgeHandle) override { return -1; }
    int get_to_vertex_id(HalfedgeHandle) override { return -1; }
    int get_face_id(HalfedgeHandle) override { return -1; }
    StatusInfo status(HalfedgeHandle) const override { return StatusInfo(); }

    // OpenMesh's PLY writer looks for custom properties in the kernel: an empty one has none.
    const OpenMesh::BaseKernel* kernel() override { return &no_properties_; }

    size_t n_vertices() const override { return n_vertices_; }
    size_t n_faces() const override { return n_faces_; }
    size_t n_edges() const override { return 0; }
    bool is_triangle_mesh() const override { return true; }
    bool has_vertex_normals() const override { return has_normals_; }
    bool has_vertex_colors() const override { return has_colors_; }
    bool has_vertex_texcoords() const override { return has_uvs_; }

private:
    // Attribute `which` (0 position, 1 normal, 2 colour, 3 uv) of a global vertex, or null if its mesh has none.
    const float* attr(VertexHandle vh, int which, int width) const {
        const std::size_t v = vertex_window_ + std::size_t(vh.idx());
        std::size_t m = last_mesh_;
        if (!(v >= mesh_vertex_begin_[m] && v - mesh_vertex_begin_[m] < meshes_[m]->vertex_count())) {
            m = std::size_t(std::upper_bound(mesh_vertex_begin_.begin(), mesh_vertex_begin_.end(), v) -
                            mesh_vertex_begin_.begin()) - 1;
            last_mesh_ = m;
        }
        const ExportMesh& mesh = *meshes_[m];
        const ExportArray<float>& a = which == 0 ? mesh.positions : which == 1 ? mesh.normals : which == 2 ? mesh.colors : mesh.uvs;
        if (a.empty()) return nullptr;
        return &a[std::size_t(width) * (v - mesh_vertex_begin_[m])];
    }
    const FaceGroup& group_of(std::size_t f) const {
        std::size_t g = last_group_;
        if (!(f >= groups_[g].face_begin && f - groups_[g].face_begin < groups_[g].part->triangle_count)) {
            g = std::size_t(std::upper_bound(groups_.begin(), groups_.end(), f,
                                             [](std::size_t x, const FaceGroup& gr) { return x < gr.face_begin; }) -
                            groups_.begin()) - 1;
            last_group_ = g;
        }
        return groups_[g];
    }

    std::vector<const ExportMesh*> meshes_;
    std::vector<std::size_t> mesh_vertex_begin_;
    std::vector<FaceGroup> groups_;
    std::size_t n_vertices_ = 0, n_faces_ = 0, vertex_window_ = 0, face_window_ = 0;
    bool has_normals_ = false, has_colors_ = false, has_uvs_ = false;
    mutable std::size_t last_mesh_ = 0, last_group_ = 0;
    SrgbTable srgb_;
    OpenMesh::BaseKernel no_properties_;
};

std::string stem_of(const std::string& path) {
    const std::size_t slash = os::last_separator(path);
    std::string name = slash == std::string::npos ? path : path.substr(slash + 1);
    const std::size_t dot = name.find_last_of('.');
    return dot == std::string::npos ? name : name.substr(0, dot);
}

std::string sanitized(const std::string& name, const std::string& fallback) {
    std::string s;
    for (char c : name) s += (c == ' ' || c == '\t' || c == '\n' || c == '\r') ? '_' : c;
    return s.empty() ? fallback : s;
}

// Passes OpenMesh's OBJ text through, inserting `o <mesh>` / `usemtl <material>` before the first face line of
// each face group (OpenMesh writes all vertices, then the faces in exporter order), and appending each vertex's
// sRGB colour to its `v` line (the common `v x y z r g b` extension, which Blender, assimp and MeshLab read;
// Debian's OpenMesh 9.0 OBJ writer refuses Options::VertexColor).
class ObjStreamFilter : public std::streambuf {
public:
    ObjStreamFilter(std::streambuf& out, std::vector<std::pair<std::size_t, std::string>> headers,
                    const SceneExporter* colors)
        : out_(out), headers_(std::move(headers)), colors_(colors) {}

protected:
    int_type overflow(int_type ch) override {
        if (traits_type::eq_int_type(ch, traits_type::eof())) return traits_type::not_eof(ch);
        put(traits_type::to_char_type(ch));
        return ch;
    }
    std::streamsize xsputn(const char* s, std::streamsize n) override {
        for (std::streamsize i = 0; i < n; ++i) put(s[i]);
        return n;
    }
    int sync() override { return out_.pubsync(); }

private:
    void put(char c) {
        if (column_ == 0 && c == 'f') {
            while (next_ < headers_.size() && headers_[next_].first == faces_) {
                const std::string& h = headers_[next_++].second;
                out_.sputn(h.data(), std::streamsize(h.size()));
            }
            ++faces_;
        }
        if (column_ == 0) first_ = c;
        if (column_ == 1) vertex_line_ = first_ == 'v' && c == ' ';
        if (c == '\n') {
            if (vertex_line_ && colors_) {
                const OpenMesh::Vec4f col = colors_->colorAf(OpenMesh::VertexHandle(int(vertices_++)));
                char text[64];
                const int len = std::snprintf(text, sizeof(text), " %.6f %.6f %.6f", col[0], col[1], col[2]);
                out_.sputn(text, len);
            }
            column_ = 0;
            vertex_line_ = false;
        } else {
            ++column_;
        }
        out_.sputc(c);
    }
    std::streambuf& out_;
    std::vector<std::pair<std::size_t, std::string>> headers_;
    const SceneExporter* colors_;
    std::size_t next_ = 0, faces_ = 0, vertices_ = 0, column_ = 0;
    char first_ = 0;
    bool vertex_line_ = false;
};

std::string mtl_number(float v) {
    std::ostringstream s;
    s.precision(6);
    s << std::fixed << v;
    return s.str();
}

}  // namespace

MeshWriteStats write_obj(const std::string& path, const ExportScene& scene) {
    SceneExporter exporter(scene);
    const std::string stem = stem_of(path);
    const std::size_t slash = os::last_separator(path);
    const std::string mtl_path = (slash == std::string::npos ? std::string() : path.substr(0, slash + 1)) + stem + ".mtl";

    // Materials: the scene's, plus a default one for parts without a material.
    auto material_name = [&](int m) {
        return m < 0 ? std::string("RaySplats_default") : sanitized(scene.materials[std::size_t(m)].name, "material_" + std::to_string(m));
    };
    std::ostringstream mtl;
    mtl << "# RaySplats material library\n";
    std::vector<int> used;
    for (const FaceGroup& g : exporter.groups())
        if (std::find(used.begin(), used.end(), g.part->material) == used.end()) used.push_back(g.part->material);
    for (int m : used) {
        ExportMaterial def;
        const ExportMaterial& mat = m < 0 ? def : scene.materials[std::size_t(m)];
        mtl << "\nnewmtl " << material_name(m) << "\n";
        mtl << "Kd " << mtl_number(mat.base_color[0]) << ' ' << mtl_number(mat.base_color[1]) << ' '
            << mtl_number(mat.base_color[2]) << "\n";
        mtl << "d " << mtl_number(mat.base_color[3]) << "\n";
        // PBR extension of MTL (Pr roughness, Pm metallic), read by Blender's and assimp's importers.
        mtl << "Pr " << mtl_number(mat.roughness) << "\nPm " << mtl_number(mat.metallic) << "\n";
        mtl << "illum 2\n";
    }

    std::vector<std::pair<std::size_t, std::string>> headers;
    const ExportMesh* last_mesh = nullptr;
    int last_material = -2;
    for (const FaceGroup& g : exporter.groups()) {
        std::string h;
        if (g.mesh != last_mesh) h += "o " + sanitized(g.mesh->name, "mesh") + "\n", last_material = -2;
        if (g.part->material != last_material) h += "usemtl " + material_name(g.part->material) + "\n";
        last_mesh = g.mesh, last_material = g.part->material;
        if (!h.empty()) headers.emplace_back(g.face_begin, h);
    }

    OpenMesh::IO::Options opt;
    if (exporter.has_vertex_normals()) opt += OpenMesh::IO::Options::VertexNormal;
    if (exporter.has_vertex_texcoords()) opt += OpenMesh::IO::Options::VertexTexCoord;

    AtomicFileWriter mtl_file(mtl_path);
    const std::string mtl_text = mtl.str();
    mtl_file.write(mtl_text.data(), mtl_text.size());

    AtomicFileWriter file(path);
    {
        AtomicFileStreamBuf filebuf(file);
        const std::string head = "# RaySplats mesh export\nmtllib " + stem + ".mtl\n";
        filebuf.sputn(head.data(), std::streamsize(head.size()));
        ObjStreamFilter groupbuf(filebuf, std::move(headers), exporter.has_vertex_colors() ? &exporter : nullptr);
        std::ostream out(&groupbuf);
        out.exceptions(std::ios::badbit);
        bool ok;
        {
            std::lock_guard<std::mutex> lock(g_openmesh_mutex);
            omlog().disable();  // "[OBJWriter] : write file" on every export
            ok = OpenMesh::IO::OBJWriter().write(out, exporter, opt, 6);
        }
        out.flush();
        if (!ok || !out) throw FileFormatError(path, "OpenMesh's OBJ writer failed");
        filebuf.pubsync();
    }
    mtl_file.commit();
    file.commit();
    MeshWriteStats stats;
    stats.vertices = exporter.n_vertices();
    stats.triangles = exporter.n_faces();
    stats.primitives = exporter.groups().size();
    return stats;
}

namespace {

// A streambuf appending to memory (one slice of a PLY body), through the streambuf's own put area.
class MemoryStreamBuf : public std::streambuf {
public:
    explicit MemoryStreamBuf(std::size_t reserve) : data_(std::max<std::size_t>(reserve, 64)) {
        setp(data_.data(), data_.data() + data_.size());
    }
    // The bytes written so far (the buffer is trimmed to them).
    std::vector<char>& data() {
        data_.resize(std::size_t(pptr() - pbase()));
        setp(nullptr, nullptr);
        return data_;
    }

protected:
    int_type overflow(int_type ch) override {
        grow(1);
        if (!traits_type::eq_int_type(ch, traits_type::eof())) *pptr() = traits_type::to_char_type(ch), pbump(1);
        return traits_type::not_eof(ch);
    }
    std::streamsize xsputn(const char* s, std::streamsize n) override {
        if (epptr() - pptr() < n) grow(std::size_t(n));
        std::memcpy(pptr(), s, std::size_t(n));
        pbump(int(n));
        return n;
    }

private:
    void grow(std::size_t at_least) {
        const std::size_t used = std::size_t(pptr() - pbase());
        data_.resize(std::max(2 * data_.size(), used + at_least));
        setp(data_.data(), data_.data() + data_.size());
        pbump(int(used));  // the slices are far below 2 GiB (kSliceRecords records)
    }
    std::vector<char> data_;
};

// OpenMesh PLY writer instances, one per concurrent slice. The library's singleton is used by one thread at a
// time; the others are extra instances, created once and kept for the life of the process (their
// constructor registers them with OpenMesh's IOManager, which keeps the pointer).
class PlyWriterPool {
public:
    OpenMesh::IO::_PLYWriter_* acquire() {
        std::lock_guard<std::mutex> lock(mutex_);
        if (free_.empty()) return new OpenMesh::IO::_PLYWriter_();  // intentionally never deleted (see above)
        OpenMesh::IO::_PLYWriter_* w = free_.back();
        free_.pop_back();
        return w;
    }
    void release(OpenMesh::IO::_PLYWriter_* w) {
        std::lock_guard<std::mutex> lock(mutex_);
        free_.push_back(w);
    }

private:
    std::mutex mutex_;
    std::vector<OpenMesh::IO::_PLYWriter_*> free_;
};
PlyWriterPool g_ply_writers;

}  // namespace

MeshWriteStats write_ply(const std::string& path, const ExportScene& scene) {
    const SceneExporter whole(scene);
    // Positions, RGBA (8-bit sRGB + alpha) and UVs as s, t (the names Blender 3.x's importer reads). No normals:
    // the patches are flat, so every reader derives the same ones from the faces, and the file is 25 % smaller.
    OpenMesh::IO::Options opt = OpenMesh::IO::Options::Binary;
    opt += OpenMesh::IO::Options::LSB;
    if (whole.has_vertex_colors()) opt += OpenMesh::IO::Options::VertexColor, opt += OpenMesh::IO::Options::ColorAlpha;
    if (whole.has_vertex_texcoords()) opt += OpenMesh::IO::Options::VertexTexCoord, opt += OpenMesh::IO::Options::TexCoordST;

    // OpenMesh writes the records one value at a time through std::ostream::write, which is what a PLY export
    // of millions of patches waits on; so the body is cut into slices (vertex ranges, then face ranges), each
    // written by OpenMesh in parallel into memory, and the slices are concatenated under one header (taken
    // from OpenMesh's own output, with the total counts).
    const std::size_t nv = whole.n_vertices(), nf = whole.n_faces();
    constexpr std::size_t kSliceRecords = std::size_t(1) << 21;
    struct Slice { std::size_t v0, nv, f0, nf; std::vector<char> bytes; std::string header; };
    std::vector<Slice> slices;
    for (std::size_t v = 0; v < nv || (v == 0 && nv == 0); v += kSliceRecords) {
        slices.push_back({v, std::min(kSliceRecords, nv - v), 0, 0, {}, {}});
        if (nv == 0) break;
    }
    for (std::size_t f = 0; f < nf; f += kSliceRecords) slices.push_back({0, 0, f, std::min(kSliceRecords, nf - f), {}, {}});
    std::exception_ptr error;
    std::mutex error_mutex;
    tbb::parallel_for(std::size_t(0), slices.size(), [&](std::size_t i) {
        Slice& slice = slices[i];
        try {
            SceneExporter exporter(scene);
            exporter.set_window(slice.v0, slice.nv, slice.f0, slice.nf);
            MemoryStreamBuf buffer(slice.nv * 24 + slice.nf * 13 + 4096);
            std::ostream out(&buffer);
            OpenMesh::IO::_PLYWriter_* writer = g_ply_writers.acquire();
            const bool ok = writer->write(out, exporter, opt, 6);
            g_ply_writers.release(writer);
            if (!ok || !out) throw FileFormatError(path, "OpenMesh's PLY writer failed");
            std::vector<char>& bytes = buffer.data();
            static const char kEnd[] = "end_header\n";
            auto end = std::search(bytes.begin(), bytes.end(), kEnd, kEnd + sizeof(kEnd) - 1);
            if (end == bytes.end()) throw FileFormatError(path, "OpenMesh's PLY writer wrote no header");
            end += sizeof(kEnd) - 1;
            slice.header.assign(bytes.begin(), end);
            slice.bytes.assign(end, bytes.end());
        } catch (...) {
            std::lock_guard<std::mutex> lock(error_mutex);
            if (!error) error = std::current_exception();
        }
    });
    if (error) std::rethrow_exception(error);

    // The header of the first slice, with the real element counts.
    std::string header = slices.front().header;
    auto set_count = [&](const std::string& element, std::size_t count) {
        const std::string key = "element " + element + " ";
        const std::size_t at = header.find(key);
        if (at == std::string::npos) throw FileFormatError(path, "OpenMesh's PLY header has no " + element + " element");
        const std::size_t end = header.find('\n', at);
        header.replace(at, end - at, key + std::to_string(count));
    };
    set_count("vertex", nv);
    set_count("face", nf);

    AtomicFileWriter file(path);
    file.write(header.data(), header.size());
    std::size_t bytes = header.size();
    for (const Slice& slice : slices) file.write(slice.bytes.data(), slice.bytes.size()), bytes += slice.bytes.size();
    file.commit();
    MeshWriteStats stats;
    stats.vertices = nv;
    stats.triangles = nf;
    stats.primitives = whole.groups().size();
    stats.bytes = bytes;
    return stats;
}

}  // namespace io
}  // namespace raysplats
