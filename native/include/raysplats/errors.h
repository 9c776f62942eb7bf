// Errors thrown by the RaySplats core. Native code never aborts or exits (docs/design.md §2): every failure is
// one of these exceptions, which the Python bindings turn into Python exceptions for the add-on.
#pragma once

#include <cstdint>
#include <stdexcept>
#include <string>

namespace raysplats {

// Base class of every error the core throws on purpose.
class Error : public std::runtime_error {
public:
    using std::runtime_error::runtime_error;
};

// Bad or unreadable input file. The message always names the file, and the byte offset where known.
class FileFormatError : public Error {
public:
    static constexpr std::uint64_t kNoOffset = ~std::uint64_t(0);

    FileFormatError(const std::string& path, const std::string& problem, std::uint64_t byte_offset = kNoOffset)
        : Error(compose(path, problem, byte_offset)), path_(path), problem_(problem), byte_offset_(byte_offset) {}

    const std::string& path() const { return path_; }
    const std::string& problem() const { return problem_; }
    std::uint64_t byte_offset() const { return byte_offset_; }

private:
    static std::string compose(const std::string& path, const std::string& problem, std::uint64_t off) {
        std::string s = "'" + path + "': " + problem;
        if (off != kNoOffset) s += " (at byte " + std::to_string(off) + ")";
        return s;
    }
    std::string path_, problem_;
    std::uint64_t byte_offset_;
};

// Invalid arguments handed to a core function (wrong array sizes, K out of range, ...).
class InvalidArgument : public Error {
public:
    using Error::Error;
};

}  // namespace raysplats
