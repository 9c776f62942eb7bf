// PlayCanvas SOG reader (read only: the core writes no SOG).
//
// A SOG scene is a meta.json plus lossless WebP images, either as files beside the meta.json ("unbundled") or as the
// members of one zip file, a .sog bundle (the same names at the archive's root; a bundle whose files sit in one
// folder is read too). Sources, cited beside each formula below:
//   [spec]  the SOG format specification, developer.playcanvas.com user-manual/gaussian-splatting/formats/sog
//           (playcanvas/developer-site docs/user-manual/gaussian-splatting/formats/sog.md), version 2;
//   [st]    @playcanvas/splat-transform src/lib/readers/read-sog.ts (v2) and read-sog-v1.ts (v1), whose decoding wrote
//           shared/data/unicorn_sh3_reordered.ply from unicorn_sh3.sog, and src/lib/writers/write-sog.ts;
//   [eng]   playcanvas/engine src/scene/gsplat/gsplat-sog-data.js (GSplatSogIterator, decompress, prepareCodebook)
//           and src/framework/parsers/sogs.js (upgradeMeta: v1 -> v2).
//
// Pixels: image width W, height H, splat i at pixel (i % W, i / W), row-major from the top left; every per-splat image
// has W*H >= count and the trailing pixels are ignored [spec 1.1]. Bytes are raw 8-bit values, no gamma [spec 2].
//
//   meta.json         version 2 ("version": 2, "count") or 1 (no "version"; count = means.shape[0]) [st, eng]
//   means_l, means_u  q = means_u.c << 8 | means_l.c per axis c of R,G,B; n = lerp(mins[c], maxs[c], q / 65535);
//                     position = sign(n) (exp|n| - 1), undoing the encoder's sign(x) ln(|x| + 1) [spec 3.1; st]
//   quats             R,G,B: three components a = (byte / 255 - 0.5) sqrt 2, in [-1/sqrt2, 1/sqrt2]; A - 252 in 0..3 is
//                     the index, in (w, x, y, z) order, of the largest component, left out and rebuilt as
//                     sqrt(max(0, 1 - a^2 - b^2 - c^2)); the kept ones fill the other places in order [spec 3.2; st
//                     unpackQuat; eng: mode 0 -> (x, y, z, w) = (a, b, c, d)]. A outside 252..255 is reserved: refused.
//   scales            v2: log scale = scales.codebook[byte] per axis R,G,B [spec 3.3; st];
//                     v1: log scale = lerp(scales.mins[c], scales.maxs[c], byte / 255) [st v1; eng]; scale = exp.
//   sh0               v2: SH DC coefficient = sh0.codebook[byte] per R,G,B; opacity = A / 255 [spec 3.4; st stores
//                     logit(A / 255) in its PLY]; v1: DC = lerp(sh0.mins[c], sh0.maxs[c], byte / 255), opacity =
//                     sigmoid(lerp(mins[3], maxs[3], A / 255)) [st v1; eng].
//   shN_labels        palette index n = R | G << 8 per splat, n < shN.count (v2) [spec 3.5; st]
//   shN_centroids     64 palette entries per row, each `coeffs` = 3, 8, 15 pixels wide (bands 1, 2, 3), so the image is
//                     64 * coeffs wide; coefficient k of entry n is pixel ((n % 64) coeffs + k, n / 64), its R,G,B the
//                     red, green, blue coefficient: v2 shN.codebook[byte], v1 lerp(shN.mins, shN.maxs, byte / 255)
//                     (scalars) [spec 3.5; st; eng]. v1 has no "bands": they follow from the width (192, 512, 960) [st v1,
//                     eng calcBands], and its palette holds (W / coeffs) H entries [st v1].
//   codebooks         256 numbers; a null first entry (JavaScript writes -Infinity as null) is replaced as the engine
//                     does: codebook[0] = codebook[1] + (codebook[1] - codebook[255]) / 255 [eng prepareCodebook].
//
// Axes: none converted. splat-transform's writer bakes its data to "PLY space" before encoding and its reader returns
// the table in PLY space (write-sog.ts, read-sog.ts: Transform.PLY), so a SOG holds the axes of the .ply it came from,
// the core's RDF (docs/design.md §4), like .ply and .splat. ([spec 1.2] says x right, y up, z back; the tools do not
// convert.)
//
// Hostile input: every bound below is checked before what it bounds is allocated.
//   - meta.json at most 1 MiB and 64 levels deep; each number finite; every name a relative path inside the scene.
//   - a zip member's claimed size at most what its role can need, and at most 1032 times its deflated size (deflate's
//     largest expansion); stored members as long as their data; the CRC is checked.
//   - an image's W*H at least count, at most 2 count + 65536 (writers pad to a multiple of 4 [st write-sog.ts]), and at
//     most 65536 pixels per byte of the WebP (see kMaxLosslessPixelsPerByte): count, which sizes the cloud, is thus
//     bounded by the bytes of the means image.
//   - every codebook index inside its codebook, every palette index below shN.count and inside the centroids image.
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <unzip.h>
#include <webp/decode.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <sys/stat.h>

#include "io/io_common.h"
#include "io/splat_formats.h"
#include "raysplats/default_init_allocator.h"
#include "raysplats/splat_io.h"

namespace raysplats {
namespace {

using Json = nlohmann::json;
using Bytes = std::vector<std::uint8_t, DefaultInitAllocator<std::uint8_t>>;

constexpr std::uint64_t kMaxMetaBytes = std::uint64_t(1) << 20;  // a real meta.json: 16 kB (three 256-entry codebooks)
constexpr int kMaxJsonDepth = 64;
// WebP images are at most 16383 x 16383 pixels (the VP8L header's 14-bit sizes): no SOG holds more splats.
constexpr std::uint64_t kMaxSplats = std::uint64_t(16383) * 16383;
// Deflate's largest expansion: 258 bytes out of a length/distance pair coded in as little as 2 bits, 1032:1 (zlib's
// zlib.h and the zip bomb literature quote the same bound).
constexpr std::uint64_t kDeflateMaxRatio = 1032;
// Pixels a lossless WebP (VP8L) can decode from one byte: a backward reference copies at most 4096 (packed) pixels and
// its length code for that needs 10 extra bits (VP8L spec 5.2.2: prefix code 23, (23 - 2) >> 1 extra bits), and the
// colour-indexing transform packs up to 8 pixels (palettes of 2 colours) into one, so at most 8 * 4096 pixels per
// 10 bits, 26214 pixels per byte; rounded up to 65536 for headroom.
constexpr std::uint64_t kMaxLosslessPixelsPerByte = 65536;
// Writers pad images to a multiple of 4 in each direction [st write-sog.ts: width = ceil(sqrt(n) / 4) * 4, height =
// ceil(n / width / 4) * 4]; older ones made them square. Anything far larger than the count needs is refused.
inline std::uint64_t max_pixels_for(std::uint64_t count) { return 2 * count + 65536; }
// Bytes of a lossless WebP of P pixels at worst: 4 Huffman codes of at most 15 bits per literal pixel, plus headers.
inline std::uint64_t max_webp_bytes(std::uint64_t pixels) { return 8 * pixels + (std::uint64_t(1) << 20); }

constexpr int kShCoeffsForBands[4] = {0, 3, 8, 15};
constexpr std::uint64_t kPaletteEntriesPerRow = 64;
constexpr std::uint64_t kMaxPaletteEntries = 65536;  // 16-bit labels [spec 3.5]

// ---------------------------------------------------------------------------------------------------------------
// Where the scene's files come from: a zip bundle (from a file or from memory) or a folder.

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

// Names in meta.json are relative to it; "..", absolute paths and NULs could reach files outside the scene.
void check_member_name(const SogFiles& files, const std::string& name, const std::string& field) {
    bool bad = name.empty() || name[0] == '/' || name.find('\0') != std::string::npos || name.find('\\') != std::string::npos;
    for (std::size_t start = 0; !bad && start <= name.size();) {
        const std::size_t end = std::min(name.find('/', start), name.size());
        if (name.compare(start, end - start, "..") == 0 && end - start == 2) bad = true;
        start = end + 1;
    }
    if (bad)
        throw files.error(files.meta_name(), "'" + field + "' is '" + name +
                                                 "': not a file name relative to meta.json (no '..', no absolute path)");
}

// --- zip bundles, read with minizip over a block of memory (a mapped file or a caller's buffer)

struct MemoryStream {
    const std::uint8_t* data;
    std::uint64_t size;
    std::uint64_t pos;
};

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

class ZipBundle : public SogFiles {
public:
    // `data` must outlive the bundle. `path` names the bundle in errors.
    ZipBundle(const std::uint8_t* data, std::size_t size, std::string path) : path_(std::move(path)) {
        stream_ = MemoryStream{data, size, 0};
        zlib_filefunc64_def functions{memory_open, memory_read, memory_write, memory_tell,
                                      memory_seek, memory_close, memory_error, &stream_};
        zip_ = unzOpen2_64("bundle", &functions);
        if (!zip_) throw FileFormatError(path_, "not a zip archive (no readable central directory): a .sog is a zip of meta.json and WebP images");
        try {
            list_members();
        } catch (...) {
            unzClose(zip_);
            throw;
        }
    }
    ~ZipBundle() override {
        if (zip_) unzClose(zip_);
    }
    ZipBundle(const ZipBundle&) = delete;
    ZipBundle& operator=(const ZipBundle&) = delete;

    FileFormatError error(const std::string& name, const std::string& problem) const override {
        return FileFormatError(path_, name.empty() ? problem : "member '" + name + "': " + problem);
    }
    std::string meta_name() const override { return prefix_ + "meta.json"; }

    Bytes read(const std::string& name, std::uint64_t max_bytes, const std::string& role) override {
        const std::string member = name == meta_name() ? name : prefix_ + name;
        const auto it = members_.find(member);
        if (it == members_.end())
            throw error("", name == meta_name() ? "the bundle has no meta.json"
                                                : "meta.json names '" + name + "' (" + role + "), which the bundle does not contain");
        const Member& m = it->second;
        if (m.flags & 1u) throw error(member, "is encrypted");
        if (m.method != 0 && m.method != Z_DEFLATED)
            throw error(member, "compressed with zip method " + std::to_string(m.method) + " (only stored and deflate are read)");
        if (m.uncompressed > max_bytes)
            throw error(member, "claims " + std::to_string(m.uncompressed) + " bytes, more than " + role + " can need (" +
                                    std::to_string(max_bytes) + ")");
        if (m.method == 0 && m.uncompressed != m.compressed)
            throw error(member, "stored (not compressed) but claims " + std::to_string(m.uncompressed) + " bytes from " +
                                    std::to_string(m.compressed));
        if (m.method == Z_DEFLATED && m.uncompressed > m.compressed * kDeflateMaxRatio + 1024)
            throw error(member, "claims " + std::to_string(m.uncompressed) + " bytes from " + std::to_string(m.compressed) +
                                    " deflated: more than deflate's 1032:1 expansion allows (a zip bomb?)");
        if (m.compressed > stream_.size)
            throw error(member, "claims " + std::to_string(m.compressed) + " compressed bytes, more than the whole bundle");
        unz64_file_pos pos = m.pos;
        if (unzGoToFilePos64(zip_, &pos) != UNZ_OK || unzOpenCurrentFile(zip_) != UNZ_OK)
            throw error(member, "cannot open its data (bad local header)");
        Bytes out;
        out.resize(std::size_t(m.uncompressed));
        std::size_t done = 0;
        while (done < out.size()) {
            const unsigned chunk = unsigned(std::min<std::size_t>(out.size() - done, std::size_t(1) << 30));
            const int got = unzReadCurrentFile(zip_, out.data() + done, chunk);
            if (got <= 0) {
                unzCloseCurrentFile(zip_);
                throw error(member, "corrupt or truncated data: " + std::to_string(done) + " of " +
                                        std::to_string(m.uncompressed) + " bytes read");
            }
            done += std::size_t(got);
        }
        if (unzCloseCurrentFile(zip_) == UNZ_CRCERROR) throw error(member, "CRC-32 mismatch: the data is corrupt");
        return out;
    }

private:
    struct Member {
        unz64_file_pos pos{};
        std::uint64_t compressed = 0, uncompressed = 0;
        unsigned method = 0, flags = 0;
    };

    void list_members() {
        // A central directory lists at most one entry per 46 bytes of the file: a claimed count beyond that is a lie
        // that minizip's walk stops at anyway; the cap keeps a hostile listing from growing the map without end.
        const std::uint64_t max_entries = stream_.size / 46 + 1;
        int status = unzGoToFirstFile(zip_);
        for (std::uint64_t k = 0; status == UNZ_OK; ++k, status = unzGoToNextFile(zip_)) {
            if (k >= max_entries) throw FileFormatError(path_, "zip central directory lists more entries than the file can hold");
            unz_file_info64 info{};
            char name[1024];
            if (unzGetCurrentFileInfo64(zip_, &info, name, sizeof name, nullptr, 0, nullptr, 0) != UNZ_OK)
                throw FileFormatError(path_, "corrupt zip central directory (entry " + std::to_string(k) + ")");
            if (info.size_filename >= sizeof name) continue;  // longer than any name meta.json could give
            Member m;
            unzGetFilePos64(zip_, &m.pos);
            m.compressed = info.compressed_size, m.uncompressed = info.uncompressed_size;
            m.method = unsigned(info.compression_method), m.flags = unsigned(info.flag);
            members_.emplace(std::string(name, info.size_filename), m);
        }
        if (status != UNZ_END_OF_LIST_OF_FILE) throw FileFormatError(path_, "corrupt zip central directory");
        // meta.json at the root [spec 1.3], or else in the bundle's one folder (some tools zip the folder).
        if (members_.count("meta.json")) return;
        std::string found;
        for (const auto& member : members_) {
            const std::string& n = member.first;
            if (n.size() > 10 && n.compare(n.size() - 10, 10, "/meta.json") == 0 && n.find('/') == n.size() - 10) {
                if (!found.empty()) throw FileFormatError(path_, "the bundle has no meta.json at its root, and several in folders");
                found = n;
            }
        }
        if (found.empty()) throw FileFormatError(path_, "the bundle has no meta.json: not a SOG bundle");
        prefix_ = found.substr(0, found.size() - 9);
    }

    std::string path_;
    MemoryStream stream_{};
    unzFile zip_ = nullptr;
    std::map<std::string, Member> members_;
    std::string prefix_;
};

// --- unbundled: meta.json and the images beside it

class Folder : public SogFiles {
public:
    explicit Folder(const std::string& meta_path) : meta_path_(meta_path) {
        const std::size_t slash = meta_path.find_last_of('/');
        dir_ = slash == std::string::npos ? "" : meta_path.substr(0, slash + 1);
    }
    FileFormatError error(const std::string& name, const std::string& problem) const override {
        return FileFormatError(name.empty() || name == meta_path_ ? meta_path_ : dir_ + name, problem);
    }
    std::string meta_name() const override { return meta_path_; }
    Bytes read(const std::string& name, std::uint64_t max_bytes, const std::string& role) override {
        const std::string path = name == meta_path_ ? name : dir_ + name;
        struct stat st {};
        if (::stat(path.c_str(), &st) != 0)
            throw FileFormatError(path, "meta.json ('" + meta_path_ + "') names this file (" + role + "), which cannot be opened: " +
                                            std::strerror(errno));
        const io::FileBytes f(path);
        if (f.size() > max_bytes)
            throw FileFormatError(path, "is " + std::to_string(f.size()) + " bytes, more than " + role + " can need (" +
                                            std::to_string(max_bytes) + ")");
        Bytes out;
        out.resize(f.size());
        if (f.size()) std::memcpy(out.data(), f.data(), f.size());
        return out;
    }

private:
    std::string meta_path_, dir_;
};

// ---------------------------------------------------------------------------------------------------------------
// meta.json

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

class MetaReader {
public:
    MetaReader(const SogFiles& files, const Json& root) : files_(files), root_(root) {}

    [[noreturn]] void fail(const std::string& problem) const { throw files_.error(files_.meta_name(), "meta.json: " + problem); }

    const Json& object(const Json& parent, const char* key, const std::string& where) const {
        if (!parent.is_object() || !parent.contains(key)) fail("'" + where + "' is missing");
        const Json& v = parent[key];
        if (!v.is_object()) fail("'" + where + "' is not an object");
        return v;
    }
    double number(const Json& v, const std::string& where) const {
        if (v.is_null()) fail("'" + where + "' is null, not a number (JavaScript writes NaN and Infinity as null)");
        if (!v.is_number()) fail("'" + where + "' is not a number");
        const double d = v.get<double>();
        if (!std::isfinite(d)) fail("'" + where + "' is not finite");
        return d;
    }
    void numbers(const Json& parent, const char* key, const std::string& where, double* out, std::size_t n) const {
        if (!parent.contains(key)) fail("'" + where + "' is missing");
        const Json& a = parent[key];
        if (!a.is_array() || a.size() != n) fail("'" + where + "' is not a list of " + std::to_string(n) + " numbers");
        for (std::size_t k = 0; k < n; ++k) out[k] = number(a[k], where + "[" + std::to_string(k) + "]");
    }
    void files(const Json& parent, const std::string& where, std::string* out, std::size_t n) const {
        if (!parent.contains("files")) fail("'" + where + ".files' is missing");
        const Json& a = parent["files"];
        if (!a.is_array() || a.size() < n) fail("'" + where + ".files' is not a list of " + std::to_string(n) + " file names");
        for (std::size_t k = 0; k < n; ++k) {
            const std::string field = where + ".files[" + std::to_string(k) + "]";
            if (!a[k].is_string()) fail("'" + field + "' is not a file name");
            out[k] = a[k].get<std::string>();
            check_member_name(files_, out[k], field);
        }
    }
    // A v2 codebook: 1..256 finite numbers (a null first entry replaced as the engine does). Returns its size.
    int codebook(const Json& parent, const std::string& where, std::vector<double>& out) const {
        if (!parent.contains("codebook")) fail("'" + where + ".codebook' is missing");
        const Json& a = parent["codebook"];
        if (!a.is_array() || a.empty() || a.size() > 256) fail("'" + where + ".codebook' is not a list of 1 to 256 numbers");
        out.assign(a.size(), 0.0);
        for (std::size_t k = 0; k < a.size(); ++k)
            if (!(k == 0 && a[k].is_null() && a.size() == 256))
                out[k] = number(a[k], where + ".codebook[" + std::to_string(k) + "]");
        // [eng prepareCodebook]: "patch codebooks starting with a null entry".
        if (a[0].is_null()) out[0] = out[1] + (out[1] - out[255]) / 255.0;
        return int(out.size());
    }
    std::uint64_t whole_number(const Json& v, const std::string& where, std::uint64_t max) const {
        const double d = number(v, where);
        if (d < 0 || d != std::floor(d) || d > double(max))
            fail("'" + where + "' is " + v.dump() + ", not a whole number from 0 to " + std::to_string(max));
        return std::uint64_t(d);
    }

    SogMeta parse() const {
        SogMeta m;
        if (!root_.is_object()) fail("not a JSON object");
        if (root_.contains("version")) {
            const double v = number(root_["version"], "version");
            if (v != 2) fail("version " + root_["version"].dump() + " is not supported (this reader knows 2, and 1 without 'version')");
            m.version = 2;
        } else {
            m.version = 1;  // [st read-sog.ts]: "V1 (legacy) has no `version` field"
        }
        const Json& means = object(root_, "means", "means");
        if (m.version == 2) {
            if (!root_.contains("count")) fail("'count' is missing");
            m.count = whole_number(root_["count"], "count", kMaxSplats);
        } else {
            if (!means.contains("shape") || !means["shape"].is_array() || means["shape"].empty())
                fail("'means.shape' is missing (a version 1 meta.json gives the splat count as means.shape[0])");
            m.count = whole_number(means["shape"][0], "means.shape[0]", kMaxSplats);
        }
        if (root_.contains("antialias") && root_["antialias"].is_boolean()) m.antialias = root_["antialias"].get<bool>();
        numbers(means, "mins", "means.mins", m.means_min, 3);
        numbers(means, "maxs", "means.maxs", m.means_max, 3);
        files(means, "means", m.means_files, 2);
        files(object(root_, "quats", "quats"), "quats", &m.quats_file, 1);

        const Json& scales = object(root_, "scales", "scales");
        const Json& sh0 = object(root_, "sh0", "sh0");
        files(scales, "scales", &m.scales_file, 1);
        files(sh0, "sh0", &m.sh0_file, 1);
        if (m.version == 2) {
            std::vector<double> book;
            m.scale_valid = codebook(scales, "scales", book);
            for (int c = 0; c < 3; ++c)
                for (int b = 0; b < m.scale_valid; ++b) m.scale_lut[c][b] = float(book[std::size_t(b)]);
            m.dc_valid = codebook(sh0, "sh0", book);
            for (int c = 0; c < 3; ++c)
                for (int b = 0; b < m.dc_valid; ++b) m.dc_lut[c][b] = float(book[std::size_t(b)]);
            for (int b = 0; b < 256; ++b) m.opacity_lut[b] = float(b / 255.0);  // [spec 3.4]: A / 255
        } else {
            double smin[3], smax[3], cmin[4], cmax[4];
            numbers(scales, "mins", "scales.mins", smin, 3);
            numbers(scales, "maxs", "scales.maxs", smax, 3);
            numbers(sh0, "mins", "sh0.mins", cmin, 4);
            numbers(sh0, "maxs", "sh0.maxs", cmax, 4);
            for (int b = 0; b < 256; ++b) {
                const double t = b / 255.0;
                for (int c = 0; c < 3; ++c) {
                    m.scale_lut[c][b] = float(smin[c] + (smax[c] - smin[c]) * t);
                    m.dc_lut[c][b] = float(cmin[c] + (cmax[c] - cmin[c]) * t);
                }
                m.opacity_lut[b] = float(1.0 / (1.0 + std::exp(-(cmin[3] + (cmax[3] - cmin[3]) * t))));  // logit lerp
            }
        }

        if (root_.contains("shN") && !root_["shN"].is_null()) {
            const Json& shn = object(root_, "shN", "shN");
            m.has_shn = true;
            std::string names[2];
            files(shn, "shN", names, 2);
            m.centroids_file = names[0], m.labels_file = names[1];
            if (m.version == 2) {
                if (!shn.contains("bands")) fail("'shN.bands' is missing");
                m.bands = int(whole_number(shn["bands"], "shN.bands", 3));
                if (m.bands < 1) fail("'shN.bands' is 0 (1 to 3 when shN is present)");
                if (!shn.contains("count")) fail("'shN.count' is missing");
                m.palette_count = whole_number(shn["count"], "shN.count", kMaxPaletteEntries);
                if (m.palette_count == 0) fail("'shN.count' is 0 (a palette of 1 to 65536 entries)");
                std::vector<double> book;
                m.shn_valid = codebook(shn, "shN", book);
                for (int b = 0; b < m.shn_valid; ++b) m.shn_lut[b] = float(book[std::size_t(b)]);
            } else {
                double lo = 0, hi = 0;
                if (!shn.contains("mins") || !shn.contains("maxs")) fail("'shN.mins' or 'shN.maxs' is missing");
                lo = number(shn["mins"], "shN.mins");
                hi = number(shn["maxs"], "shN.maxs");
                for (int b = 0; b < 256; ++b) m.shn_lut[b] = float(lo + (hi - lo) * (b / 255.0));
                if (shn.contains("shape") && shn["shape"].is_array() && shn["shape"].size() >= 2 && shn["shape"][1].is_number())
                    m.v1_shn_shape_coeffs = std::int64_t(whole_number(shn["shape"][1], "shN.shape[1]", 1000));
            }
        }
        return m;
    }

private:
    const SogFiles& files_;
    const Json& root_;
};

SogMeta read_meta(SogFiles& files) {
    const Bytes text = files.read(files.meta_name(), kMaxMetaBytes, "meta.json");
    Json root;
    try {
        // The callback bounds the nesting, so that a hostile "[[[[..." costs no more than a real meta.json.
        root = Json::parse(text.begin(), text.end(), [&](int depth, Json::parse_event_t, Json&) {
            if (depth > kMaxJsonDepth)
                throw files.error(files.meta_name(), "meta.json: nested more than " + std::to_string(kMaxJsonDepth) + " levels deep");
            return true;
        });
    } catch (const Json::exception& e) {
        const std::string hint = std::string(reinterpret_cast<const char*>(text.data()), text.size()).find("NaN") != std::string::npos
                                     ? " (JSON has no NaN or Infinity)"
                                     : "";
        throw files.error(files.meta_name(), std::string("meta.json: malformed JSON: ") + e.what() + hint);
    }
    return MetaReader(files, root).parse();
}

// ---------------------------------------------------------------------------------------------------------------
// Images

struct Image {
    std::string name;
    std::uint32_t width = 0, height = 0;
    Bytes webp;  // the file, until decoded
    Bytes rgba;  // width * height * 4 once decoded
    std::uint64_t pixels() const { return std::uint64_t(width) * height; }
};

// Reads an image file and checks its size against what it must hold, without decoding it.
Image open_image(SogFiles& files, const std::string& name, const std::string& role, std::uint64_t min_pixels,
                 std::uint64_t max_pixels, const std::string& min_reason) {
    Image im;
    im.name = name;
    im.webp = files.read(name, max_webp_bytes(max_pixels), role);
    WebPBitstreamFeatures features;
    if (WebPGetFeatures(im.webp.data(), im.webp.size(), &features) != VP8_STATUS_OK)
        throw files.error(name, "not a WebP image (" + role + "; SOG images are lossless WebP)");
    if (features.format != 2)
        throw files.error(name, "a lossy WebP (" + role + "): SOG values are exact bytes that lossy compression corrupts");
    im.width = std::uint32_t(features.width), im.height = std::uint32_t(features.height);
    const std::string size = std::to_string(im.width) + " x " + std::to_string(im.height);
    if (im.pixels() < min_pixels)
        throw files.error(name, role + " is " + size + " = " + std::to_string(im.pixels()) + " pixels, fewer than " + min_reason);
    if (im.pixels() > max_pixels)
        throw files.error(name, role + " is " + size + " pixels, more than the " + std::to_string(max_pixels) +
                                    " it can need for " + min_reason);
    if (im.pixels() > std::uint64_t(im.webp.size()) * kMaxLosslessPixelsPerByte)
        throw files.error(name, role + " claims " + size + " pixels, more than a lossless WebP of " +
                                    std::to_string(im.webp.size()) + " bytes can hold");
    return im;
}

void decode_image(const SogFiles& files, Image& im) {
    im.rgba.resize(std::size_t(im.pixels()) * 4);
    if (!WebPDecodeRGBAInto(im.webp.data(), im.webp.size(), im.rgba.data(), im.rgba.size(), int(im.width) * 4))
        throw files.error(im.name, "corrupt WebP data (" + std::to_string(im.width) + " x " + std::to_string(im.height) + ")");
    Bytes().swap(im.webp);
}

void release(Image& im) { Bytes().swap(im.rgba), Bytes().swap(im.webp); }

// The first splat (lowest index) at which a check failed, across threads, with what was wrong there.
struct FirstBad {
    std::atomic<std::uint64_t> index{~std::uint64_t(0)};
    void note(std::uint64_t i) {
        std::uint64_t cur = index.load();
        while (i < cur && !index.compare_exchange_weak(cur, i)) {
        }
    }
    bool any() const { return index.load() != ~std::uint64_t(0); }
};

std::string pixel_of(const Image& im, std::uint64_t i) {
    return "pixel (" + std::to_string(i % im.width) + ", " + std::to_string(i / im.width) + ") (splat " + std::to_string(i) + ")";
}

// ---------------------------------------------------------------------------------------------------------------

struct SogScene {
    SogMeta meta;
    Image means_l, means_u, quats, scales, sh0, centroids, labels;
};

// Reads meta.json and checks every image's size before anything as large as the cloud is allocated.
SogScene open_scene(SogFiles& files) {
    SogScene s;
    s.meta = read_meta(files);
    SogMeta& m = s.meta;
    const std::uint64_t n = m.count;
    const std::string reason = "the " + std::to_string(n) + " splats of meta.json's count";
    const std::uint64_t max_pixels = max_pixels_for(n);
    s.means_l = open_image(files, m.means_files[0], "the means image (low bytes)", n, max_pixels, reason);
    s.means_u = open_image(files, m.means_files[1], "the means image (high bytes)", n, max_pixels, reason);
    s.quats = open_image(files, m.quats_file, "the quats image", n, max_pixels, reason);
    s.scales = open_image(files, m.scales_file, "the scales image", n, max_pixels, reason);
    s.sh0 = open_image(files, m.sh0_file, "the sh0 image", n, max_pixels, reason);
    if (m.has_shn) {
        s.labels = open_image(files, m.labels_file, "the shN labels image", n, max_pixels, reason);
        const std::uint64_t max_centroid_pixels = kPaletteEntriesPerRow * 15 * (kMaxPaletteEntries / kPaletteEntriesPerRow);
        s.centroids = open_image(files, m.centroids_file, "the shN centroids image", 1, max_centroid_pixels,
                                 "a palette of 1 to 65536 entries");
        const std::uint32_t w = s.centroids.width;
        if (m.version == 1) {
            // [st v1, eng calcBands]: 192, 512, 960 pixels wide for 1, 2, 3 bands.
            m.bands = w == 192 ? 1 : w == 512 ? 2 : w == 960 ? 3 : 0;
            if (m.bands == 0)
                throw files.error(s.centroids.name, "the shN centroids image is " + std::to_string(w) +
                                                        " pixels wide; version 1 palettes are 192, 512 or 960 (1, 2, 3 bands)");
            m.palette_count = std::uint64_t(w / std::uint32_t(kShCoeffsForBands[m.bands])) * s.centroids.height;
            m.palette_count = std::min(m.palette_count, kMaxPaletteEntries);
        } else {
            const std::uint64_t want_w = kPaletteEntriesPerRow * std::uint64_t(kShCoeffsForBands[m.bands]);
            const std::uint64_t want_h = (m.palette_count + kPaletteEntriesPerRow - 1) / kPaletteEntriesPerRow;
            if (w != want_w || s.centroids.height < want_h)
                throw files.error(s.centroids.name,
                                  "the shN centroids image is " + std::to_string(w) + " x " + std::to_string(s.centroids.height) +
                                      "; a palette of " + std::to_string(m.palette_count) + " entries of " +
                                      std::to_string(m.bands) + " bands needs " + std::to_string(want_w) + " x " +
                                      std::to_string(want_h) + " (64 entries per row)");
        }
    }
    return s;
}

// Decodes the images into a cloud (activations applied: linear scales and opacities; rotations not yet normalised).
GaussianCloud decode_scene(SogFiles& files, SogScene& s) {
    const SogMeta& m = s.meta;
    const std::size_t n = std::size_t(m.count);
    const int degree = m.has_shn ? m.bands : 0;
    GaussianCloud c;
    c.resize(n, degree);
    const std::size_t K = std::size_t(c.coeffs_per_channel());
    const auto for_each_splat = [n](auto&& body) {
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, io::kGrain), [&](const tbb::blocked_range<std::size_t>& r) {
            for (std::size_t i = r.begin(); i != r.end(); ++i) body(i);
        });
    };

    // Positions [spec 3.1].
    decode_image(files, s.means_l);
    decode_image(files, s.means_u);
    {
        const std::uint8_t* lo = s.means_l.rgba.data();
        const std::uint8_t* hi = s.means_u.rgba.data();
        for_each_splat([&](std::size_t i) {
            for (int a = 0; a < 3; ++a) {
                const unsigned q = unsigned(hi[4 * i + std::size_t(a)]) << 8 | lo[4 * i + std::size_t(a)];
                const double v = m.means_min[a] + (m.means_max[a] - m.means_min[a]) * (q / 65535.0);
                c.positions[3 * i + std::size_t(a)] = float(std::copysign(std::expm1(std::fabs(v)), v));
            }
        });
    }
    release(s.means_l);
    release(s.means_u);

    // Rotations [spec 3.2]: the components in (w, x, y, z) order, the largest left out.
    decode_image(files, s.quats);
    {
        constexpr int kKept[4][3] = {{1, 2, 3}, {0, 2, 3}, {0, 1, 3}, {0, 1, 2}};
        const std::uint8_t* q = s.quats.rgba.data();
        FirstBad bad;
        for_each_splat([&](std::size_t i) {
            const std::uint8_t* p = q + 4 * i;
            float* out = &c.rotations[4 * i];
            if (p[3] < 252) {
                bad.note(i);
                out[0] = 1.0f, out[1] = out[2] = out[3] = 0.0f;
                return;
            }
            const int largest = p[3] - 252;
            float sum = 0.0f;
            for (int k = 0; k < 3; ++k) {
                const float v = (float(p[k]) / 255.0f - 0.5f) * 1.41421356237309505f;
                out[kKept[largest][k]] = v;
                sum += v * v;
            }
            out[largest] = std::sqrt(std::max(0.0f, 1.0f - sum));
        });
        if (bad.any())
            throw files.error(s.quats.name, "the quats image's alpha at " + pixel_of(s.quats, bad.index) + " is " +
                                                std::to_string(q[4 * bad.index + 3]) + "; it must be 252 to 255 (the largest component)");
    }
    release(s.quats);

    // Scales and colour through their codebooks [spec 3.3, 3.4].
    const auto check_indices = [&](const Image& im, int channels, int valid, const char* book) {
        if (valid >= 256) return;
        const std::uint8_t* p = im.rgba.data();
        FirstBad bad;
        for_each_splat([&](std::size_t i) {
            for (int ch = 0; ch < channels; ++ch)
                if (p[4 * i + std::size_t(ch)] >= valid) bad.note(i);
        });
        if (bad.any()) {
            int value = 0;
            for (int ch = 0; ch < channels; ++ch) value = std::max<int>(value, p[4 * bad.index + std::size_t(ch)]);
            throw files.error(im.name, "index " + std::to_string(value) + " at " + pixel_of(im, bad.index) + " is outside the " +
                                           std::to_string(valid) + "-entry " + book + " codebook of meta.json");
        }
    };
    decode_image(files, s.scales);
    check_indices(s.scales, 3, m.scale_valid, "scales");
    {
        const std::uint8_t* p = s.scales.rgba.data();
        float exp_lut[3][256];
        for (int a = 0; a < 3; ++a)
            for (int b = 0; b < 256; ++b) exp_lut[a][b] = std::exp(m.scale_lut[a][b]);
        for_each_splat([&](std::size_t i) {
            for (int a = 0; a < 3; ++a) c.scales[3 * i + std::size_t(a)] = exp_lut[a][p[4 * i + std::size_t(a)]];
        });
    }
    release(s.scales);

    decode_image(files, s.sh0);
    check_indices(s.sh0, 3, m.dc_valid, "sh0");
    {
        const std::uint8_t* p = s.sh0.rgba.data();
        for_each_splat([&](std::size_t i) {
            float* sh = &c.sh[i * K * 3];
            for (int ch = 0; ch < 3; ++ch) sh[ch] = m.dc_lut[ch][p[4 * i + std::size_t(ch)]];
            c.opacities[i] = m.opacity_lut[p[4 * i + 3]];
        });
    }
    release(s.sh0);

    // Higher SH bands through the palette [spec 3.5].
    if (m.has_shn) {
        decode_image(files, s.labels);
        decode_image(files, s.centroids);
        const int coeffs = kShCoeffsForBands[m.bands];
        const std::uint8_t* labels = s.labels.rgba.data();
        const std::uint8_t* cent = s.centroids.rgba.data();
        const std::size_t cw = s.centroids.width;
        const std::uint64_t palette = m.palette_count;
        FirstBad bad_label, bad_index;
        for_each_splat([&](std::size_t i) {
            const std::uint64_t label = std::uint64_t(labels[4 * i]) | std::uint64_t(labels[4 * i + 1]) << 8;
            if (label >= palette) {
                bad_label.note(i);
                return;
            }
            const std::size_t u = std::size_t(label % kPaletteEntriesPerRow) * std::size_t(coeffs);
            const std::size_t v = std::size_t(label / kPaletteEntriesPerRow);
            const std::uint8_t* entry = cent + (v * cw + u) * 4;
            float* sh = &c.sh[i * K * 3];
            for (int k = 0; k < coeffs; ++k)
                for (int ch = 0; ch < 3; ++ch) {
                    const std::uint8_t b = entry[4 * k + ch];
                    if (b >= m.shn_valid) bad_index.note(i);
                    sh[3 * (1 + std::size_t(k)) + std::size_t(ch)] = m.shn_lut[b];
                }
        });
        if (bad_label.any()) {
            const std::size_t i = bad_label.index;
            throw files.error(s.labels.name, "palette index " + std::to_string(labels[4 * i] | labels[4 * i + 1] << 8) + " at " +
                                                 pixel_of(s.labels, i) + " is not below the palette's " +
                                                 std::to_string(palette) + " entries");
        }
        if (bad_index.any())
            throw files.error(s.centroids.name, "the palette entry of " + pixel_of(s.labels, bad_index.index) +
                                                    " holds an index outside the " + std::to_string(m.shn_valid) +
                                                    "-entry shN codebook of meta.json");
        release(s.labels);
        release(s.centroids);
    }
    return c;
}

GaussianCloud read_scene(SogFiles& files, const ReadOptions& options, LoadReport* report) {
    SogScene scene = open_scene(files);
    GaussianCloud c = decode_scene(files, scene);
    io::finalize_cloud(c, options, report);
    if (report && scene.meta.antialias)
        report->warnings.push_back("meta.json says the scene was trained with anti-aliasing ('antialias': true), which this "
                                   "renderer does not model: it may look slightly different than in PlayCanvas");
    if (report && scene.meta.version == 1)
        report->warnings.push_back("a version 1 (legacy) SOG: PlayCanvas's tools write version 2 now");
    return c;
}

using io::is_zip;

// Runs `body` on the scene's files: a bundle for zip content, else a meta.json with the images beside it.
template <typename Body>
auto with_sog_files(const io::FileBytes& f, Body body) {
    const std::string& path = f.path();
    if (is_zip(f.data(), f.size())) {
        ZipBundle bundle(f.data(), f.size(), path);
        return body(static_cast<SogFiles&>(bundle));
    }
    if (io::lower_extension(path) == ".sog" || f.in_memory())
        throw FileFormatError(path, "not a SOG bundle: a .sog is a zip archive (no 'PK' zip magic)", 0);
    Folder folder(path);
    return body(static_cast<SogFiles&>(folder));
}

}  // namespace

namespace io {
bool is_zip(const std::uint8_t* d, std::size_t size) { return size >= 4 && std::memcmp(d, "PK\x03\x04", 4) == 0; }

bool is_sog_file(const std::string& path, const std::uint8_t* head, std::size_t head_size) {
    if (is_zip(head, head_size)) return true;
    const std::string e = lower_extension(path);
    if (e == ".sog") return true;
    std::string lower = path;
    for (char& ch : lower) ch = char(std::tolower(static_cast<unsigned char>(ch)));
    return lower.size() >= 9 && lower.compare(lower.size() - 9, 9, "meta.json") == 0;
}

// A zip is a .sog bundle; an unbundled SOG is its meta.json, known by name (as a .sog that lacks the zip magic,
// which the reader then refuses with its own message).
Evidence detect_sog(const std::uint8_t* d, std::size_t size, const std::string& name, bool) {
    if (is_zip(d, size)) return Evidence::Signature;
    return is_sog_file(name, nullptr, 0) ? Evidence::Name : Evidence::None;
}

SplatFileSummary probe_sog(const FileBytes& f) {
    return with_sog_files(f, [](SogFiles& files) {
        const SogMeta m = read_meta(files);
        SplatFileSummary s{SplatFormat::Sog, m.count, 0};
        if (!m.has_shn) return s;
        if (m.version == 2) {
            s.sh_degree = m.bands;
        } else if (m.v1_shn_shape_coeffs >= 0) {
            const std::int64_t k = m.v1_shn_shape_coeffs;  // per channel (15) or all three (45)
            s.sh_degree = (k == 45 || k == 15) ? 3 : (k == 24 || k == 8) ? 2 : (k == 9 || k == 3) ? 1 : 0;
        } else {
            const Image centroids = open_image(files, m.centroids_file, "the shN centroids image", 1,
                                               kPaletteEntriesPerRow * 15 * (kMaxPaletteEntries / kPaletteEntriesPerRow),
                                               "a palette of 1 to 65536 entries");
            s.sh_degree = centroids.width == 192 ? 1 : centroids.width == 512 ? 2 : centroids.width == 960 ? 3 : 0;
        }
        return s;
    });
}

GaussianCloud read_sog(const FileBytes& f, const ReadOptions& options, LoadReport* report) {
    return with_sog_files(f, [&](SogFiles& files) { return read_scene(files, options, report); });
}
}  // namespace io

GaussianCloud read_sog(const std::string& path, const ReadOptions& options, LoadReport* report) {
    return io::read_sog(io::FileBytes(path), options, report);
}

GaussianCloud read_sog_bundle(const std::uint8_t* data, std::size_t size, const std::string& name, const ReadOptions& options,
                              LoadReport* report) {
    return io::read_sog(io::FileBytes(data, size, name), options, report);
}

}  // namespace raysplats
