#include "io/zip_archive.h"

#include <unzip.h>

#include <algorithm>
#include <cstring>

namespace raysplats {
namespace io {
namespace {

// Deflate's largest expansion: 258 bytes out of a length/distance pair coded in as little as 2 bits, 1032:1 (zlib's
// zlib.h and the zip bomb literature quote the same bound).
constexpr std::uint64_t kDeflateMaxRatio = 1032;
// The size of a central directory entry without its variable fields: a directory lists at most one entry per 46
// bytes of the archive.
constexpr std::uint64_t kCentralDirectoryEntryBytes = 46;

// minizip's file functions over a ZipArchive::MemoryStream.
using MemoryStream = ZipArchive::MemoryStream;

voidpf ZCALLBACK memory_open(voidpf opaque, const void*, int mode) {
    if (mode & ZLIB_FILEFUNC_MODE_CREATE) return nullptr;
    static_cast<MemoryStream*>(opaque)->pos = 0;
    return opaque;
}
uLong ZCALLBACK memory_read(voidpf, voidpf stream, void* buf, uLong size) {
    MemoryStream& s = *static_cast<MemoryStream*>(stream);
    const std::uint64_t n = std::min<std::uint64_t>(size, s.size - std::min(s.pos, s.size));
    if (n) std::memcpy(buf, s.data + s.pos, std::size_t(n));
    s.pos += n;
    return uLong(n);
}
uLong ZCALLBACK memory_write(voidpf, voidpf, const void*, uLong) { return 0; }
ZPOS64_T ZCALLBACK memory_tell(voidpf, voidpf stream) { return static_cast<MemoryStream*>(stream)->pos; }
long ZCALLBACK memory_seek(voidpf, voidpf stream, ZPOS64_T offset, int origin) {
    MemoryStream& s = *static_cast<MemoryStream*>(stream);
    std::uint64_t base = 0;
    switch (origin) {
        case ZLIB_FILEFUNC_SEEK_SET: base = 0; break;
        case ZLIB_FILEFUNC_SEEK_CUR: base = s.pos; break;
        case ZLIB_FILEFUNC_SEEK_END: base = s.size; break;
        default: return -1;
    }
    if (offset > s.size || base > s.size - offset) return -1;
    s.pos = base + offset;
    return 0;
}
int ZCALLBACK memory_close(voidpf, voidpf) { return 0; }
int ZCALLBACK memory_error(voidpf, voidpf) { return 0; }

}  // namespace

bool is_zip(const std::uint8_t* d, std::size_t size) { return size >= 4 && std::memcmp(d, "PK\x03\x04", 4) == 0; }

ZipArchive::ZipArchive(const std::uint8_t* data, std::size_t size, std::string path,
                       const std::string& what_it_should_be)
    : path_(std::move(path)) {
    stream_ = MemoryStream{data, size, 0};
    zlib_filefunc64_def functions{memory_open, memory_read, memory_write, memory_tell,
                                  memory_seek, memory_close, memory_error, &stream_};
    zip_ = unzOpen2_64("archive", &functions);
    if (!zip_) throw FileFormatError(path_, "not a zip archive (no readable central directory): " + what_it_should_be);
    try {
        list_entries();
    } catch (...) {
        unzClose(zip_);
        throw;
    }
}

ZipArchive::~ZipArchive() {
    if (zip_) unzClose(zip_);
}

FileFormatError ZipArchive::error(const std::string& name, const std::string& problem) const {
    return FileFormatError(path_, name.empty() ? problem : "member '" + name + "': " + problem);
}

std::vector<std::string> ZipArchive::names() const {
    std::vector<std::string> out;
    out.reserve(entries_.size());
    for (const auto& entry : entries_) out.push_back(entry.first);
    return out;
}

void ZipArchive::list_entries() {
    // A claimed count beyond one entry per 46 bytes is a lie that minizip's walk stops at anyway; the cap keeps a
    // hostile listing from growing the map without end.
    const std::uint64_t max_entries = stream_.size / kCentralDirectoryEntryBytes + 1;
    int status = unzGoToFirstFile(zip_);
    for (std::uint64_t k = 0; status == UNZ_OK; ++k, status = unzGoToNextFile(zip_)) {
        if (k >= max_entries) throw FileFormatError(path_, "zip central directory lists more entries than the file can hold");
        unz_file_info64 info{};
        char name[1024];
        if (unzGetCurrentFileInfo64(zip_, &info, name, sizeof name, nullptr, 0, nullptr, 0) != UNZ_OK)
            throw FileFormatError(path_, "corrupt zip central directory (entry " + std::to_string(k) + ")");
        if (info.size_filename >= sizeof name) continue;  // longer than any name a reader could ask for
        Entry e;
        unz64_file_pos pos{};
        unzGetFilePos64(zip_, &pos);
        e.directory_offset = pos.pos_in_zip_directory, e.file_number = pos.num_of_file;
        e.compressed = info.compressed_size, e.uncompressed = info.uncompressed_size;
        e.method = unsigned(info.compression_method), e.flags = unsigned(info.flag);
        entries_.emplace(std::string(name, info.size_filename), e);
    }
    if (status != UNZ_END_OF_LIST_OF_FILE) throw FileFormatError(path_, "corrupt zip central directory");
}

void ZipArchive::check_claimed_sizes(const std::string& name, const Entry& e, std::uint64_t max_bytes,
                                     const std::string& role) const {
    if (e.flags & 1u) throw error(name, "is encrypted");
    if (e.method != 0 && e.method != Z_DEFLATED)
        throw error(name, "compressed with zip method " + std::to_string(e.method) + " (only stored and deflate are read)");
    if (e.uncompressed > max_bytes)
        throw error(name, "claims " + std::to_string(e.uncompressed) + " bytes, more than " + role + " can need (" +
                              std::to_string(max_bytes) + ")");
    if (e.method == 0 && e.uncompressed != e.compressed)
        throw error(name, "stored (not compressed) but claims " + std::to_string(e.uncompressed) + " bytes from " +
                              std::to_string(e.compressed));
    if (e.method == Z_DEFLATED && e.uncompressed > e.compressed * kDeflateMaxRatio + 1024)
        throw error(name, "claims " + std::to_string(e.uncompressed) + " bytes from " + std::to_string(e.compressed) +
                              " deflated: more than deflate's 1032:1 expansion allows (a zip bomb?)");
    if (e.compressed > stream_.size)
        throw error(name, "claims " + std::to_string(e.compressed) + " compressed bytes, more than the whole bundle");
}

Bytes ZipArchive::read(const std::string& name, std::uint64_t max_bytes, const std::string& role) {
    const Entry& e = entries_.at(name);
    check_claimed_sizes(name, e, max_bytes, role);
    unz64_file_pos pos{e.directory_offset, e.file_number};
    if (unzGoToFilePos64(zip_, &pos) != UNZ_OK || unzOpenCurrentFile(zip_) != UNZ_OK)
        throw error(name, "cannot open its data (bad local header)");
    Bytes out;
    out.resize(std::size_t(e.uncompressed));
    std::size_t done = 0;
    while (done < out.size()) {
        const unsigned chunk = unsigned(std::min<std::size_t>(out.size() - done, std::size_t(1) << 30));
        const int got = unzReadCurrentFile(zip_, out.data() + done, chunk);
        if (got <= 0) {
            unzCloseCurrentFile(zip_);
            throw error(name, "corrupt or truncated data: " + std::to_string(done) + " of " +
                                  std::to_string(e.uncompressed) + " bytes read");
        }
        done += std::size_t(got);
    }
    if (unzCloseCurrentFile(zip_) == UNZ_CRCERROR) throw error(name, "CRC-32 mismatch: the data is corrupt");
    return out;
}

}  // namespace io
}  // namespace raysplats
