// A zip archive in memory, read with minizip (which needs only zlib): its central directory listed once, then whole
// entries by name. Every size an entry claims is checked before it is allocated, and its CRC after it is read, so a
// hostile archive costs no more memory than its entries can really hold:
//   - an entry's claimed size at most what the caller's role for it can need, and at most 1032 times its deflated
//     size (deflate's largest expansion); stored entries as long as their data; only stored and deflate are read;
//   - a central directory of at most one entry per 46 bytes of the archive.
// Knows nothing of what the archive holds (sog_files.cpp reads SOG bundles with it). Internal to the core.
#pragma once

#include <cstddef>
#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "io/io_common.h"
#include "raysplats/errors.h"

namespace raysplats {
namespace io {

// Whether bytes start with a zip local file header ("PK\3\4").
bool is_zip(const std::uint8_t* data, std::size_t size);

class ZipArchive {
public:
    // `data` must outlive the archive; `path` names it in errors. Throws FileFormatError(path, "not a zip archive (no
    // readable central directory): " + what_it_should_be) when minizip finds no central directory, and
    // FileFormatError(path, ...) for a corrupt one.
    ZipArchive(const std::uint8_t* data, std::size_t size, std::string path, const std::string& what_it_should_be);
    ~ZipArchive();
    ZipArchive(const ZipArchive&) = delete;
    ZipArchive& operator=(const ZipArchive&) = delete;

    bool contains(const std::string& name) const { return entries_.count(name) != 0; }
    // The entries' names, sorted.
    std::vector<std::string> names() const;
    // The whole entry `name` (which contains() must have found), refusing one that claims more than `max_bytes`;
    // `role` says in errors what the entry is for ("the means image").
    Bytes read(const std::string& name, std::uint64_t max_bytes, const std::string& role);
    // An error about the entry `name` (empty: about the archive as a whole), naming the archive's path.
    FileFormatError error(const std::string& name, const std::string& problem) const;

    // Where minizip reads from: the bytes in memory and a read position.
    struct MemoryStream {
        const std::uint8_t* data;
        std::uint64_t size;
        std::uint64_t pos;
    };

private:
    struct Entry {
        std::uint64_t directory_offset = 0, file_number = 0;  // minizip's unz64_file_pos
        std::uint64_t compressed = 0, uncompressed = 0;
        unsigned method = 0, flags = 0;
    };

    void list_entries();
    void check_claimed_sizes(const std::string& name, const Entry& entry, std::uint64_t max_bytes,
                             const std::string& role) const;

    std::string path_;
    MemoryStream stream_{};
    void* zip_ = nullptr;  // minizip's unzFile
    std::map<std::string, Entry> entries_;
};

}  // namespace io
}  // namespace raysplats
