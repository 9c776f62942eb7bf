// Writes the seed corpora of the fuzz targets at build time (native/fuzz/CMakeLists.txt), from the small real scenes
// of shared/data: their first splats re-written through the project's own writers (so every seed is a valid file the
// reader accepts, and the fuzzer starts from real values), truncated headers, and edge cases the writers never make
// (ASCII and big-endian PLY, SPZ versions 2 and 3, a SOG built member by member). Nothing large is committed: the
// seeds live in the build tree.
//   make_fuzz_seeds <shared/data folder> <output folder>   (one sub-folder per target)
#include <zlib.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <utility>
#include <vector>

#include "../tests/sog_test_util.h"
#include "io/splat_formats.h"
#include "raysplats/mesh_export.h"
#include "raysplats/splat_io.h"

namespace fs = std::filesystem;
using namespace raysplats;
using Bytes = std::vector<std::uint8_t>;

namespace {

std::string g_out;

Bytes read_file(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    return Bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

void write_seed(const std::string& target, const std::string& name, const Bytes& bytes) {
    fs::create_directories(g_out + "/" + target);
    std::ofstream out(g_out + "/" + target + "/" + name, std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
}

// A reader's seed, and the same file for fuzz_splat_bytes (the dispatch), whose first byte picks the file name there
// (fuzz_splat_bytes.cpp's kNames: 0 .ply, 1 .splat, 2 .spz, 3 .sog, 4 .glb, 6 .compressed.ply).
void put(const std::string& target, const std::string& name, const Bytes& bytes) {
    write_seed(target, name, bytes);
    const std::pair<const char*, std::uint8_t> names[] = {{"ply", 0},  {"dot_splat", 1}, {"spz", 2},
                                                          {"sog", 3},  {"gltf", 4},      {"compressed_ply", 6}};
    for (const auto& [reader, index] : names)
        if (target == reader && bytes.size() < (std::size_t(1) << 20)) {
            Bytes prefixed{index};
            prefixed.insert(prefixed.end(), bytes.begin(), bytes.end());
            write_seed("splat_bytes", target + "_" + name, prefixed);
        }
}
void put(const std::string& target, const std::string& name, const std::string& text) { put(target, name, Bytes(text.begin(), text.end())); }

Bytes head(const Bytes& b, std::size_t n) { return Bytes(b.begin(), b.begin() + std::min(n, b.size())); }

GaussianCloud first(const GaussianCloud& c, std::size_t n) {
    n = std::min(n, c.size());
    GaussianCloud out;
    out.resize(n, c.sh_degree);
    const std::size_t shn = std::size_t(c.coeffs_per_channel()) * 3;
    std::copy(c.positions.begin(), c.positions.begin() + 3 * n, out.positions.begin());
    std::copy(c.rotations.begin(), c.rotations.begin() + 4 * n, out.rotations.begin());
    std::copy(c.scales.begin(), c.scales.begin() + 3 * n, out.scales.begin());
    std::copy(c.opacities.begin(), c.opacities.begin() + n, out.opacities.begin());
    std::copy(c.sh.begin(), c.sh.begin() + shn * n, out.sh.begin());
    return out;
}

// A writer's file, as bytes (written to the output folder's temporary name, read back, removed).
template <typename Write>
Bytes written(Write write, const GaussianCloud& c, const std::string& extension) {
    const std::string path = g_out + "/tmp_seed" + extension;
    write(path, c);
    Bytes b = read_file(path);
    fs::remove(path);
    return b;
}

// An INRIA PLY as ASCII or big-endian binary text (the project's writer makes binary little endian only).
Bytes ply_in(const GaussianCloud& c, bool ascii) {
    const int rest = (c.coeffs_per_channel() - 1) * 3;
    std::string h = std::string("ply\nformat ") + (ascii ? "ascii" : "binary_big_endian") + " 1.0\ncomment seed\nelement vertex " +
                    std::to_string(c.size()) + "\nproperty float x\nproperty float y\nproperty float z\n";
    for (int i = 0; i < 3; ++i) h += "property float f_dc_" + std::to_string(i) + "\n";
    for (int i = 0; i < rest; ++i) h += "property float f_rest_" + std::to_string(i) + "\n";
    h += "property float opacity\n";
    for (int i = 0; i < 3; ++i) h += "property float scale_" + std::to_string(i) + "\n";
    for (int i = 0; i < 4; ++i) h += "property float rot_" + std::to_string(i) + "\n";
    h += "end_header\n";
    Bytes out(h.begin(), h.end());
    const int K = c.coeffs_per_channel();
    for (std::size_t i = 0; i < c.size(); ++i) {
        std::vector<float> v = {c.positions[3 * i], c.positions[3 * i + 1], c.positions[3 * i + 2]};
        for (int ch = 0; ch < 3; ++ch) v.push_back(c.sh[(i * K) * 3 + ch]);
        for (int ch = 0; ch < 3; ++ch)  // f_rest: channel-major, as the INRIA files
            for (int k = 1; k < K; ++k) v.push_back(c.sh[(i * K + k) * 3 + ch]);
        v.push_back(std::log(c.opacities[i] / (1.0f - c.opacities[i] + 1e-7f) + 1e-7f));
        for (int j = 0; j < 3; ++j) v.push_back(std::log(c.scales[3 * i + j] + 1e-30f));
        for (int j = 0; j < 4; ++j) v.push_back(c.rotations[4 * i + j]);
        for (float x : v) {
            if (ascii) {
                const std::string s = std::to_string(x) + " ";
                out.insert(out.end(), s.begin(), s.end());
            } else {
                std::uint8_t b[4];
                std::memcpy(b, &x, 4);
                for (int j = 3; j >= 0; --j) out.push_back(b[j]);
            }
        }
        if (ascii) out.back() = '\n';
    }
    return out;
}

Bytes gzip(const Bytes& in) {
    z_stream zs{};
    deflateInit2(&zs, 9, Z_DEFLATED, 16 + MAX_WBITS, 8, Z_DEFAULT_STRATEGY);
    Bytes out(deflateBound(&zs, uLong(in.size())) + 64);
    zs.next_in = const_cast<Bytef*>(in.data());
    zs.avail_in = uInt(in.size());
    zs.next_out = out.data();
    zs.avail_out = uInt(out.size());
    deflate(&zs, Z_FINISH);
    out.resize(zs.total_out);
    deflateEnd(&zs);
    return out;
}

// SPZ versions 2 and 3 (gzip; the writer makes version 4): a header and a payload of patterned bytes.
Bytes legacy_spz(std::uint32_t version, std::uint32_t n, int degree) {
    Bytes p;
    testutil::put32(p, 0x5053474e), testutil::put32(p, version), testutil::put32(p, n);
    p.push_back(std::uint8_t(degree)), p.push_back(12), p.push_back(0), p.push_back(0);
    const std::size_t sh = std::size_t((degree + 1) * (degree + 1) - 1) * 3;
    const std::size_t per = 9 + 1 + 3 + 3 + (version >= 3 ? 4 : 3) + sh;
    for (std::size_t i = 0; i < n * per; ++i) p.push_back(std::uint8_t(37 * i + 11));
    return gzip(p);
}

}  // namespace

int main(int argc, char** argv) {
    if (argc != 3) {
        std::fprintf(stderr, "usage: make_fuzz_seeds <shared/data folder> <output folder>\n");
        return 2;
    }
    const std::string data = argv[1];
    g_out = argv[2];
    fs::create_directories(g_out);
    try {
        const GaussianCloud sh3 = first(read_splat_file(data + "/small_sh3_inria.ply"), 300);
        const GaussianCloud sh0 = first(read_splat_file(data + "/donut_sh0.ply"), 300);
        const GaussianCloud s16 = first(sh3, 16), d16 = first(sh0, 16);

        // PLY (and the compressed PLY its header hands over).
        const Bytes ply3 = written(write_ply, s16, ".ply");
        put("ply", "sh3_16.ply", ply3);
        put("ply", "sh0_16.ply", written(write_ply, d16, ".ply"));
        put("ply", "ascii_sh1.ply", ply_in(first(s16, 3), true));  // SH 3 written as ASCII
        put("ply", "big_endian.ply", ply_in(first(d16, 4), false));
        put("ply", "header_only.ply", head(ply3, std::string(ply3.begin(), ply3.end()).find("end_header") + 11));
        put("ply", "truncated_header.ply", head(ply3, 200));
        put("ply", "point_cloud.ply", std::string("ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
                                                  "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
                                                  "end_header\n0 0 0\n1 0 0\n2 0 1\n"));
        put("ply", "compressed.ply", written(write_compressed_ply, first(sh0, 20), ".compressed.ply"));

        // Compressed PLY: a full chunk and a partial one, with and without higher SH; the real file's head.
        const Bytes cply3 = written(write_compressed_ply, sh3, ".compressed.ply");
        put("compressed_ply", "sh3_300.compressed.ply", cply3);
        put("compressed_ply", "sh0_20.compressed.ply", written(write_compressed_ply, first(sh0, 20), ".compressed.ply"));
        put("compressed_ply", "real_head.compressed.ply", head(read_file(data + "/guitar_supersplat.compressed.ply"), 3000));
        put("compressed_ply", "truncated.compressed.ply", head(cply3, cply3.size() / 3));

        // .splat: real records, the writer's, one with a negative scale.
        const Bytes splat = head(read_file(data + "/small.splat"), 32 * 48);
        put("dot_splat", "real_48.splat", splat);
        put("dot_splat", "sh3_16.splat", written(write_dot_splat, s16, ".splat"));
        Bytes negative = head(splat, 64);
        negative[12 + 3] |= 0x80;  // sign bit of the first record's scale x
        put("dot_splat", "negative_scale.splat", negative);

        // SPZ: version 4 from the writer (SH 3 and 0), the real file's head, versions 2 and 3 by hand.
        put("spz", "sh3_64.spz", written(write_spz, first(sh3, 64), ".spz"));
        put("spz", "sh0_16.spz", written(write_spz, d16, ".spz"));
        put("spz", "real_head.spz", head(read_file(data + "/biker_v4.spz"), 2048));
        put("spz", "v2_sh1.spz", legacy_spz(2, 4, 1));
        put("spz", "v3_sh3.spz", legacy_spz(3, 3, 3));
        put("spz", "v3_sh0.spz", legacy_spz(3, 5, 0));

        // SOG: a small scene built member by member (2 x 2 images), and the real scene (2 MB, with its SH palette).
        const std::string meta = testutil::sog_meta_v2(3, testutil::json_ramp(256, -5.0, 0.02), testutil::json_ramp(256, -1.0, 0.008));
        put("sog", "small.sog", testutil::make_zip(testutil::small_sog_members(3, 2, 2, meta)));
        put("sog", "unicorn_sh3.sog", read_file(data + "/unicorn_sh3.sog"));

        // glTF: the mesh export's KHR_gaussian_splatting, SH 3 and SH 0.
        for (const auto& [name, cloud] : {std::pair<const char*, const GaussianCloud*>{"sh3_16.glb", &s16}, {"sh0_16.glb", &d16}}) {
            ExportScene scene;
            scene.gaussians.push_back({"splats", *cloud, {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1}});
            MeshWriteOptions options;
            options.gaussian_splatting_extension = true;
            const std::string path = g_out + "/tmp_seed.glb";
            write_mesh_file(path, scene, options);
            put("gltf", name, read_file(path));
            fs::remove(path);
        }

        // Polygon bridge (fuzz_polygon_bridge.cpp's input layout): mode, K, SH degree, rho; then Gaussians (round trip)
        // or a raw mesh.
        Bytes round_trip = {0, 5, 1, 64, 2};
        auto floats = [](Bytes& b, std::initializer_list<float> v) {
            for (float x : v) {
                std::uint8_t q[4];
                std::memcpy(q, &x, 4);
                b.insert(b.end(), q, q + 4);
            }
        };
        for (int i = 0; i < 2; ++i) {
            floats(round_trip, {0.1f * i, 0.2f, 0.3f, 0.9f, 0.1f, 0.3f, 0.2f, 0.05f, 0.02f, 0.001f, 0.8f});
            for (int k = 0; k < 12; ++k) floats(round_trip, {0.01f * k});
        }
        round_trip.push_back(2);
        floats(round_trip, {0.5f});
        put("polygon_bridge", "round_trip.bin", round_trip);
        Bytes raw = {1, 1, 0, 64, 4, 4, 1};
        floats(raw, {0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0});
        raw.insert(raw.end(), {1, 2, 3, 4, 1, 5, 31});
        floats(raw, {1.0f, 0.1f, 3.0f, 0.2f, 0.3f, 0.4f});
        put("polygon_bridge", "raw_quad.bin", raw);
    } catch (const std::exception& e) {
        std::fprintf(stderr, "make_fuzz_seeds: %s\n", e.what());
        return 1;
    }
    return 0;
}
