// The table of splat formats (io/splat_formats.h): each row names a format (raysplats/splat_io.h: SplatFormatInfo)
// and carries its functions; the public list and the lookups by file name and by format come from it.
#include "io/splat_formats.h"

#include <cctype>
#include <cstring>
#include <string>

#include "raysplats/errors.h"

namespace raysplats {
namespace io {

namespace {

std::vector<SplatFormatRow> make_table() {
    std::vector<SplatFormatRow> rows{
        {{SplatFormat::Ply, "ply", {".ply"}, "INRIA 3D Gaussian Splatting PLY", "-Y"}, false, detect_ply, read_ply,
         probe_ply, write_ply},
        {{SplatFormat::Splat, "splat", {".splat"}, "antimatter15 .splat (32-byte records, no higher SH bands)", "-Y"},
         true, detect_dot_splat, read_dot_splat, probe_dot_splat, write_dot_splat},
        {{SplatFormat::Spz, "spz", {".spz"}, "Niantic SPZ (compressed)", "-Y"}, false, detect_spz, read_spz, probe_spz,
         write_spz},
        // glTF is +Y up by specification; the reader converts it to the core's RDF like SPZ's RUB.
        {{SplatFormat::Gltf, "gltf", {".glb", ".gltf"}, "glTF 2.0 with KHR_gaussian_splatting (import only)", "-Y", true},
         false, detect_gltf, read_gltf_splats, probe_gltf, nullptr,
         "glTF splats are written by the mesh export (KHR_gaussian_splatting), not here"},
        // A PLY file: the PLY row detects it, and read_ply / probe_ply hand it over by its header.
        {{SplatFormat::CompressedPly, "compressed_ply", {".compressed.ply"},
          "SuperSplat compressed PLY (chunks of 256 splats, 16 bytes a splat)", "-Y"},
         false, nullptr, read_ply, probe_ply, write_compressed_ply},
        {{SplatFormat::Sog, "sog", {".sog", "meta.json"},
          "PlayCanvas SOG (a .sog bundle, or the meta.json of an unbundled one); read only", "-Y"},
         false, detect_sog, read_sog, probe_sog, nullptr,
         "SOG is read only here: write .ply, .splat or .spz (PlayCanvas's splat-transform converts those to SOG)"}};
    for (SplatFormatRow& row : rows) row.info.writable = row.write != nullptr;
    return rows;
}

std::string lower_case(std::string s) {
    for (char& ch : s) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
    return s;
}

}  // namespace

const std::vector<SplatFormatRow>& splat_format_table() {
    static const std::vector<SplatFormatRow> table = make_table();
    return table;
}

const SplatFormatRow& splat_format_row(SplatFormat format) {
    for (const SplatFormatRow& row : splat_format_table())
        if (row.info.format == format) return row;
    throw InvalidArgument("splat format " + std::to_string(int(format)) + " is not in the format table");
}

}  // namespace io

const std::vector<SplatFormatInfo>& splat_formats() {
    static const std::vector<SplatFormatInfo> formats = [] {
        std::vector<SplatFormatInfo> out;
        for (const io::SplatFormatRow& row : io::splat_format_table()) out.push_back(row.info);
        return out;
    }();
    return formats;
}

SplatFormatMatch match_splat_format(const std::string& path, bool writable_only) {
    const std::string lower = io::lower_case(path);
    // Endings may be whole names (SOG's "meta.json"), not only extensions.
    SplatFormatMatch best;
    for (const SplatFormatInfo& f : splat_formats()) {
        if (writable_only && !f.writable) continue;
        for (const char* ending : f.extensions) {
            const std::size_t n = std::strlen(ending);
            if (n > best.ending_length && lower.size() >= n && lower.compare(lower.size() - n, n, ending) == 0)
                best = {&f, n};
        }
    }
    return best;
}

std::string splat_endings_text(bool writable_only, const std::string& separator) {
    std::string text;
    for (const SplatFormatInfo& f : splat_formats())
        if (!writable_only || f.writable)
            for (const char* ending : f.extensions) text += (text.empty() ? "" : separator) + std::string(ending);
    return text;
}

SplatFormat splat_format_from_extension(const std::string& path) {
    const SplatFormatMatch match = match_splat_format(path);
    if (match.format) return match.format->format;
    throw FileFormatError(path, "unknown splat format: extension '" + io::lower_extension(path) + "' is not one of " +
                                    splat_endings_text());
}

const char* splat_format_name(SplatFormat format) {
    for (const SplatFormatInfo& f : splat_formats())
        if (f.format == format) return f.name;
    return "unknown";
}

}  // namespace raysplats
