// Mesh export of docs/design.md §7: Gaussians as small triangle patches, and ordinary meshes, written as OBJ (+MTL),
// PLY (binary, RGBA vertex colours) and glTF 2.0 (.gltf + .bin, or .glb; optionally Draco-compressed).
//
// A splat patch is the Gaussian's polygon (docs/design.md §5, K rim vertices on the ellipse of Mahalanobis radius
// rho_i) plus a centre vertex, fan-triangulated from the centre (K triangles, K + 1 vertices):
//   centre:  position m,                               alpha a,                 uv (0.5, 0.5)
//   rim k:   m + rho_i (s1 cos θ_k a1 + s2 sin θ_k a2), alpha a·exp(-rho_i²/2),  uv 0.5 + 0.5 (rho_i/rho)(cos θ_k, sin θ_k)
// with rho_i = visible_polygon_radius(a, rho) = min(rho, sqrt(2 ln(255 a))) (polygon_bridge.h: the patch spans
// where the Gaussian is visible, as the polygon its import made; a Gaussian with a < 1/255 gets a patch of zero
// size). Linear interpolation of the vertex alpha approximates the falloff, and a renderer with one alpha texture
// for all patches gets it exactly: at texture coordinate uv every Gaussian is a·exp(-|x|²/2), x = rho (2 uv - 1)
// (x is the local polygon coordinate Blender's `gs_uv` map holds; the rim of a faint Gaussian lies inside the
// circle of radius 0.5). Normal: a1 × a2 at every vertex.
// Colour: the view-independent SH DC term, c = clamp(0.5 + SH_00 · f_dc, 0, 1) (display sRGB, docs/design.md §4);
// higher SH bands are not representable in these formats and are left out.
//
// Colours are kept linear in memory (as Blender and glTF's COLOR_0 hold them); the OBJ and PLY writers
// store them sRGB-encoded (8-bit PLY, float OBJ), which is what viewers of those formats show directly.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <new>
#include <string>
#include <utility>
#include <vector>

#include "raysplats/default_init_allocator.h"
#include "raysplats/gaussian_cloud.h"
#include "raysplats/polygon_bridge.h"

namespace raysplats {

// Export arrays are filled in parallel: see DefaultInitAllocator.
template <typename T>
using ExportArray = std::vector<T, DefaultInitAllocator<T>>;

// A PBR material (glTF metallic-roughness; Blender's Principled BSDF base colour, metallic, roughness).
struct ExportMaterial {
    std::string name;
    float base_color[4] = {0.8f, 0.8f, 0.8f, 1.0f};  // linear RGBA
    float metallic = 0.0f;
    float roughness = 0.5f;
    bool alpha_blend = false;   // glTF alphaMode BLEND (splat patches), else OPAQUE
    bool double_sided = false;
};

// A contiguous piece of an ExportMesh with one material: vertices [vertex_begin, vertex_begin + vertex_count)
// and triangles [triangle_begin, triangle_begin + triangle_count) whose indices are relative to vertex_begin.
// Each part becomes one glTF primitive (one Draco stream); parts of splat patches hold at most 65535 vertices
// so that their indices fit 16 bits.
struct ExportMeshPart {
    std::size_t vertex_begin = 0, vertex_count = 0;
    std::size_t triangle_begin = 0, triangle_count = 0;
    int material = -1;  // index into ExportScene::materials, -1: default material
};

// A triangle mesh with per-vertex attributes; optional attributes are empty.
struct ExportMesh {
    std::string name;
    ExportArray<float> positions;           // 3 per vertex
    ExportArray<float> normals;             // 3 per vertex (optional)
    ExportArray<float> colors;              // 4 per vertex, linear RGB + alpha (optional)
    ExportArray<float> uvs;                 // 2 per vertex (optional)
    ExportArray<std::uint32_t> triangles;   // 3 per triangle, relative to the part's vertex_begin
    std::vector<ExportMeshPart> parts;
    // Row-major 4x4 placing the mesh in the scene (glTF node matrix). Identity when the vertices are already
    // in output coordinates; OBJ and PLY, which have no scene graph, ignore it.
    double node_matrix[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};

    std::size_t vertex_count() const { return positions.size() / 3; }
    std::size_t triangle_count() const { return triangles.size() / 3; }
    void check_consistent() const;  // throws InvalidArgument
};

// Gaussians to write as points with KHR_gaussian_splatting (glTF only, when MeshWriteOptions asks), in output
// axes, placed by node_matrix like ExportMesh.
struct ExportGaussians {
    std::string name;
    GaussianCloud cloud;
    double node_matrix[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
};

struct ExportScene {
    std::vector<ExportMesh> meshes;
    std::vector<ExportMaterial> materials;
    std::vector<ExportGaussians> gaussians;  // one point primitive (and node) each
};

enum class MeshFileFormat { Obj, Ply, Gltf, Glb };

// From the extension (.obj, .ply, .gltf, .glb, any case); throws InvalidArgument for anything else.
MeshFileFormat mesh_format_from_path(const std::string& path);

struct DracoOptions {
    bool enabled = false;
    int position_bits = 14;   // quantisation bits per attribute (KHR_draco_mesh_compression), 1..30
    int normal_bits = 10;
    int uv_bits = 12;             // (colours are 8-bit integers: Draco stores them losslessly)
    int compression_level = 7;  // 0 (fastest) .. 10 (smallest), Draco's encoder speed = 10 - level
};

struct MeshWriteOptions {
    DracoOptions draco;                     // glTF/GLB only
    bool gaussian_splatting_extension = false;  // glTF/GLB: also write ExportScene::gaussians
};

struct MeshWriteStats {
    std::size_t vertices = 0, triangles = 0, primitives = 0;
    std::size_t bytes = 0;  // size of the main file (plus .bin / .mtl)
};

// Writes the scene atomically (temporary files renamed over the targets only when everything is written;
// a .gltf's .bin and an .obj's .mtl sit beside it with the same stem). Throws InvalidArgument for an empty
// scene or inconsistent arrays, FileFormatError naming the path when it cannot be written.
MeshWriteStats write_mesh_file(const std::string& path, const ExportScene& scene, const MeshWriteOptions& options = {});

// Splat patches (see the top of this file) of every Gaussian, with splat patch material index `material`.
// Multi-threaded.
ExportMesh splat_patches(const GaussianCloud& cloud, const PolygonSettings& settings, const std::string& name,
                         int material = -1);

// An ordinary triangle mesh (e.g. Blender's loop triangles) mapped by `transform` (row-major 4x4; normals by
// its inverse transpose), split into one part per material. `triangle_materials` (one per triangle, may be
// null) index `material_slots`, which maps to ExportScene::materials (-1: default). Vertex colours, when
// `colors` is null, are the base colour of the vertex's material so that formats without materials (PLY)
// still show them.
struct TriangleMeshView {
    const float* positions = nullptr;  std::size_t vertex_count = 0;
    const float* normals = nullptr;    // per vertex, may be null
    const float* colors = nullptr;     // 4 per vertex, linear, may be null
    const float* uvs = nullptr;        // 2 per vertex, may be null
    const std::uint32_t* triangles = nullptr;  std::size_t triangle_count = 0;
    const std::int32_t* triangle_materials = nullptr;
};
ExportMesh triangle_mesh(const TriangleMeshView& view, const double transform[16], const std::vector<int>& material_slots,
                         const std::vector<ExportMaterial>& materials, const std::string& name);

// Polygons as they are (e.g. a Gaussian object's K-gons after editing), each fan-triangulated from its first
// corner, one vertex per corner with the given corner colours (4, linear) and UVs (2), both optional.
ExportMesh polygon_mesh(const PolygonMeshView& mesh, const float* corner_colors, const float* corner_uvs,
                        const double transform[16], const std::string& name, int material = -1);

}  // namespace raysplats
