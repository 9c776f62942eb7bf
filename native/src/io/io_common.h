// Private helpers shared by the splat file readers and writers (native/src/io): file access, atomic
// writes, and the common repair / filter step every reader ends with. Not part of the public API.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <algorithm>
#include <cmath>
#include <exception>
#include <limits>
#include <memory>
#include <streambuf>
#include <thread>
#include <string>
#include <vector>

#include "core/os_files.h"
#include "raysplats/default_init_allocator.h"
#include "raysplats/errors.h"
#include "raysplats/gaussian_cloud.h"
#include "raysplats/splat_io.h"

namespace raysplats {
namespace io {

// Splats per task for tbb::parallel_for over per-splat work.
constexpr std::size_t kGrain = 8192;

// Bytes read from a file or an archive: resize() leaves them uninitialised, since they are written right after.
using Bytes = std::vector<std::uint8_t, DefaultInitAllocator<std::uint8_t>>;

// Read-only view of a whole file: memory mapped where possible. Throws FileFormatError naming the file
// if it cannot be opened or read. An empty file gives size() == 0 and data() == nullptr.
// The second constructor views bytes the caller holds (not owned, not copied), with a name that stands for the file
// in error messages: every format's reader takes a FileBytes, so reading a file and reading the same bytes from
// memory run the same code and give the same errors (and the fuzz targets, native/fuzz, test what files get).
class FileBytes {
public:
    explicit FileBytes(const std::string& path);
    FileBytes(const std::uint8_t* data, std::size_t size, const std::string& name)
        : path_(name), data_(size ? data : nullptr), size_(size), in_memory_(true) {}
    FileBytes(const FileBytes&) = delete;
    FileBytes& operator=(const FileBytes&) = delete;

    const std::uint8_t* data() const { return data_; }
    std::size_t size() const { return size_; }
    const std::string& path() const { return path_; }
    // True for a view of memory: path() is only a name, so a reader must not look for files beside it (glTF's
    // external buffers, SOG's unbundled images).
    bool in_memory() const { return in_memory_; }

private:
    std::string path_;
    const std::uint8_t* data_ = nullptr;
    std::size_t size_ = 0;
    bool in_memory_ = false;
    std::unique_ptr<os::FileView> file_;  // the file's bytes (mapped where possible); none for a view of memory
};

// Writes a file atomically: everything goes to a temporary file in the target's folder, which commit()
// flushes, syncs and moves over the target (os::replace_file: one step on Linux and on Windows). If commit() is never reached (an exception, a failed write),
// the destructor removes the temporary file and the target is untouched. All failures throw
// FileFormatError naming the target path.
class AtomicFileWriter {
public:
    explicit AtomicFileWriter(const std::string& path);
    ~AtomicFileWriter();
    AtomicFileWriter(const AtomicFileWriter&) = delete;
    AtomicFileWriter& operator=(const AtomicFileWriter&) = delete;

    void write(const void* data, std::size_t size);
    void commit();
    const std::string& temp_path() const { return temp_path_; }

private:
    [[noreturn]] void fail(const std::string& what, const os::Error& error);
    std::string path_, temp_path_;
    os::NewFile file_;
    bool committed_ = false;
};

// A std::streambuf over an AtomicFileWriter, for writers that produce a std::ostream (OpenMesh). Double
// buffered: a full 4 MiB buffer is written by a helper thread while the caller fills the other one, so the
// kernel's copy into the page cache overlaps the formatting. Call sync() (std::ostream::flush) before
// AtomicFileWriter::commit(); write errors surface there (or at the next buffer switch) as the writer's
// FileFormatError.
class AtomicFileStreamBuf : public std::streambuf {
public:
    explicit AtomicFileStreamBuf(AtomicFileWriter& writer) : writer_(writer) {
        for (auto& b : buffers_) b.resize(kBufferSize);
        setp(buffers_[0].data(), buffers_[0].data() + kBufferSize);
    }
    ~AtomicFileStreamBuf() override {
        if (worker_.joinable()) worker_.join();
    }

protected:
    int_type overflow(int_type ch) override {
        switch_buffers();
        if (!traits_type::eq_int_type(ch, traits_type::eof())) {
            *pptr() = traits_type::to_char_type(ch);
            pbump(1);
        }
        return traits_type::not_eof(ch);
    }
    std::streamsize xsputn(const char* s, std::streamsize n) override {
        std::streamsize done = 0;
        while (done < n) {
            if (pptr() == epptr()) switch_buffers();
            const std::streamsize room = std::min<std::streamsize>(n - done, epptr() - pptr());
            std::memcpy(pptr(), s + done, std::size_t(room));
            pbump(int(room));
            done += room;
        }
        return n;
    }
    int sync() override {
        switch_buffers();
        wait();
        return 0;
    }

private:
    static constexpr std::size_t kBufferSize = std::size_t(4) << 20;

    void wait() {
        if (worker_.joinable()) worker_.join();
        if (error_) {
            std::exception_ptr e = error_;
            error_ = nullptr;
            std::rethrow_exception(e);
        }
    }
    void switch_buffers() {
        const std::size_t n = std::size_t(pptr() - pbase());
        wait();
        if (n) {
            const char* data = pbase();
            worker_ = std::thread([this, data, n] {
                try {
                    writer_.write(data, n);
                } catch (...) {
                    error_ = std::current_exception();
                }
            });
            current_ ^= 1;
        }
        setp(buffers_[current_].data(), buffers_[current_].data() + kBufferSize);
    }

    AtomicFileWriter& writer_;
    std::vector<char> buffers_[2];
    int current_ = 0;
    std::thread worker_;
    std::exception_ptr error_;
};

// The format of a file's bytes (splat_file.cpp, over the table of io/splat_formats.h): the first format whose
// signature the content carries (PLY, SPZ (NGSP or gzip), zip (SOG), glTF magic), else the format its name alone
// gives (.gltf, .sog / meta.json, .splat). A name ending in .splat (headerless: any bytes can start a record) takes a
// content format only for a full signature ('ply' and a line end, 'NGSP', gzip that inflates to 'NGSP', zip, glTF
// binary version 2), since its first float can begin with any magic by chance (gzip's two bytes: 1 in 65,536).
// Throws FileFormatError naming `name` for an empty file or an unknown format. A compressed PLY is SplatFormat::Ply
// here (its header tells, read_ply hands it over).
SplatFormat detect_splat_format(const std::uint8_t* data, std::size_t size, const std::string& name);
// read_splat_file and probe_splat_file on bytes in memory (`name` stands for the file in errors and gives the format
// when the content does not). Never opens a file: a .gltf with external buffers or an unbundled SOG meta.json is
// refused (FileFormatError), they are read from their folder by the path readers.
GaussianCloud read_splat_bytes(const std::uint8_t* data, std::size_t size, const std::string& name,
                               const ReadOptions& options = {}, LoadReport* report = nullptr);
SplatFileSummary probe_splat_bytes(const std::uint8_t* data, std::size_t size, const std::string& name);
GaussianCloud read_splat(const FileBytes& f, const ReadOptions& options, LoadReport* report);
SplatFileSummary probe_splat(const FileBytes& f);

// Throws InvalidArgument if the cloud's arrays disagree (checked by every writer before it opens a file).
void check_writable(const GaussianCloud& cloud);

// The last step of every reader. `cloud` holds every splat of the file with activations applied (linear
// scale and opacity) but rotations not yet normalised. This
//  - drops splats with a non-finite position, scale or rotation,
//  - sets non-finite opacity / SH values to 0,
//  - replaces zero quaternions by the identity and normalises the others,
//  - drops splats with opacity < options.min_opacity, keeps at most options.max_count of the rest (a uniform,
//    seeded choice over the whole file),
// counting each repair in `report` (which is reset first; may be null).
void finalize_cloud(GaussianCloud& cloud, const ReadOptions& options, LoadReport* report);

// The normalisation every reader applies to a stored quaternion (w x y z) in finalize_cloud: false (q untouched)
// for a zero or non-finite one. Writers that quantise rotations use it to find stored values that read back
// exactly as the cloud's quaternion, so that an untouched round trip is byte-exact.
inline bool normalise_quaternion(const float in[4], float out[4]) {
    const double n2 = double(in[0]) * in[0] + double(in[1]) * in[1] + double(in[2]) * in[2] + double(in[3]) * in[3];
    if (!(n2 > 1e-30) || !std::isfinite(n2)) return false;
    const double inv = 1.0 / std::sqrt(n2);
    for (int j = 0; j < 4; ++j) out[j] = float(in[j] * inv);
    return true;
}
inline bool same_quaternion(const float a[4], const float b[4]) {
    return a[0] == b[0] && a[1] == b[1] && a[2] == b[2] && a[3] == b[3];
}

// The float a writer stores for `target` so that the reader's `decode` (increasing) gives `target` back
// exactly: `guess` (the analytic inverse, e.g. log of a scale) if it decodes to target, else the nearest float
// to it that does, found by walking ulps toward target (a few steps: the analytic inverse is within rounding of
// it). Where no float decodes exactly to target (a value the reader cannot produce), `guess`.
template <typename Decode>
float stored_value_for(float target, float guess, Decode decode) {
    if (!std::isfinite(guess)) return guess;
    const float first = decode(guess);
    if (first == target) return guess;
    const float direction = first < target ? std::numeric_limits<float>::infinity() : -std::numeric_limits<float>::infinity();
    float x = guess;
    for (int step = 0; step < 64; ++step) {
        x = std::nextafter(x, direction);
        const float v = decode(x);
        if (v == target) return x;
        if ((first < target) != (v < target)) break;  // passed it: target is between two decoded values
    }
    return guess;
}

// Lower-case extension with the dot (".ply"), or "" if none.
std::string lower_extension(const std::string& path);

// Little-endian loads/stores that do not depend on alignment.
inline std::uint32_t load_u32le(const std::uint8_t* p) {
    return std::uint32_t(p[0]) | (std::uint32_t(p[1]) << 8) | (std::uint32_t(p[2]) << 16) | (std::uint32_t(p[3]) << 24);
}
inline std::uint64_t load_u64le(const std::uint8_t* p) {
    return std::uint64_t(load_u32le(p)) | (std::uint64_t(load_u32le(p + 4)) << 32);
}
inline void store_u32le(std::uint8_t* p, std::uint32_t v) {
    p[0] = std::uint8_t(v), p[1] = std::uint8_t(v >> 8), p[2] = std::uint8_t(v >> 16), p[3] = std::uint8_t(v >> 24);
}
inline void store_u64le(std::uint8_t* p, std::uint64_t v) {
    store_u32le(p, std::uint32_t(v));
    store_u32le(p + 4, std::uint32_t(v >> 32));
}
inline void store_f32le(std::uint8_t* p, float v) {
    std::uint32_t u;
    std::memcpy(&u, &v, 4);
    store_u32le(p, u);
}

}  // namespace io
}  // namespace raysplats
