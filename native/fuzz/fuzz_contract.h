// The contract every reader's fuzz target checks (docs/architecture.md, native/fuzz/): on any bytes, a reader either
// throws FileFormatError whose message names the file, or returns a cloud that passes the cloud's own checks
// (GaussianCloud::check_consistent, check_values; unit quaternions, opacities in [0, 1], the repairs finalize_cloud
// promises), and the header probe (probe_splat_file's, on the same bytes) agrees with it on the splat count where
// both succeed. Anything else (another exception type, a crash, a sanitizer report) is a finding: it aborts, and
// libFuzzer saves the input.
#pragma once

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <string>

#include "io/io_common.h"
#include "io/splat_formats.h"
#include "raysplats/errors.h"
#include "raysplats/gaussian_cloud.h"
#include "raysplats/splat_io.h"

namespace raysplats {
namespace fuzz {

[[noreturn]] inline void finding(const std::string& what) {
    std::fprintf(stderr, "\n*** fuzz contract broken: %s\n", what.c_str());
    std::fflush(stderr);
    std::abort();
}

// The values a reader promises beyond check_values (finalize_cloud: rotations normalised or the identity). With
// unit_rotations false (the polygon bridge, which passes an unedited Gaussian's stored rotation through bit for bit,
// normalised or not), a rotation need only be one: finite and not zero.
inline void check_cloud(const GaussianCloud& c, const std::string& name, bool unit_rotations = true) {
    try {
        c.check_consistent();
        c.check_values(name);
    } catch (const std::exception& e) {
        finding(std::string("the cloud read fails the cloud's own check: ") + e.what());
    }
    for (std::size_t i = 0; i < c.size(); ++i) {
        const float* q = &c.rotations[4 * i];
        const double n2 = double(q[0]) * q[0] + double(q[1]) * q[1] + double(q[2]) * q[2] + double(q[3]) * q[3];
        if (unit_rotations ? !(std::fabs(n2 - 1.0) < 1e-5) : !(n2 > 0.0 && std::isfinite(n2))) finding("splat " + std::to_string(i) + " has a rotation that is not a unit quaternion");
        if (!(c.opacities[i] >= 0.0f && c.opacities[i] <= 1.0f))
            finding("splat " + std::to_string(i) + " has opacity " + std::to_string(c.opacities[i]) + " outside [0, 1]");
    }
    if (c.sh_degree < 0 || c.sh_degree > 3) finding("SH degree " + std::to_string(c.sh_degree));
}

inline bool same_format(SplatFormat a, SplatFormat b) {
    auto plyish = [](SplatFormat f) { return f == SplatFormat::Ply || f == SplatFormat::CompressedPly; };
    return a == b || (plyish(a) && plyish(b));
}

// Runs `read` (bytes -> cloud, filling a LoadReport) on the input under `name` and checks the contract; `format` is
// the reader's format, for the probe comparison.
template <typename Read>
void check_reader(const std::uint8_t* data, std::size_t size, const std::string& name, SplatFormat format, Read read) {
    GaussianCloud cloud;
    LoadReport report;
    try {
        cloud = read(data, size, name, &report);
    } catch (const FileFormatError& e) {
        if (std::string(e.what()).find("'" + name + "'") == std::string::npos)
            finding(std::string("FileFormatError does not name the file: ") + e.what());
        return;
    } catch (const std::exception& e) {
        finding(std::string("the reader threw another exception than FileFormatError: ") + e.what());
    } catch (...) {
        finding("the reader threw something that is not a std::exception");
    }
    check_cloud(cloud, name);
    SplatFileSummary summary;
    try {
        summary = io::probe_splat_bytes(data, size, name);
    } catch (const FileFormatError&) {
        return;  // the probe reads the header only: it may refuse what it cannot see is readable (never the reverse)
    } catch (const std::exception& e) {
        finding(std::string("the probe threw another exception than FileFormatError: ") + e.what());
    }
    if (!same_format(summary.format, format)) return;  // bytes the dispatch gives another format (by content)
    // The probe gives the count the file declares: the reader's splats plus those it dropped (ReadOptions keep all).
    const std::uint64_t read_count = cloud.size() + report.non_finite_dropped;
    if (summary.count != read_count)
        finding("the probe says " + std::to_string(summary.count) + " splats, the reader read " + std::to_string(cloud.size()) +
                " and dropped " + std::to_string(report.non_finite_dropped));
    if (summary.sh_degree != cloud.sh_degree)
        finding("the probe says SH degree " + std::to_string(summary.sh_degree) + ", the reader read " +
                std::to_string(cloud.sh_degree));
}

}  // namespace fuzz
}  // namespace raysplats
