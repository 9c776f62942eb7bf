// Reading and writing splat files, whatever their format: the format table (the names, file endings and
// conventions of the formats the core reads and writes: INRIA 3DGS .ply, antimatter15 .splat, Niantic .spz,
// SuperSplat's compressed .ply, the KHR_gaussian_splatting primitives of glTF files, PlayCanvas SOG; docs/design.md
// §4) and the generic calls that dispatch on it. Each format's own functions are internal (native/src/io/
// splat_formats.h). Every reader throws FileFormatError naming the file (and byte offset) on bad input; writers are
// atomic (temporary file in the same folder, then rename), so a failed write never replaces a good file.
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

// The format a file name ends with: the longest of the table's endings that matches (case-insensitive; so
// "a.compressed.ply" is a compressed PLY and "a.ply" an INRIA one), and the length of that ending; format is null when
// none matches. `writable_only`: among the formats the core writes. The one place the rule is written (the add-on
// asks it through the bindings).
struct SplatFormatMatch {
    const SplatFormatInfo* format = nullptr;
    std::size_t ending_length = 0;
};
SplatFormatMatch match_splat_format(const std::string& path, bool writable_only = false);
// The table's endings joined by `separator` (".ply, .splat, ..."), for messages and help texts.
std::string splat_endings_text(bool writable_only = false, const std::string& separator = ", ");
// Format from the file name's ending (match_splat_format); throws FileFormatError when none matches.
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

// Reads any supported file; the format comes from the content (each format's signature: PLY magic, gzip or SPZ
// magic, glTF magic, zip magic for a .sog), falling back to the name for the headerless .splat, a .gltf and SOG's
// meta.json. Quaternions come out normalised, scales linear, opacities linear. Non-finite values are dropped or repaired and counted in `report`.
GaussianCloud read_splat_file(const std::string& path, const ReadOptions& options = {}, LoadReport* report = nullptr);

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

// Writes the format given by the name's ending (match_splat_format; a read-only format, glTF or SOG, is refused with
// FileFormatError). Throws InvalidArgument for an inconsistent cloud (before touching any file) and FileFormatError
// naming the path when the file cannot be written.
void write_splat_file(const std::string& path, const GaussianCloud& cloud);

}  // namespace raysplats
