// raysplats._native.MeshExportScene: thin bindings over raysplats/mesh_export.h. The add-on adds materials and
// meshes (splat patches from Gaussians, ordinary triangle meshes, raw polygons) as numpy arrays, then writes
// the scene; the GIL is released around the native work.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <optional>
#include <string>
#include <vector>

#include "conversions.h"
#include "raysplats/errors.h"
#include "raysplats/mesh_export.h"

namespace py = pybind11;
using namespace pybind11::literals;
using namespace raysplats::python;

namespace {

void copy_matrix(const std::optional<DoubleArray>& m, double out[16], const char* name) {
    if (!m) return;
    require_size(*m, name, 16);
    std::copy(m->data(), m->data() + 16, out);
}

class MeshExportScene {
public:
    int add_material(const std::string& name, std::vector<float> base_color, float metallic, float roughness,
                     bool alpha_blend, bool double_sided) {
        if (base_color.size() != 4) throw raysplats::InvalidArgument("base_color must have 4 values (linear RGBA)");
        raysplats::ExportMaterial m;
        m.name = name;
        std::copy(base_color.begin(), base_color.end(), m.base_color);
        m.metallic = metallic, m.roughness = roughness, m.alpha_blend = alpha_blend, m.double_sided = double_sided;
        scene_.materials.push_back(m);
        return int(scene_.materials.size() - 1);
    }

    void add_splats(const std::string& name, const FloatArray& positions, const FloatArray& rotations,
                    const FloatArray& scales, const FloatArray& opacities, const FloatArray& sh, int vertices_per_polygon,
                    float radius, int material, std::optional<DoubleArray> node_matrix, bool keep_gaussians, bool patches) {
        raysplats::GaussianCloud cloud = cloud_from_arrays(positions, rotations, scales, opacities, sh);
        if (patches) {
            raysplats::ExportMesh mesh;
            {
                py::gil_scoped_release release;
                mesh = raysplats::splat_patches(cloud, {vertices_per_polygon, radius}, name, material);
            }
            copy_matrix(node_matrix, mesh.node_matrix, "node_matrix");
            scene_.meshes.push_back(std::move(mesh));
        }
        if (keep_gaussians) {
            raysplats::ExportGaussians g;
            g.name = name + " Gaussians";
            copy_matrix(node_matrix, g.node_matrix, "node_matrix");
            g.cloud = std::move(cloud);
            scene_.gaussians.push_back(std::move(g));
        }
    }

    void add_triangles(const std::string& name, const FloatArray& positions, const UintArray& triangles,
                       std::optional<FloatArray> normals, std::optional<IntArray> triangle_materials,
                       std::vector<int> material_slots, const DoubleArray& transform, std::optional<DoubleArray> node_matrix) {
        raysplats::TriangleMeshView view;
        view.positions = positions.data();
        view.vertex_count = std::size_t(positions.size() / 3);
        require_size(positions, "positions", 3 * py::ssize_t(view.vertex_count));
        view.triangles = triangles.data();
        view.triangle_count = std::size_t(triangles.size() / 3);
        require_size(triangles, "triangles", 3 * py::ssize_t(view.triangle_count));
        if (normals) require_size(*normals, "normals", positions.size()), view.normals = normals->data();
        if (triangle_materials)
            require_size(*triangle_materials, "triangle_materials", py::ssize_t(view.triangle_count)),
                view.triangle_materials = triangle_materials->data();
        double m[16];
        require_size(transform, "transform", 16);
        std::copy(transform.data(), transform.data() + 16, m);
        raysplats::ExportMesh mesh;
        {
            py::gil_scoped_release release;
            mesh = raysplats::triangle_mesh(view, m, material_slots, scene_.materials, name);
        }
        copy_matrix(node_matrix, mesh.node_matrix, "node_matrix");
        scene_.meshes.push_back(std::move(mesh));
    }

    void add_polygons(const std::string& name, const FloatArray& vertex_positions, const IntArray& corner_vertices,
                      const IntArray& face_corner_start, const IntArray& face_corner_count,
                      std::optional<FloatArray> corner_colors, std::optional<FloatArray> corner_uvs, const DoubleArray& transform,
                      int material, std::optional<DoubleArray> node_matrix) {
        raysplats::PolygonMeshView view;
        view.vertex_positions = vertex_positions.data();
        view.vertex_count = std::size_t(vertex_positions.size() / 3);
        view.corner_vertices = corner_vertices.data();
        view.corner_count = std::size_t(corner_vertices.size());
        view.face_corner_start = face_corner_start.data();
        view.face_corner_count = face_corner_count.data();
        view.face_count = std::size_t(face_corner_start.size());
        require_size(face_corner_count, "face_corner_count", face_corner_start.size());
        if (corner_colors) require_size(*corner_colors, "corner_colors", 4 * corner_vertices.size());
        if (corner_uvs) require_size(*corner_uvs, "corner_uvs", 2 * corner_vertices.size());
        double m[16];
        require_size(transform, "transform", 16);
        std::copy(transform.data(), transform.data() + 16, m);
        raysplats::ExportMesh mesh;
        {
            py::gil_scoped_release release;
            mesh = raysplats::polygon_mesh(view, corner_colors ? corner_colors->data() : nullptr,
                                           corner_uvs ? corner_uvs->data() : nullptr, m, name, material);
        }
        copy_matrix(node_matrix, mesh.node_matrix, "node_matrix");
        scene_.meshes.push_back(std::move(mesh));
    }

    py::dict write(const std::string& path, bool draco, int position_bits, int normal_bits, int uv_bits,
                   int compression_level, bool gaussian_splatting) const {
        raysplats::MeshWriteOptions options;
        options.draco.enabled = draco;
        options.draco.position_bits = position_bits;
        options.draco.normal_bits = normal_bits;
        options.draco.uv_bits = uv_bits;
        options.draco.compression_level = compression_level;
        options.gaussian_splatting_extension = gaussian_splatting;
        raysplats::MeshWriteStats stats;
        {
            py::gil_scoped_release release;
            stats = raysplats::write_mesh_file(path, scene_, options);
        }
        return py::dict("vertices"_a = stats.vertices, "triangles"_a = stats.triangles, "primitives"_a = stats.primitives,
                        "bytes"_a = stats.bytes);
    }

    std::size_t mesh_count() const { return scene_.meshes.size(); }
    std::size_t triangle_count() const {
        std::size_t t = 0;
        for (const auto& m : scene_.meshes) t += m.triangle_count();
        return t;
    }

private:
    raysplats::ExportScene scene_;
};

}  // namespace

void register_mesh_export(py::module_& m) {
    py::class_<MeshExportScene>(m, "MeshExportScene",
                                "A scene to export as OBJ, PLY, glTF or GLB (raysplats/mesh_export.h): add materials "
                                "and meshes, then write().")
        .def(py::init<>())
        .def("add_material", &MeshExportScene::add_material, "name"_a, "base_color"_a, "metallic"_a = 0.0f,
             "roughness"_a = 0.5f, "alpha_blend"_a = false, "double_sided"_a = false,
             "Adds a PBR material (linear base colour RGBA); returns its index.")
        .def("add_splats", &MeshExportScene::add_splats, "name"_a, "positions"_a, "rotations"_a, "scales"_a,
             "opacities"_a, "sh"_a, "vertices_per_polygon"_a = 8, "radius"_a = 3.0f, "material"_a = -1,
             "node_matrix"_a = py::none(), "keep_gaussians"_a = false, "patches"_a = true,
             "Adds Gaussians (in output coordinates) as fan-triangulated splat patches (unless patches=False); "
             "keep_gaussians also keeps them for KHR_gaussian_splatting.")
        .def("add_triangles", &MeshExportScene::add_triangles, "name"_a, "positions"_a, "triangles"_a,
             "normals"_a = py::none(), "triangle_materials"_a = py::none(), "material_slots"_a = std::vector<int>(),
             "transform"_a, "node_matrix"_a = py::none(),
             "Adds a triangle mesh mapped by transform (4x4 row-major), one part per material slot.")
        .def("add_polygons", &MeshExportScene::add_polygons, "name"_a, "vertex_positions"_a, "corner_vertices"_a,
             "face_corner_start"_a, "face_corner_count"_a, "corner_colors"_a = py::none(), "corner_uvs"_a = py::none(),
             "transform"_a, "material"_a = -1, "node_matrix"_a = py::none(),
             "Adds polygons as they are, each fan-triangulated from its first corner, one vertex per corner.")
        .def("write", &MeshExportScene::write, "path"_a, "draco"_a = false, "position_bits"_a = 14,
             "normal_bits"_a = 10, "uv_bits"_a = 12, "compression_level"_a = 7, "gaussian_splatting"_a = false,
             "Writes the scene atomically; the format comes from the extension (.obj, .ply, .gltf, .glb).")
        .def_property_readonly("mesh_count", &MeshExportScene::mesh_count)
        .def_property_readonly("triangle_count", &MeshExportScene::triangle_count);
}
