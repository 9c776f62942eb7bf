// Mesh export: splat patch geometry (docs/design.md §7), parts, triangle meshes and polygons, and the written files
// read back independently (tinygltf's loader, Draco's decoder, raw PLY/OBJ parsing), plus write errors.
#include <gtest/gtest.h>

#define TINYGLTF_NO_STB_IMAGE
#define TINYGLTF_NO_STB_IMAGE_WRITE
#define TINYGLTF_NO_EXTERNAL_IMAGE
#include <tiny_gltf.h>  // the implementation is compiled into the core (gltf_writer.cpp)

#include <draco/compression/decode.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "io_test_util.h"
#include "raysplats/errors.h"
#include "raysplats/mesh_export.h"
#include "raysplats/splat_io.h"

namespace raysplats {
namespace {

using namespace testutil;
namespace fs = std::filesystem;

constexpr double kC0 = 0.28209479177387814;

double srgb_to_linear(double c) { return c <= 0.04045 ? c / 12.92 : std::pow((c + 0.055) / 1.055, 2.4); }

// One Gaussian at (1, 2, 3), axes along x and y (scales 0.5, 0.2), thin along z, opacity 0.8, DC colour
// 0.7 / 0.5 / 0.3 (display values).
GaussianCloud one_gaussian() {
    GaussianCloud c;
    c.resize(1, 0);
    const float pos[3] = {1, 2, 3}, scales[3] = {0.5f, 0.2f, 0.01f}, srgb[3] = {0.7f, 0.5f, 0.3f};
    for (int k = 0; k < 3; ++k) {
        c.positions[k] = pos[k];
        c.scales[k] = scales[k];
        c.sh[k] = float((srgb[k] - 0.5) / kC0);
    }
    c.opacities[0] = 0.8f;
    return c;
}

ExportScene patch_scene(const GaussianCloud& cloud) {
    ExportScene scene;
    ExportMaterial m;
    m.name = "splats";
    m.alpha_blend = true;
    scene.materials.push_back(m);
    scene.meshes.push_back(splat_patches(cloud, PolygonSettings{}, "splats", 0));
    return scene;
}

TEST(SplatPatches, OneGaussianIsAFanWithFalloffAlphaUvsAndNormal) {
    const ExportMesh m = splat_patches(one_gaussian(), PolygonSettings{}, "g");
    ASSERT_EQ(m.vertex_count(), 9u);
    ASSERT_EQ(m.triangle_count(), 8u);
    // Centre vertex: the Gaussian's centre, alpha = opacity, uv at the texture centre.
    EXPECT_FLOAT_EQ(m.positions[0], 1.0f);
    EXPECT_FLOAT_EQ(m.positions[1], 2.0f);
    EXPECT_FLOAT_EQ(m.positions[2], 3.0f);
    EXPECT_FLOAT_EQ(m.colors[3], 0.8f);
    EXPECT_FLOAT_EQ(m.uvs[0], 0.5f);
    EXPECT_FLOAT_EQ(m.uvs[1], 0.5f);
    const double rim_alpha = 0.8 * std::exp(-4.5);
    for (int k = 0; k < 8; ++k) {
        const std::size_t v = 1 + std::size_t(k);
        // Rim vertex k on the 3-sigma ellipse: m + 3 (0.5 cos θ x + 0.2 sin θ y).
        const double theta = 2 * M_PI * k / 8;
        EXPECT_NEAR(m.positions[3 * v], 1 + 1.5 * std::cos(theta), 1e-5);
        EXPECT_NEAR(m.positions[3 * v + 1], 2 + 0.6 * std::sin(theta), 1e-5);
        EXPECT_NEAR(m.positions[3 * v + 2], 3, 1e-6);
        EXPECT_NEAR(m.colors[4 * v + 3], rim_alpha, 1e-7);
        // uv = 0.5 + 0.5 (cos θ, sin θ): local coordinate rho (2 uv - 1) has |x| = rho.
        EXPECT_NEAR(m.uvs[2 * v], 0.5 + 0.5 * std::cos(theta), 1e-6);
        EXPECT_NEAR(m.uvs[2 * v + 1], 0.5 + 0.5 * std::sin(theta), 1e-6);
    }
    for (std::size_t v = 0; v < 9; ++v) {
        EXPECT_NEAR(m.normals[3 * v + 2], 1.0, 1e-6);  // a1 × a2 = x × y = +z
        EXPECT_NEAR(m.colors[4 * v], srgb_to_linear(0.7), 1e-5);
        EXPECT_NEAR(m.colors[4 * v + 1], srgb_to_linear(0.5), 1e-5);
        EXPECT_NEAR(m.colors[4 * v + 2], srgb_to_linear(0.3), 1e-5);
    }
    // Fan from the centre, each triangle wound like the normal.
    for (int t = 0; t < 8; ++t) {
        const std::uint32_t* tri = &m.triangles[3 * t];
        EXPECT_EQ(tri[0], 0u);
        EXPECT_EQ(tri[1], 1u + t);
        EXPECT_EQ(tri[2], 1u + (t + 1) % 8);
        const float* a = &m.positions[3 * tri[0]];
        const float* b = &m.positions[3 * tri[1]];
        const float* c = &m.positions[3 * tri[2]];
        const double z = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
        EXPECT_GT(z, 0);
    }
}

// A faint Gaussian's patch spans only where it is visible (docs/design.md §5, rho_i = sqrt(2 ln(255 a)) < rho): its rim
// at rho_i with alpha 1/255, its UVs on the circle of radius 0.5 rho_i / rho, so that x = rho (2 uv - 1) is the local
// coordinate on every patch (one alpha texture serves all). A Gaussian below 1/255 gets a patch of zero size.
TEST(SplatPatches, FaintGaussiansHavePatchesOfTheirVisibleRadius) {
    GaussianCloud cloud = one_gaussian();
    cloud.opacities[0] = 0.05f;
    const double rho_i = std::sqrt(2 * std::log(255 * 0.05));  // 2.2567
    const ExportMesh m = splat_patches(cloud, PolygonSettings{}, "g");
    EXPECT_FLOAT_EQ(m.colors[3], 0.05f);
    for (int k = 0; k < 8; ++k) {
        const std::size_t v = 1 + std::size_t(k);
        const double theta = 2 * M_PI * k / 8;
        EXPECT_NEAR(m.positions[3 * v], 1 + rho_i * 0.5 * std::cos(theta), 1e-5);
        EXPECT_NEAR(m.positions[3 * v + 1], 2 + rho_i * 0.2 * std::sin(theta), 1e-5);
        EXPECT_NEAR(m.colors[4 * v + 3], 1.0 / 255, 1e-8);
        const double x = 3.0 * (2 * m.uvs[2 * v] - 1), y = 3.0 * (2 * m.uvs[2 * v + 1] - 1);
        EXPECT_NEAR(x, rho_i * std::cos(theta), 1e-5);
        EXPECT_NEAR(y, rho_i * std::sin(theta), 1e-5);
        EXPECT_NEAR(0.05 * std::exp(-0.5 * (x * x + y * y)), m.colors[4 * v + 3], 1e-8);  // the texture agrees
    }
    cloud.opacities[0] = 0.003f;
    const ExportMesh invisible = splat_patches(cloud, PolygonSettings{}, "g");
    ASSERT_EQ(invisible.vertex_count(), 9u);
    for (std::size_t v = 1; v < 9; ++v) {
        for (int c = 0; c < 3; ++c) EXPECT_EQ(invisible.positions[3 * v + c], invisible.positions[c]);
        EXPECT_FLOAT_EQ(invisible.uvs[2 * v], 0.5f);
    }
}

TEST(SplatPatches, PartsHoldAtMost65535VerticesWithLocalIndices) {
    const GaussianCloud cloud = read_splat_file(data_path("donut_sh0.ply"));
    const ExportMesh m = splat_patches(cloud, PolygonSettings{}, "donut");
    ASSERT_EQ(m.vertex_count(), 9 * cloud.size());
    ASSERT_GT(m.parts.size(), 1u);
    std::size_t vertices = 0, triangles = 0;
    for (const ExportMeshPart& p : m.parts) {
        EXPECT_LE(p.vertex_count, 65535u);
        EXPECT_EQ(p.vertex_begin, vertices);
        EXPECT_EQ(p.triangle_begin, triangles);
        vertices += p.vertex_count, triangles += p.triangle_count;
    }
    EXPECT_EQ(vertices, m.vertex_count());
    EXPECT_EQ(triangles, m.triangle_count());
    EXPECT_NO_THROW(m.check_consistent());
}

TEST(TriangleMesh, SplitsByMaterialTransformsAndColoursByBaseColour) {
    // Two triangles sharing an edge, with materials 1 and 0 (slots), moved by +10 in x and scaled by 2 in z.
    const float positions[] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, 0};
    const float normals[] = {0, 0, 1, 0, 0, 1, 0, 0, 1, 0, 0, 1};
    const std::uint32_t triangles[] = {0, 1, 2, 1, 3, 2};
    const std::int32_t materials[] = {1, 0};
    std::vector<ExportMaterial> mats(2);
    mats[0].base_color[0] = 1, mats[1].base_color[1] = 1;
    TriangleMeshView view;
    view.positions = positions, view.vertex_count = 4, view.normals = normals;
    view.triangles = triangles, view.triangle_count = 2, view.triangle_materials = materials;
    const double transform[16] = {1, 0, 0, 10, 0, 1, 0, 0, 0, 0, 2, 0, 0, 0, 0, 1};
    const ExportMesh m = triangle_mesh(view, transform, {0, 1}, mats, "two");
    ASSERT_EQ(m.parts.size(), 2u);
    EXPECT_EQ(m.parts[0].material, 0);  // triangle 1 (slot 0) first
    EXPECT_EQ(m.parts[0].vertex_count, 3u);
    EXPECT_EQ(m.parts[1].material, 1);
    EXPECT_EQ(m.vertex_count(), 6u);  // each part its own compact vertices
    EXPECT_FLOAT_EQ(m.positions[0], 11.0f);  // vertex 1 of the input, moved
    EXPECT_FLOAT_EQ(m.colors[0], 1.0f);      // material 0's base colour (red)
    EXPECT_FLOAT_EQ(m.colors[4 * 3 + 1], 1.0f);  // part 1: material 1 (green)
    EXPECT_NEAR(m.normals[2], 1.0, 1e-6);
    EXPECT_NO_THROW(m.check_consistent());
}

TEST(PolygonMesh, FanTriangulatesEachFaceWithOneVertexPerCorner) {
    const float verts[] = {0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0, 2, 0, 0};
    const std::int32_t corners[] = {0, 1, 2, 3, 1, 4, 2};
    const std::int32_t starts[] = {0, 4}, counts[] = {4, 3};
    PolygonMeshView view;
    view.vertex_positions = verts, view.vertex_count = 5;
    view.corner_vertices = corners, view.corner_count = 7;
    view.face_corner_start = starts, view.face_corner_count = counts, view.face_count = 2;
    const double identity[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
    const ExportMesh m = polygon_mesh(view, nullptr, nullptr, identity, "p");
    EXPECT_EQ(m.vertex_count(), 7u);
    EXPECT_EQ(m.triangle_count(), 3u);
    EXPECT_NEAR(m.normals[2], 1.0, 1e-6);
}

// ---------------------------------------------------------------------------------------------------------
// Files read back

TEST(MeshFiles, GlbReadsBackWithTinygltfAndTheCentreVertexColour) {
    const std::string path = tmp_path("one.glb");
    const MeshWriteStats stats = write_mesh_file(path, patch_scene(one_gaussian()));
    EXPECT_EQ(stats.vertices, 9u);
    EXPECT_EQ(stats.bytes, fs::file_size(path));
    tinygltf::TinyGLTF loader;
    tinygltf::Model model;
    std::string err, warn;
    ASSERT_TRUE(loader.LoadBinaryFromFile(&model, &err, &warn, path)) << err;
    ASSERT_EQ(model.meshes.size(), 1u);
    const tinygltf::Primitive& prim = model.meshes[0].primitives[0];
    EXPECT_EQ(model.materials[size_t(prim.material)].alphaMode, "BLEND");
    const tinygltf::Accessor& pos = model.accessors[size_t(prim.attributes.at("POSITION"))];
    EXPECT_EQ(pos.count, 9u);
    EXPECT_NEAR(pos.minValues[0], -0.5, 1e-6);
    EXPECT_NEAR(pos.maxValues[0], 2.5, 1e-6);
    const tinygltf::Accessor& col = model.accessors[size_t(prim.attributes.at("COLOR_0"))];
    ASSERT_EQ(col.componentType, TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE);
    const tinygltf::BufferView& view = model.bufferViews[size_t(col.bufferView)];
    const std::uint8_t* c = model.buffers[0].data.data() + view.byteOffset + col.byteOffset;
    EXPECT_EQ(c[0], std::lround(srgb_to_linear(0.7) * 255));  // linear, as glTF requires
    EXPECT_EQ(c[3], std::lround(0.8 * 255));                   // centre alpha: the opacity
    EXPECT_EQ(c[4 + 3], std::lround(0.8 * std::exp(-4.5) * 255));  // rim alpha
    EXPECT_EQ(model.accessors[size_t(prim.indices)].count, 24u);
}

TEST(MeshFiles, GltfWithSeparateBinReadsBack) {
    const std::string path = tmp_path("one_text.gltf");
    write_mesh_file(path, patch_scene(one_gaussian()));
    EXPECT_TRUE(fs::exists(tmp_path("one_text.bin")));
    tinygltf::TinyGLTF loader;
    tinygltf::Model model;
    std::string err, warn;
    ASSERT_TRUE(loader.LoadASCIIFromFile(&model, &err, &warn, path)) << err;
    EXPECT_EQ(model.buffers[0].uri, "one_text.bin");
    EXPECT_EQ(model.accessors[size_t(model.meshes[0].primitives[0].attributes.at("POSITION"))].count, 9u);
}

TEST(MeshFiles, DracoPrimitivesDecodeToTheExportedCounts) {
    const GaussianCloud cloud = read_splat_file(data_path("small_sh3_inria.ply"));
    const ExportScene scene = patch_scene(cloud);
    const std::string path = tmp_path("draco.glb");
    MeshWriteOptions options;
    options.draco.enabled = true;
    write_mesh_file(path, scene, options);
    // tinygltf 2.7's loader rejects accessors without a bufferView (as Draco's are), so the GLB is parsed here.
    const std::vector<std::uint8_t> bytes = read_bytes(path);
    ASSERT_EQ(std::memcmp(bytes.data(), "glTF", 4), 0);
    std::uint32_t json_length, bin_length;
    std::memcpy(&json_length, bytes.data() + 12, 4);
    std::memcpy(&bin_length, bytes.data() + 20 + json_length, 4);
    const std::uint8_t* bin = bytes.data() + 20 + json_length + 8;
    const nlohmann::json doc = nlohmann::json::parse(bytes.begin() + 20, bytes.begin() + 20 + json_length);
    ASSERT_EQ(doc["extensionsRequired"], nlohmann::json::array({"KHR_draco_mesh_compression"}));
    const ExportMesh& mesh = scene.meshes[0];
    const auto& primitives = doc["meshes"][0]["primitives"];
    ASSERT_EQ(primitives.size(), mesh.parts.size());
    std::size_t points = 0, faces = 0;
    for (std::size_t p = 0; p < mesh.parts.size(); ++p) {
        const auto& prim = primitives[p];
        const auto& ext = prim["extensions"]["KHR_draco_mesh_compression"];
        const auto& view = doc["bufferViews"][ext["bufferView"].get<int>()];
        const std::size_t offset = view.value("byteOffset", std::size_t(0)), length = view["byteLength"];
        ASSERT_LE(offset + length, bin_length);
        draco::DecoderBuffer buffer;
        buffer.Init(reinterpret_cast<const char*>(bin + offset), length);
        draco::Decoder decoder;
        auto decoded = decoder.DecodeMeshFromBuffer(&buffer);
        ASSERT_TRUE(decoded.ok()) << decoded.status().error_msg_string();
        const draco::Mesh& dm = *decoded.value();
        EXPECT_EQ(dm.num_points(), mesh.parts[p].vertex_count);
        EXPECT_EQ(dm.num_faces(), mesh.parts[p].triangle_count);
        const auto& acc = doc["accessors"][prim["attributes"]["POSITION"].get<int>()];
        EXPECT_EQ(acc["count"].get<std::size_t>(), mesh.parts[p].vertex_count);
        EXPECT_FALSE(acc.contains("bufferView"));
        // The same positions within the 14-bit quantisation step of the part's extent. Edgebreaker reorders the
        // points, so each coordinate's sorted values are compared (sorting keeps an elementwise bound).
        const draco::PointAttribute* pa = dm.GetAttributeByUniqueId(ext["attributes"]["POSITION"].get<std::uint32_t>());
        ASSERT_NE(pa, nullptr);
        ASSERT_NE(dm.GetAttributeByUniqueId(ext["attributes"]["COLOR_0"].get<std::uint32_t>()), nullptr);
        double extent = 0;
        for (int c = 0; c < 3; ++c) extent = std::max(extent, acc["max"][c].get<double>() - acc["min"][c].get<double>());
        const ExportMeshPart& part = mesh.parts[p];
        for (int c = 0; c < 3; ++c) {
            std::vector<float> got(part.vertex_count), want(part.vertex_count);
            for (std::size_t v = 0; v < part.vertex_count; ++v) {
                float value[3];
                pa->GetMappedValue(draco::PointIndex(std::uint32_t(v)), value);
                got[v] = value[c];
                want[v] = mesh.positions[3 * (part.vertex_begin + v) + c];
            }
            std::sort(got.begin(), got.end());
            std::sort(want.begin(), want.end());
            for (std::size_t v = 0; v < part.vertex_count; ++v) ASSERT_NEAR(got[v], want[v], extent / (1 << 13));
        }
        points += dm.num_points(), faces += dm.num_faces();
    }
    EXPECT_EQ(points, 9 * cloud.size());
    EXPECT_EQ(faces, 8 * cloud.size());
}

TEST(MeshFiles, PlyIsBinaryWithRgbaAndUvs) {
    const std::string path = tmp_path("one.ply");
    write_mesh_file(path, patch_scene(one_gaussian()));
    const std::vector<std::uint8_t> bytes = read_bytes(path);
    const std::string text(bytes.begin(), bytes.end());
    const std::size_t end = text.find("end_header\n");
    ASSERT_NE(end, std::string::npos);
    const std::string header = text.substr(0, end);
    for (const char* line : {"format binary_little_endian 1.0", "element vertex 9", "property float x",
                             "property float s", "property float t", "property uchar red", "property uchar alpha",
                             "element face 8"})
        EXPECT_NE(header.find(line), std::string::npos) << line;
    // Vertex record: x y z s t r g b a (OpenMesh's order); the centre vertex first.
    const std::uint8_t* v = bytes.data() + end + 11;
    float xyz[3];
    std::memcpy(xyz, v, 12);
    EXPECT_FLOAT_EQ(xyz[0], 1.0f);
    EXPECT_EQ(v[20], std::lround(0.7 * 255));  // sRGB display value
    EXPECT_EQ(v[23], std::lround(0.8 * 255));
}

TEST(MeshFiles, ObjHasColouredVerticesGroupsAndMaterials) {
    ExportScene scene = patch_scene(one_gaussian());
    ExportMaterial red;
    red.name = "Red Metal";
    red.base_color[0] = 1, red.base_color[1] = 0, red.base_color[2] = 0;
    red.metallic = 1;
    scene.materials.push_back(red);
    const float positions[] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
    const std::uint32_t tri[] = {0, 1, 2};
    TriangleMeshView view;
    view.positions = positions, view.vertex_count = 3, view.triangles = tri, view.triangle_count = 1;
    const double identity[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
    scene.meshes.push_back(triangle_mesh(view, identity, {1}, scene.materials, "Cube"));
    const std::string path = tmp_path("scene.obj");
    write_mesh_file(path, scene);
    std::ifstream in(path);
    std::string line;
    std::vector<std::string> v_lines, markers;
    std::size_t faces = 0;
    while (std::getline(in, line)) {
        if (line.rfind("v ", 0) == 0) v_lines.push_back(line);
        if (line.rfind("f ", 0) == 0) ++faces;
        if (line.rfind("o ", 0) == 0 || line.rfind("usemtl ", 0) == 0 || line.rfind("mtllib ", 0) == 0)
            markers.push_back(line);
    }
    ASSERT_EQ(v_lines.size(), 12u);
    EXPECT_EQ(faces, 9u);
    EXPECT_EQ(markers, (std::vector<std::string>{"mtllib scene.mtl", "o splats", "usemtl splats", "o Cube",
                                                 "usemtl Red_Metal"}));
    std::istringstream first(v_lines[0]);
    std::string tag;
    double x, y, z, r, g, b;
    first >> tag >> x >> y >> z >> r >> g >> b;
    EXPECT_NEAR(r, 0.7, 1e-5);  // sRGB display value
    EXPECT_NEAR(b, 0.3, 1e-5);
    std::ifstream mtl(tmp_path("scene.mtl"));
    std::stringstream mtl_text;
    mtl_text << mtl.rdbuf();
    EXPECT_NE(mtl_text.str().find("newmtl Red_Metal\nKd 1.000000 0.000000 0.000000"), std::string::npos);
    EXPECT_NE(mtl_text.str().find("Pm 1.000000"), std::string::npos);
}

// ---------------------------------------------------------------------------------------------------------
// Errors

TEST(MeshFileErrors, EmptySceneUnknownFormatAndUnwritablePath) {
    EXPECT_THROW(write_mesh_file(tmp_path("empty.glb"), ExportScene{}), InvalidArgument);
    EXPECT_FALSE(fs::exists(tmp_path("empty.glb")));
    EXPECT_THROW(write_mesh_file(tmp_path("x.fbx"), patch_scene(one_gaussian())), InvalidArgument);
    for (const char* ext : {".glb", ".gltf", ".ply", ".obj"}) {
        try {
            write_mesh_file(std::string("/nonexistent-dir/scene") + ext, patch_scene(one_gaussian()));
            ADD_FAILURE() << "no error for " << ext;
        } catch (const FileFormatError& e) {
            EXPECT_NE(std::string(e.what()).find("/nonexistent-dir/"), std::string::npos) << e.what();
        }
    }
}

TEST(MeshFileErrors, FailedWriteLeavesTheOldFileAndNoTemporaries) {
    const std::string path = tmp_path("keep.glb");
    write_mesh_file(path, patch_scene(one_gaussian()));
    const std::vector<std::uint8_t> before = read_bytes(path);
    ExportScene bad = patch_scene(one_gaussian());
    bad.meshes[0].triangles[0] = 1000;  // out of range: rejected before anything is written
    EXPECT_THROW(write_mesh_file(path, bad), InvalidArgument);
    MeshWriteOptions options;
    options.draco.enabled = true;
    options.draco.position_bits = 99;
    EXPECT_THROW(write_mesh_file(path, patch_scene(one_gaussian()), options), InvalidArgument);
    EXPECT_EQ(read_bytes(path), before);
    for (const auto& entry : fs::directory_iterator(fs::path(path).parent_path()))
        EXPECT_EQ(entry.path().filename().string().find("keep.glb.tmp"), std::string::npos) << entry.path();
}

}  // namespace
}  // namespace raysplats
