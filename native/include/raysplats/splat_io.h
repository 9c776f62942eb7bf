// Reading and writing splat files: INRIA 3DGS .ply, antimatter15 .splat, Niantic .spz (DESIGN §4).
// Every reader throws FileFormatError naming the file (and byte offset) on bad input; writers are atomic
// (temporary file in the same folder, then rename), so a failed write never replaces a good file.
#pragma once

#include <string>

#include "raysplats/gaussian_cloud.h"

namespace raysplats {

enum class SplatFormat { Ply, Splat, Spz };

// Format from the file name's extension (.ply, .splat, .spz; case-insensitive); throws FileFormatError otherwise.
SplatFormat splat_format_from_extension(const std::string& path);
const char* splat_format_name(SplatFormat format);

// Applied by every reader, after NaN/Inf repair: splats are taken in file order, those dropped (non-finite
// position/scale/rotation, or opacity below min_opacity) are skipped, and the first max_count of the rest
// are returned.
struct ReadOptions {
    // Splats with opacity below this are not loaded (0 keeps all).
    float min_opacity = 0.0f;
    // At most this many splats are loaded, the first ones in the file (0 = no limit).
    std::size_t max_count = 0;
};

// Reads any supported file; the format comes from the content (PLY magic, gzip or SPZ magic), falling back
// to the extension for the headerless .splat. Quaternions come out normalised, scales linear, opacities
// linear. Non-finite values are dropped or repaired and counted in `report`.
GaussianCloud read_splat_file(const std::string& path, const ReadOptions& options = {}, LoadReport* report = nullptr);

// INRIA 3DGS PLY: ascii, binary little or big endian; properties by name in any order, any PLY scalar type;
// SH degree from the number of f_rest_* (0, 9, 24, 45); other properties and elements are ignored.
GaussianCloud read_ply(const std::string& path, const ReadOptions& options = {}, LoadReport* report = nullptr);
// antimatter15 .splat (32-byte records); SH degree 0.
GaussianCloud read_dot_splat(const std::string& path, const ReadOptions& options = {}, LoadReport* report = nullptr);
// Niantic SPZ versions 2 and 3 (gzip) and 4 (zstd streams). Coordinates are returned as stored in the file,
// without the reference library's optional axis conversion (see spz_format.cpp for the reasoning).
GaussianCloud read_spz(const std::string& path, const ReadOptions& options = {}, LoadReport* report = nullptr);

// Writes the format given by the extension. All writers throw InvalidArgument for an inconsistent cloud
// (before touching any file) and FileFormatError naming the path when the file cannot be written.
void write_splat_file(const std::string& path, const GaussianCloud& cloud);

// INRIA layout, binary little endian, exactly the reference property order:
// x y z nx ny nz f_dc_0..2 f_rest_0..(3*(K-1)-1) opacity scale_0..2 rot_0..3 (opacity logit, scales log).
// Normals are 0; opacity is clamped to [1e-7, 1-1e-7] and scales to >= 1e-30 first, so the file holds no Inf.
void write_ply(const std::string& path, const GaussianCloud& cloud);
// 32-byte records: position float3, scale float3 (linear), RGBA uint8 (colour from SH DC, alpha = opacity),
// quaternion uint8x4 (w x y z, (q*128)+128). Higher SH bands are lost (the format has none).
void write_dot_splat(const std::string& path, const GaussianCloud& cloud);
// SPZ version 4 (zstd streams), as current Niantic tools write. Quantised: positions 24-bit fixed point
// (12 fractional bits, fewer only if the scene needs the range), opacity and colour 8 bits, log scale in
// steps of 1/16 over [-10, 6), rotation 9-bit smallest three, higher SH bands 8 bits over [-1, 1).
void write_spz(const std::string& path, const GaussianCloud& cloud);

}  // namespace raysplats
