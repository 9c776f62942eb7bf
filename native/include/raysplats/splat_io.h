// Reading and writing splat files: INRIA 3DGS .ply, antimatter15 .splat, Niantic .spz, SuperSplat's compressed .ply
// (docs/design.md §4); reading the KHR_gaussian_splatting primitives of glTF files (.glb, .gltf; written by
// mesh_export.h's glTF writer) and PlayCanvas SOG (.sog bundles and unbundled meta.json folders).
// Every reader throws FileFormatError naming the file (and byte offset) on bad input; writers are atomic
// (temporary file in the same folder, then rename), so a failed write never replaces a good file.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "raysplats/gaussian_cloud.h"

namespace raysplats {

enum class SplatFormat { Ply, Splat, Spz, Gltf, CompressedPly, Sog };

// The splat formats the core reads and writes: the one list the add-on, its command line and the tools take
// their format names, file extensions and import defaults from.
struct SplatFormatInfo {
    SplatFormat format;
    const char* name;                     // "ply", "splat", "spz", "gltf", "compressed_ply", "sog"
    // Lower-case endings of the file name: an extension with its dot (possibly two dots, ".compressed.ply"), or a
    // whole name ("meta.json", SOG's unbundled form); the first is the one written. A file name takes the format of
    // the longest ending it matches.
    std::vector<const char*> extensions;
    const char* description;
    // The up direction of the cloud the reader returns: "-Y" for every format, since the readers convert to the
    // core's COLMAP convention (x right, y down, z forward; SPZ's RUB is rotated on reading and writing). Which
    // way a scene is up is a property of the scene, not of its file format (docs/design.md §4).
    const char* up_axis;
    // True when the format's specification fixes which way is up (glTF: +Y up), so the file's own axes are taken
    // as they are; false when the file only follows a habit of its producers, so the scene's data may tell better
    // (raysplats/up_axis.h).
    bool up_axis_by_specification = false;
    // False for a format the core reads but does not write as a splat file (glTF: written by the mesh export; SOG):
    // write_splat_file refuses them, export lists skip them.
    bool writable = true;
};
const std::vector<SplatFormatInfo>& splat_formats();

// Format from the file name's ending (.ply, .splat, .spz, .compressed.ply, .glb, .gltf, .sog, meta.json;
// case-insensitive; the longest ending that
// matches); throws FileFormatError otherwise.
SplatFormat splat_format_from_extension(const std::string& path);
const char* splat_format_name(SplatFormat format);

// Applied by every reader, after NaN/Inf repair: splats are taken in file order, those dropped (non-finite
// position/scale/rotation, or opacity below min_opacity) are skipped, and of the rest at most max_count are
// returned: all when they are fewer, else a uniform random choice over the whole file (fixed seed, file order kept).
struct ReadOptions {
    // Splats with opacity below this are not loaded (0 keeps all).
    float min_opacity = 0.0f;
    // At most this many splats are loaded, chosen uniformly over the whole file (0 = no limit).
    std::size_t max_count = 0;
};

// Reads any supported file; the format comes from the content (PLY magic, gzip or SPZ magic, glTF magic or a .gltf
// extension, zip magic for a .sog), falling back to the name for the headerless .splat and SOG's meta.json.
// Quaternions come out normalised, scales linear, opacities
// linear. Non-finite values are dropped or repaired and counted in `report`.
GaussianCloud read_splat_file(const std::string& path, const ReadOptions& options = {}, LoadReport* report = nullptr);

// INRIA 3DGS PLY: ascii, binary little or big endian; properties by name in any order, any PLY scalar type;
// SH degree from the number of f_rest_* (0, 9, 24, 45); other properties and elements are ignored. A compressed PLY
// (below) is recognised by its header and read as such.
GaussianCloud read_ply(const std::string& path, const ReadOptions& options = {}, LoadReport* report = nullptr);
// antimatter15 .splat (32-byte records); SH degree 0.
GaussianCloud read_dot_splat(const std::string& path, const ReadOptions& options = {}, LoadReport* report = nullptr);
// Niantic SPZ versions 2 and 3 (gzip) and 4 (zstd streams). SPZ stores RUB (x right, y up, z back); the cloud
// comes out in the core's RDF like every reader's: positions, rotations and SH rotated 180° about x.
GaussianCloud read_spz(const std::string& path, const ReadOptions& options = {}, LoadReport* report = nullptr);
// PlayCanvas SOG, versions 1 and 2 (native/src/io/sog_format.cpp gives the format and its sources): `path` is a .sog
// bundle (a zip of meta.json and lossless WebP images) or an unbundled meta.json with the images beside it. No axes
// are converted: PlayCanvas's tools store a SOG in the axes of the .ply it came from (the core's RDF). Every bound a
// hostile file could abuse (zip sizes, image sizes, codebook and palette indices) is checked before allocating.
GaussianCloud read_sog(const std::string& path, const ReadOptions& options = {}, LoadReport* report = nullptr);
// The same for a .sog bundle held in memory (`name` names it in errors): for bundles that come from elsewhere than a
// file, and for fuzzing.
GaussianCloud read_sog_bundle(const std::uint8_t* data, std::size_t size, const std::string& name,
                              const ReadOptions& options = {}, LoadReport* report = nullptr);

// glTF 2.0 (.glb, or .gltf with its buffers beside it) carrying KHR_gaussian_splatting (ratified text): every splat
// primitive the default scene places, through its node's world transform, in one cloud (SH degree the highest of
// them, missing bands zero), converted from glTF's frame (+Y up) to the core's RDF. Other primitives are ignored.
// A file without splat primitives is refused with a message that points to Blender's glTF importer. Accessors are
// bounds-checked against their buffers before anything is allocated (memory proportional to the file).
GaussianCloud read_gltf_splats(const std::string& path, const ReadOptions& options = {}, LoadReport* report = nullptr);
// The same from bytes in memory (a .glb, or a .gltf whose buffers are data: URIs); `name` names it in errors.
GaussianCloud read_gltf_splats_from_memory(const std::uint8_t* data, std::size_t size, const std::string& name,
                                           const ReadOptions& options = {}, LoadReport* report = nullptr);
// What a glTF file holds besides splats, for an importer that hands the rest to a mesh importer: its splat and
// other primitives, and the names of the meshes that hold only splat primitives.
struct GltfContents {
    std::size_t splat_primitives = 0, other_primitives = 0;
    std::vector<std::string> splat_only_meshes;
};
GltfContents gltf_contents(const std::string& path);
// SuperSplat / PlayCanvas compressed PLY (SuperSplat's default export): element 'chunk' with per-256-splat bounds,
// element 'vertex' of packed_position / packed_rotation / packed_scale / packed_color (uint32), optional element 'sh'
// of uchar f_rest_*. Positions are in the INRIA PLY's axes (the core's RDF). Quantised: see write_compressed_ply.
GaussianCloud read_compressed_ply(const std::string& path, const ReadOptions& options = {}, LoadReport* report = nullptr);
// The same from the file's bytes in memory (`name` stands for the file in error messages): for callers that hold the
// bytes (fuzzing). Never reads outside [data, data + size).
GaussianCloud read_compressed_ply_bytes(const std::uint8_t* data, std::size_t size, const std::string& name,
                                        const ReadOptions& options = {}, LoadReport* report = nullptr);

// What a splat file's header says, read without decoding its data (a few bytes; SPZ 2/3: the first 16 bytes of its
// gzip stream; SOG: meta.json): for checking, before an import, that there is memory for it. Throws FileFormatError like the
// readers for a file they would refuse at its header. `count` is the number of splats the file declares
// (before any are dropped or filtered).
struct SplatFileSummary {
    SplatFormat format = SplatFormat::Ply;
    std::uint64_t count = 0;
    int sh_degree = 0;
};
SplatFileSummary probe_splat_file(const std::string& path);

// Writes the format given by the extension (not SOG, which is read only: FileFormatError). All writers throw InvalidArgument for an inconsistent cloud
// (before touching any file) and FileFormatError naming the path when the file cannot be written.
void write_splat_file(const std::string& path, const GaussianCloud& cloud);

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
