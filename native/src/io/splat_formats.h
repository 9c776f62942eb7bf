// The splat format registry (not part of the public API): one row per format, with the functions that detect, read,
// probe and write it. splat_file.cpp's read_splat_file, probe_splat_file and write_splat_file loop over the rows;
// splat_formats.cpp holds the table; each format's functions live in its own file (ply_format.cpp, ...), declared
// below. A new format is its reader file, one row of the table and its tests.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "io/io_common.h"
#include "raysplats/gaussian_cloud.h"
#include "raysplats/splat_io.h"

namespace raysplats {
namespace io {

// What a file's first bytes and name say about one format: its signature is there (content wins over names), or
// only its name says so (a format without a signature, or a file that may lack one), or nothing.
enum class Evidence { None, Name, Signature };

struct SplatFormatRow {
    // name, endings, description, up axis (splat_io.h); `writable` is set from `write` below.
    SplatFormatInfo info;
    // No signature: any bytes can begin such a file (.splat: its first float may spell another format's magic by
    // chance). A file whose name ends in such a format's ending takes another format only on a full signature, which
    // `detect` is told through `headerless_name`.
    bool headerless = false;
    // Whether `data` (the whole file, `size` bytes) named `name` is this format. Null for a format another row's
    // reader hands over by its header (a compressed PLY is a PLY file: the PLY row finds it, read_ply passes it on).
    Evidence (*detect)(const std::uint8_t* data, std::size_t size, const std::string& name, bool headerless_name) = nullptr;
    GaussianCloud (*read)(const FileBytes& f, const ReadOptions& options, LoadReport* report) = nullptr;
    // What the header says, without decoding the data (splat_io.h: probe_splat_file).
    SplatFileSummary (*probe)(const FileBytes& f) = nullptr;
    // Null for a format read only here; write_splat_file then refuses it with `read_only_reason`.
    void (*write)(const std::string& path, const GaussianCloud& cloud) = nullptr;
    const char* read_only_reason = nullptr;
};

// The rows, in the order of splat_io.h's splat_formats() (the order the add-on lists them in).
const std::vector<SplatFormatRow>& splat_format_table();
const SplatFormatRow& splat_format_row(SplatFormat format);
// The row of the format of a file's bytes (io_common.h: detect_splat_format gives its SplatFormat).
const SplatFormatRow& detect_splat_row(const std::uint8_t* data, std::size_t size, const std::string& name);

// Whether data starts with the n bytes of `magic`.
inline bool starts_with(const std::uint8_t* data, std::size_t size, const char* magic, std::size_t n) {
    return size >= n && std::memcmp(data, magic, n) == 0;
}

// ---------------------------------------------------------------------------------------------------------
// Each format's functions: the row's (on a FileBytes: reading a file and reading the same bytes in memory run the
// same code and give the same errors; every error names f.path()), and the entry points the tests, fuzz targets and
// benchmarks call directly (on a path or on bytes in memory).

// INRIA 3DGS PLY (ply_format.cpp): ascii, binary little or big endian; properties by name in any order, any PLY
// scalar type; SH degree from the number of f_rest_* (0, 9, 24, 45); other properties and elements are ignored. A
// compressed PLY (below) is recognised by its header and read as such.
Evidence detect_ply(const std::uint8_t* data, std::size_t size, const std::string& name, bool headerless_name);
GaussianCloud read_ply(const FileBytes& f, const ReadOptions& options, LoadReport* report);  // also compressed PLY
SplatFileSummary probe_ply(const FileBytes& f);

// antimatter15 .splat (dot_splat_format.cpp): 32-byte records, no header; SH degree 0.
Evidence detect_dot_splat(const std::uint8_t* data, std::size_t size, const std::string& name, bool headerless_name);
GaussianCloud read_dot_splat(const FileBytes& f, const ReadOptions& options, LoadReport* report);
SplatFileSummary probe_dot_splat(const FileBytes& f);

// Niantic SPZ (spz_format.cpp) versions 2 and 3 (gzip) and 4 (zstd streams). SPZ stores RUB (x right, y up, z back);
// the cloud comes out in the core's RDF like every reader's: positions, rotations and SH rotated 180° about x.
Evidence detect_spz(const std::uint8_t* data, std::size_t size, const std::string& name, bool headerless_name);
GaussianCloud read_spz(const FileBytes& f, const ReadOptions& options, LoadReport* report);
SplatFileSummary probe_spz(const FileBytes& f);
// Whether bytes are a gzip member whose content starts with SPZ's 'NGSP' magic (inflates 4 bytes).
bool gzip_holds_spz(const std::uint8_t* data, std::size_t size);

// glTF 2.0 (gltf_splat_format.cpp; .glb, or .gltf with its buffers beside it) carrying KHR_gaussian_splatting
// (ratified text): every splat primitive the default scene places, through its node's world transform, in one cloud
// (SH degree the highest of them, missing bands zero), converted from glTF's frame (+Y up) to the core's RDF. Other
// primitives are ignored. A file without splat primitives is refused with a message that points to Blender's glTF
// importer. Accessors are bounds-checked against their buffers before anything is allocated (memory proportional to
// the file). Bytes in memory (a .glb, or a .gltf whose buffers are data: URIs) have no folder for external buffers.
// Written by the mesh export (raysplats/mesh_export.h), not here.
Evidence detect_gltf(const std::uint8_t* data, std::size_t size, const std::string& name, bool headerless_name);
GaussianCloud read_gltf_splats(const FileBytes& f, const ReadOptions& options, LoadReport* report);
SplatFileSummary probe_gltf(const FileBytes& f);  // parses the JSON and checks the accessors

// SuperSplat / PlayCanvas compressed PLY (compressed_ply_format.cpp; SuperSplat's default export): element 'chunk'
// with per-256-splat bounds, element 'vertex' of packed_position / packed_rotation / packed_scale / packed_color
// (uint32), optional element 'sh' of uchar f_rest_*. Positions are in the INRIA PLY's axes (the core's RDF). The PLY
// reader and probe hand a file over when is_compressed_ply says its header has the 'chunk' element and packed vertex
// properties.
struct PlyHeader;
bool is_compressed_ply(const PlyHeader& header);
GaussianCloud read_compressed_ply_data(const std::uint8_t* data, std::size_t size, const std::string& path,
                                       const PlyHeader& header, const ReadOptions& options, LoadReport* report);
SplatFileSummary probe_compressed_ply(const std::uint8_t* data, std::size_t size, const std::string& path,
                                      const PlyHeader& header);

// PlayCanvas SOG (sog_format.cpp gives the format and its sources), versions 1 and 2: a .sog bundle (a zip of
// meta.json and lossless WebP images) or an unbundled meta.json with the images beside it. No axes are converted:
// PlayCanvas's tools store a SOG in the axes of the .ply it came from (the core's RDF). Every bound a hostile file
// could abuse (zip sizes, image sizes, codebook and palette indices) is checked before allocating. Read only.
Evidence detect_sog(const std::uint8_t* data, std::size_t size, const std::string& name, bool headerless_name);
GaussianCloud read_sog(const FileBytes& f, const ReadOptions& options, LoadReport* report);
SplatFileSummary probe_sog(const FileBytes& f);
// Whether a file is SOG: zip magic in its first bytes, or a name ending in .sog or meta.json.
bool is_sog_file(const std::string& path, const std::uint8_t* head, std::size_t head_size);

}  // namespace io

// The readers on a path, or on bytes in memory (`name` stands for the file in errors; never reads outside
// [data, data + size)), for tests, fuzz targets and benchmarks that exercise one format.
GaussianCloud read_ply(const std::string& path, const ReadOptions& options = {}, LoadReport* report = nullptr);
GaussianCloud read_dot_splat(const std::string& path, const ReadOptions& options = {}, LoadReport* report = nullptr);
GaussianCloud read_spz(const std::string& path, const ReadOptions& options = {}, LoadReport* report = nullptr);
GaussianCloud read_sog(const std::string& path, const ReadOptions& options = {}, LoadReport* report = nullptr);
GaussianCloud read_sog_bundle(const std::uint8_t* data, std::size_t size, const std::string& name,
                              const ReadOptions& options = {}, LoadReport* report = nullptr);
GaussianCloud read_gltf_splats(const std::string& path, const ReadOptions& options = {}, LoadReport* report = nullptr);
GaussianCloud read_gltf_splats_from_memory(const std::uint8_t* data, std::size_t size, const std::string& name,
                                           const ReadOptions& options = {}, LoadReport* report = nullptr);
GaussianCloud read_compressed_ply(const std::string& path, const ReadOptions& options = {}, LoadReport* report = nullptr);
GaussianCloud read_compressed_ply_bytes(const std::uint8_t* data, std::size_t size, const std::string& name,
                                        const ReadOptions& options = {}, LoadReport* report = nullptr);

// The writers (the rows' `write`): each throws InvalidArgument for an inconsistent cloud (before touching any file)
// and FileFormatError naming the path when the file cannot be written; atomic (io_common.h: AtomicFileWriter).
// INRIA layout, binary little endian, exactly the reference property order:
// x y z nx ny nz f_dc_0..2 f_rest_0..(3*(K-1)-1) opacity scale_0..2 rot_0..3 (opacity logit, scales log).
// Normals are 0; opacity is clamped to [1e-7, 1-1e-7] and scales to >= 1e-30 first, so the file holds no Inf.
void write_ply(const std::string& path, const GaussianCloud& cloud);
// 32-byte records: position float3, scale float3 (linear), RGBA uint8 (colour from SH DC, alpha = opacity),
// quaternion uint8x4 (w x y z, (q*128)+128). Higher SH bands are lost (the format has none).
void write_dot_splat(const std::string& path, const GaussianCloud& cloud);
// SPZ version 4 (zstd streams), as current Niantic tools write, in SPZ's RUB (rotated 180° about x from the
// cloud's RDF). Quantised: positions 24-bit fixed point
// (12 fractional bits, fewer only if the scene needs the range), opacity and colour 8 bits, log scale in
// steps of 1/16 over [-10, 6), rotation 9-bit smallest three, higher SH bands 8 bits over [-1, 1).
void write_spz(const std::string& path, const GaussianCloud& cloud);
// Compressed PLY as SuperSplat writes it (18 chunk bounds; chunks of 256 splats in Morton order of their centres, or
// in the cloud's order when that is as compact: see compressed_ply_format.cpp). Per chunk, with its extent E of each
// quantity, a read gives back: positions within E/4094 (x, z; 11 bits) and E/2046 (y; 10 bits); log scales the
// same, within [-20, 20]; colour (0.5 + SH_C0 f_dc) within E/510; opacity within 1/510; each of the three smaller
// quaternion components within sqrt(2)/2046; higher SH bands within 1/64 on [-4, 4) (clamped beyond).
void write_compressed_ply(const std::string& path, const GaussianCloud& cloud);

}  // namespace raysplats
