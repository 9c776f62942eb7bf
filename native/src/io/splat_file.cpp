// Format dispatch over the table, file access, atomic writes and the repair / filter step shared by all splat readers.

#include <tbb/blocked_range.h>
#include <tbb/combinable.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <memory>
#include <random>

#include "io/io_common.h"
#include "core/os_files.h"
#include "io/splat_formats.h"
#include "raysplats/splat_io.h"

namespace raysplats {
namespace io {

// ---------------------------------------------------------------------------------------------------------
// FileBytes

FileBytes::FileBytes(const std::string& path) : path_(path) {
    try {
        file_ = std::make_unique<os::FileView>(path);
    } catch (const os::Error& e) {
        const std::string what = e.what();
        throw FileFormatError(path, what == "is a directory, not a file" ? what : "cannot open or read file: " + what);
    }
    data_ = file_->data();
    size_ = file_->size();
}

// ---------------------------------------------------------------------------------------------------------
// AtomicFileWriter

AtomicFileWriter::AtomicFileWriter(const std::string& path) : path_(path) {
    if (path.empty()) throw FileFormatError(path, "cannot write: empty file name");
    if (os::path_status(path).is_directory) throw FileFormatError(path, "cannot write: is a directory");
    // The temporary file lives in the target's folder so that replacing the target is one step (same file system).
    try {
        temp_path_ = os::create_temporary_beside(path, file_);
    } catch (const os::Error& e) {
        throw FileFormatError(path, std::string("cannot write: cannot create a temporary file beside it: ") + e.what());
    }
}

AtomicFileWriter::~AtomicFileWriter() {
    file_.close();
    if (!committed_ && !temp_path_.empty()) os::remove_file(temp_path_);
}

void AtomicFileWriter::fail(const std::string& what, const os::Error& error) {
    file_.close();
    if (!temp_path_.empty()) os::remove_file(temp_path_);
    temp_path_.clear();
    throw FileFormatError(path_, "cannot write: " + what + ": " + error.what());
}

void AtomicFileWriter::write(const void* data, std::size_t size) {
    if (!file_.is_open()) throw FileFormatError(path_, "cannot write: file already closed");
    try {
        file_.write(data, size);
    } catch (const os::Error& e) {
        fail("write to temporary file failed", e);
    }
}

void AtomicFileWriter::commit() {
    if (!file_.is_open()) throw FileFormatError(path_, "cannot write: file already closed");
    try {
        file_.finish();
    } catch (const os::Error& e) {
        fail("flush and close of temporary file failed", e);
    }
    try {
        os::replace_file(temp_path_, path_);
    } catch (const os::Error& e) {
        fail("replacing the target with the temporary file failed", e);
    }
    committed_ = true;
}

// ---------------------------------------------------------------------------------------------------------
// Validation and repair

void check_writable(const GaussianCloud& cloud) { cloud.check_consistent(); }

void finalize_cloud(GaussianCloud& c, const ReadOptions& options, LoadReport* report) {
    if (report) *report = LoadReport{};
    const std::size_t n = c.size();
    const std::size_t shn = std::size_t(c.coeffs_per_channel()) * 3;
    std::vector<std::uint8_t> keep(n, 1);
    struct Counts {
        std::size_t dropped = 0, repaired = 0, zero_rot = 0, below = 0;
    };
    tbb::combinable<Counts> counts;
    const float min_op = options.min_opacity;
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, kGrain), [&](const tbb::blocked_range<std::size_t>& r) {
        Counts& k = counts.local();
        for (std::size_t i = r.begin(); i != r.end(); ++i) {
            float* p = &c.positions[3 * i];
            float* s = &c.scales[3 * i];
            float* q = &c.rotations[4 * i];
            bool finite = true;
            for (int j = 0; j < 3; ++j) finite &= std::isfinite(p[j]) && std::isfinite(s[j]);
            for (int j = 0; j < 4; ++j) finite &= std::isfinite(q[j]);
            if (!finite) {
                keep[i] = 0;
                ++k.dropped;
                continue;
            }
            bool repaired = false;
            float& op = c.opacities[i];
            if (!std::isfinite(op)) op = 0.0f, repaired = true;
            float* sh = &c.sh[i * shn];
            for (std::size_t j = 0; j < shn; ++j)
                if (!std::isfinite(sh[j])) sh[j] = 0.0f, repaired = true;
            if (repaired) ++k.repaired;
            if (!normalise_quaternion(q, q)) {
                q[0] = 1.0f, q[1] = q[2] = q[3] = 0.0f;
                ++k.zero_rot;
            }
            if (min_op > 0.0f && op < min_op) {
                keep[i] = 0;
                ++k.below;
            }
        }
    });
    Counts total;
    counts.combine_each([&](const Counts& k) {
        total.dropped += k.dropped, total.repaired += k.repaired, total.zero_rot += k.zero_rot, total.below += k.below;
    });
    if (report) {
        report->non_finite_dropped = total.dropped;
        report->non_finite_repaired = total.repaired;
        report->zero_rotation_repaired = total.zero_rot;
        if (total.dropped)
            report->warnings.push_back(std::to_string(total.dropped) +
                                       " splat(s) with NaN/Inf in position, scale or rotation dropped");
        if (total.repaired)
            report->warnings.push_back(std::to_string(total.repaired) +
                                       " splat(s) with NaN/Inf in opacity or colour: those values set to 0");
        if (total.zero_rot)
            report->warnings.push_back(std::to_string(total.zero_rot) +
                                       " splat(s) with a zero quaternion: rotation set to identity");
    }

    // Compact: the kept splats in file order, at most max_count of them.
    const std::size_t limit = options.max_count ? options.max_count : n;
    const std::size_t kept = n - total.dropped - total.below;
    if (kept == n && n <= limit) return;
    std::vector<std::size_t> src;
    src.reserve(std::min(kept, limit));
    if (kept <= limit) {
        for (std::size_t i = 0; i < n; ++i)
            if (keep[i]) src.push_back(i);
    } else {
        // A uniform thinning of the whole file, not its first max_count splats (for a scene stored tile by tile those
        // are a spatial crop): selection sampling (Knuth, TAOCP vol. 2, 3.4.2, Algorithm S) takes each of the `kept`
        // splats in turn with probability (still needed) / (still left), which picks every subset of `limit` equally
        // likely and keeps file order. The seed is fixed, so a file always thins to the same splats.
        std::mt19937_64 rng(0x5eed5eedull ^ kept);
        std::size_t left = kept;
        for (std::size_t i = 0; i < n && src.size() < limit; ++i) {
            if (!keep[i]) continue;
            const std::size_t needed = limit - src.size();
            if (std::uniform_int_distribution<std::size_t>(0, left - 1)(rng) < needed) src.push_back(i);
            --left;
        }
        if (report)
            report->warnings.push_back("kept " + std::to_string(limit) + " of " + std::to_string(kept) +
                                       " splats (maximum count), chosen uniformly at random over the whole file");
    }
    const std::size_t m = src.size();
    GaussianCloud out;
    out.sh_degree = c.sh_degree;
    out.positions.resize(3 * m);
    out.rotations.resize(4 * m);
    out.scales.resize(3 * m);
    out.opacities.resize(m);
    out.sh.resize(m * shn);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, m, kGrain), [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t d = r.begin(); d != r.end(); ++d) {
            const std::size_t s = src[d];
            std::memcpy(&out.positions[3 * d], &c.positions[3 * s], 3 * sizeof(float));
            std::memcpy(&out.rotations[4 * d], &c.rotations[4 * s], 4 * sizeof(float));
            std::memcpy(&out.scales[3 * d], &c.scales[3 * s], 3 * sizeof(float));
            out.opacities[d] = c.opacities[s];
            std::memcpy(&out.sh[shn * d], &c.sh[shn * s], shn * sizeof(float));
        }
    });
    c = std::move(out);
}

std::string lower_extension(const std::string& path) {
    const std::size_t slash = os::last_separator(path);
    const std::size_t dot = path.find_last_of('.');
    if (dot == std::string::npos || (slash != std::string::npos && dot < slash)) return "";
    std::string e = path.substr(dot);
    for (char& ch : e) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
    return e;
}

}  // namespace io

// -------------------------------------------------------------------------------------------------------------
// Dispatch over the format table (io/splat_formats.h)

namespace io {

SplatFormat detect_splat_format(const std::uint8_t* d, std::size_t size, const std::string& name) {
    return detect_splat_row(d, size, name).info.format;
}

const SplatFormatRow& detect_splat_row(const std::uint8_t* d, std::size_t size, const std::string& name) {
    if (size == 0) throw FileFormatError(name, "file is empty");
    // A file named as a headerless format (.splat) may begin with any bytes: only a full signature counts then.
    const SplatFormatMatch named = match_splat_format(name);
    const bool headerless_name = named.format && splat_format_row(named.format->format).headerless;
    // Content first: the first row whose signature the bytes carry; else the first row the name alone points to.
    const SplatFormatRow* by_name = nullptr;
    for (const SplatFormatRow& row : splat_format_table()) {
        if (!row.detect) continue;
        const Evidence evidence = row.detect(d, size, name, headerless_name);
        if (evidence == Evidence::Signature) return row;
        if (evidence == Evidence::Name && !by_name) by_name = &row;
    }
    if (by_name) return *by_name;
    const std::string e = lower_extension(name);
    if (e == ".ply" || e == ".spz")
        throw FileFormatError(name, "not a " + e.substr(1) + " file: unrecognised content (no 'ply', 'NGSP' or gzip magic)", 0);
    throw FileFormatError(name,
                          "unknown splat format: unrecognised content (no 'ply', 'NGSP' or gzip magic) and extension '" + e +
                              "' is not .splat",
                          0);
}

GaussianCloud read_splat(const FileBytes& f, const ReadOptions& options, LoadReport* report) {
    return detect_splat_row(f.data(), f.size(), f.path()).read(f, options, report);
}

SplatFileSummary probe_splat(const FileBytes& f) { return detect_splat_row(f.data(), f.size(), f.path()).probe(f); }

GaussianCloud read_splat_bytes(const std::uint8_t* data, std::size_t size, const std::string& name, const ReadOptions& options,
                               LoadReport* report) {
    return read_splat(FileBytes(data, size, name), options, report);
}

SplatFileSummary probe_splat_bytes(const std::uint8_t* data, std::size_t size, const std::string& name) {
    return probe_splat(FileBytes(data, size, name));
}

}  // namespace io

GaussianCloud read_splat_file(const std::string& path, const ReadOptions& options, LoadReport* report) {
    return io::read_splat(io::FileBytes(path), options, report);
}

SplatFileSummary probe_splat_file(const std::string& path) { return io::probe_splat(io::FileBytes(path)); }

void write_splat_file(const std::string& path, const GaussianCloud& cloud) {
    const io::SplatFormatRow& row = io::splat_format_row(splat_format_from_extension(path));
    if (!row.write) throw FileFormatError(path, row.read_only_reason);
    row.write(path, cloud);
}

}  // namespace raysplats
