// A SOG scene's meta.json (sog_format.cpp gives the format and its sources, cited here as there): read, bounded and
// checked into a SogMeta, whose tables turn every byte value of the images into what it stands for. Version 2
// ("version": 2, "count"), or version 1 (no "version"; count = means.shape[0]). Internal to the SOG reader.
//
// Hostile input: meta.json at most 1 MiB and 64 levels deep; each number finite; every file name a relative path
// inside the scene; the count at most what a WebP image can hold; a palette of at most 65536 entries.
#pragma once

#include <cstdint>
#include <string>

#include "io/sog_files.h"

namespace raysplats {
namespace io {

// WebP images are at most 16383 x 16383 pixels (the VP8L header's 14-bit sizes): no SOG holds more splats.
constexpr std::uint64_t kMaxSogSplats = std::uint64_t(16383) * 16383;
constexpr std::uint64_t kMaxSogPaletteEntries = 65536;  // 16-bit labels [spec 3.5]

struct SogMeta {
    int version = 2;
    std::uint64_t count = 0;
    bool antialias = false;
    double means_min[3] = {}, means_max[3] = {};
    std::string means_files[2], quats_file, scales_file, sh0_file;
    // Per byte value: log scale per axis, SH DC per channel, opacity (linear), and SH rest. Entries at and beyond a
    // codebook's size are not valid indices (`*_valid`).
    float scale_lut[3][256] = {}, dc_lut[3][256] = {}, opacity_lut[256] = {}, shn_lut[256] = {};
    int scale_valid = 256, dc_valid = 256, shn_valid = 256;
    bool has_shn = false;
    int bands = 0;                    // v2: from meta; v1: from the centroids image's width
    std::uint64_t palette_count = 0;  // v2: shN.count; v1: from the centroids image's size
    std::string centroids_file, labels_file;
    // v1 only, for the probe: shN.shape[1] if present (coefficients per entry, 3 or 45 ...).
    std::int64_t v1_shn_shape_coeffs = -1;
};

// Reads and checks the scene's meta.json. Throws FileFormatError (through files.error, about meta.json) for JSON
// that is malformed, too large or too deep, and for any field that is missing, of the wrong type or out of range.
SogMeta read_sog_meta(SogFiles& files);

}  // namespace io
}  // namespace raysplats
