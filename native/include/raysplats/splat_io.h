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

GaussianCloud read_ply(const std::string& path, const ReadOptions& options = {}, LoadReport* report = nullptr);
GaussianCloud read_dot_splat(const std::string& path, const ReadOptions& options = {}, LoadReport* report = nullptr);
GaussianCloud read_spz(const std::string& path, const ReadOptions& options = {}, LoadReport* report = nullptr);

// Writes the format given by the extension.
void write_splat_file(const std::string& path, const GaussianCloud& cloud);

// INRIA layout, binary little endian, exactly the reference property order:
// x y z nx ny nz f_dc_0..2 f_rest_0..(3*(K-1)-1) opacity scale_0..2 rot_0..3 (opacity logit, scales log).
void write_ply(const std::string& path, const GaussianCloud& cloud);
// 32-byte records: position float3, scale float3 (linear), RGBA uint8 (colour from SH DC, alpha = opacity),
// quaternion uint8x4 (w x y z, (q*128)+128). Higher SH bands are lost (the format has none).
void write_dot_splat(const std::string& path, const GaussianCloud& cloud);
void write_spz(const std::string& path, const GaussianCloud& cloud);

}  // namespace raysplats
