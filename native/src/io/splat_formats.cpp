// The table of splat formats (raysplats/splat_io.h) and the lookups by extension and name that use it.
#include <cctype>
#include <cstring>
#include <string>

#include "io_common.h"
#include "raysplats/errors.h"
#include "raysplats/splat_io.h"

namespace raysplats {

const std::vector<SplatFormatInfo>& splat_formats() {
    static const std::vector<SplatFormatInfo> formats{
        {SplatFormat::Ply, "ply", {".ply"}, "INRIA 3D Gaussian Splatting PLY", "-Y"},
        {SplatFormat::Splat, "splat", {".splat"}, "antimatter15 .splat (32-byte records, no higher SH bands)", "-Y"},
        {SplatFormat::Spz, "spz", {".spz"}, "Niantic SPZ (compressed)", "-Y"},
        // glTF is +Y up by specification; the reader converts it to the core's RDF like SPZ's RUB.
        {SplatFormat::Gltf, "gltf", {".glb", ".gltf"}, "glTF 2.0 with KHR_gaussian_splatting (import only)", "-Y", true, false},
        {SplatFormat::CompressedPly, "compressed_ply", {".compressed.ply"},
         "SuperSplat compressed PLY (chunks of 256 splats, 16 bytes a splat)", "-Y"}};
    return formats;
}

SplatFormat splat_format_from_extension(const std::string& path) {
    const std::string e = io::lower_extension(path);
    std::string lower = path;
    for (char& ch : lower) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
    // The longest extension the name ends with: "a.compressed.ply" is a compressed PLY, "a.ply" an INRIA one.
    std::string known;
    const SplatFormatInfo* found = nullptr;
    std::size_t found_length = 0;
    for (const SplatFormatInfo& f : splat_formats())
        for (const char* extension : f.extensions) {
            const std::size_t length = std::strlen(extension);
            if (lower.size() >= length && lower.compare(lower.size() - length, length, extension) == 0 && length > found_length)
                found = &f, found_length = length;
            known += (known.empty() ? "" : ", ") + std::string(extension);
        }
    if (found) return found->format;
    throw FileFormatError(path, "unknown splat format: extension '" + e + "' is not one of " + known);
}

const char* splat_format_name(SplatFormat format) {
    for (const SplatFormatInfo& f : splat_formats())
        if (f.format == format) return f.name;
    return "unknown";
}

}  // namespace raysplats
