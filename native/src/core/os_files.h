// The operating system's files behind one interface, for Linux (POSIX) and Windows (Win32).
//
// Contract:
// - Every path is UTF-8, as Python and Blender hand it over. On Windows it is converted to UTF-16 and given to the
//   wide-character API, so any name the file system holds works (the narrow API would use the ANSI code page and
//   lose every character outside it); on Linux it is passed through as bytes.
// - Failures throw os::Error whose message is the system's own text for the error (strerror, FormatMessage); the
//   caller adds the path and what it was doing. Nothing here exits or aborts.
// - replace_file is the last step of an atomic write: on POSIX rename(2), which replaces the target in one step; on
//   Windows MoveFileExW with MOVEFILE_REPLACE_EXISTING | MOVEFILE_WRITE_THROUGH (a plain rename fails there when the
//   target exists). Readers see the old file or the new one, never a part.
// - FileView is a whole file's bytes, mapped read-only (mmap, MapViewOfFile) where the system allows and read into
//   memory otherwise; it lives as long as the object. On Windows a mapped file cannot be replaced or deleted while
//   the view lives.
#pragma once

#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <stdexcept>
#include <string>
#include <vector>

namespace raysplats {
namespace os {

class Error : public std::runtime_error {
public:
    using std::runtime_error::runtime_error;
};

struct PathStatus {
    bool exists = false;
    bool is_directory = false;
    bool is_regular_file = false;
    std::uint64_t size = 0;
};

// What is at `path`; exists == false when nothing is (or it cannot be reached). Never throws.
PathStatus path_status(const std::string& path) noexcept;

// The path as the C++ library wants it (std::ifstream, std::filesystem): UTF-8 decoded on Windows.
std::filesystem::path native_path(const std::string& path);

// std::fopen with a UTF-8 name; nullptr and errno set on failure, as std::fopen.
std::FILE* open_stdio(const std::string& path, const char* mode);

// A whole file's bytes, read-only.
class FileView {
public:
    explicit FileView(const std::string& path);  // throws Error (also for a directory)
    ~FileView();
    FileView(const FileView&) = delete;
    FileView& operator=(const FileView&) = delete;
    const std::uint8_t* data() const { return data_; }
    std::size_t size() const { return size_; }
    bool mapped() const { return view_ != nullptr; }

private:
    const std::uint8_t* data_ = nullptr;
    std::size_t size_ = 0;
    void* view_ = nullptr;  // the mapping, when mapped
    std::vector<std::uint8_t> buffer_;
};

// A file this process creates (never an existing one), written in order and flushed to disk before it is closed.
class NewFile {
public:
    NewFile() = default;
    ~NewFile();  // closes an open file (no flush; a caller that wants the data uses finish())
    NewFile(const NewFile&) = delete;
    NewFile& operator=(const NewFile&) = delete;
    // Creates `path` exclusively: false, with nothing changed, when it exists already; throws Error otherwise.
    bool create(const std::string& path);
    void write(const void* data, std::size_t size);  // throws Error
    void finish();                                   // flushes to disk and closes; throws Error
    void close() noexcept;                           // closes without flushing
    bool is_open() const;

private:
    std::intptr_t handle_ = -1;
};

// Creates a new file in the folder of `target` with a name of its own (the target's name, ".tmp", this process's id
// and a counter) and returns that name; throws Error when none can be made. Writing it and replacing the target with
// it makes an atomic write.
std::string create_temporary_beside(const std::string& target, NewFile& file);
// Writes `size` bytes to `path` atomically (a temporary file beside it, flushed, then replace_file); on failure the
// temporary file is removed, the target is untouched and Error is thrown.
void write_file_atomically(const std::string& path, const void* data, std::size_t size);
// Moves `from` onto `to` in one step, replacing a file that is there (see the contract). Throws Error.
void replace_file(const std::string& from, const std::string& to);
// Removes a file; failures are ignored (used to clean up temporary files).
void remove_file(const std::string& path) noexcept;
// This process's id (unique names of temporary files).
unsigned long process_id() noexcept;
// Where the file name in `path` starts after its last folder separator ('/', and on Windows also '\\'), or npos when
// the path has none. On Linux a backslash is an ordinary character of a file name.
std::size_t last_separator(const std::string& path) noexcept;

}  // namespace os
}  // namespace raysplats
