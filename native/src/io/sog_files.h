// Where a SOG scene's files come from (sog_format.cpp gives the format): the members of a .sog bundle, a zip read
// with ZipArchive (meta.json at the archive's root, or else in its one folder), or meta.json with the images beside
// it ("unbundled"). Internal to the SOG reader.
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include "io/io_common.h"
#include "raysplats/errors.h"

namespace raysplats {
namespace io {

class SogFiles {
public:
    virtual ~SogFiles() = default;
    // The bytes of the file `name` (as meta.json names it), refusing more than `max_bytes`; `role` says in errors what
    // the file is for ("the means image").
    virtual Bytes read(const std::string& name, std::uint64_t max_bytes, const std::string& role) = 0;
    // An error about the file `name` (empty: about the scene as a whole).
    virtual FileFormatError error(const std::string& name, const std::string& problem) const = 0;
    virtual std::string meta_name() const = 0;
};

// The scene's files: a bundle for zip content, else a meta.json with the images beside it. `f` must outlive them.
// Throws FileFormatError for a bundle that is not a zip or has no meta.json, and for a .sog, or bytes in memory,
// without the zip magic.
std::unique_ptr<SogFiles> open_sog_files(const FileBytes& f);

}  // namespace io
}  // namespace raysplats
