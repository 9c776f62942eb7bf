// The operating system's files (core/os_files.h): POSIX and Win32 implementations of one interface.
#include "core/os_files.h"

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstring>

#ifdef _WIN32
#include "core/windows_api.h"
#else
#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>
#endif

namespace raysplats {
namespace os {

#ifdef _WIN32

namespace {

// UTF-8 to UTF-16; a name that is not valid UTF-8 is refused rather than mangled.
std::wstring widen(const std::string& s) {
    if (s.empty()) return std::wstring();
    const int n = MultiByteToWideChar(CP_UTF8, MB_ERR_INVALID_CHARS, s.data(), int(s.size()), nullptr, 0);
    if (n <= 0) throw Error("the file name is not valid UTF-8");
    std::wstring w(std::size_t(n), L'\0');
    MultiByteToWideChar(CP_UTF8, MB_ERR_INVALID_CHARS, s.data(), int(s.size()), &w[0], n);
    return w;
}

std::string narrow(const wchar_t* w, int length) {
    const int n = WideCharToMultiByte(CP_UTF8, 0, w, length, nullptr, 0, nullptr, nullptr);
    if (n <= 0) return std::string();
    std::string s(std::size_t(n), '\0');
    WideCharToMultiByte(CP_UTF8, 0, w, length, &s[0], n, nullptr, nullptr);
    return s;
}

// The system's text for an error code, in UTF-8, without the trailing line break.
std::string error_text(DWORD code) {
    wchar_t* buffer = nullptr;
    const DWORD n = FormatMessageW(FORMAT_MESSAGE_ALLOCATE_BUFFER | FORMAT_MESSAGE_FROM_SYSTEM | FORMAT_MESSAGE_IGNORE_INSERTS,
                                   nullptr, code, 0, reinterpret_cast<wchar_t*>(&buffer), 0, nullptr);
    std::string text = n ? narrow(buffer, int(n)) : std::string();
    if (buffer) LocalFree(buffer);
    while (!text.empty() && (text.back() == '\n' || text.back() == '\r' || text.back() == ' ' || text.back() == '.'))
        text.pop_back();
    return text.empty() ? "Windows error " + std::to_string(code) : text;
}

[[noreturn]] void fail_last() { throw Error(error_text(GetLastError())); }

HANDLE as_handle(std::intptr_t h) { return reinterpret_cast<HANDLE>(h); }

}  // namespace

PathStatus path_status(const std::string& path) noexcept {
    PathStatus s;
    try {
        WIN32_FILE_ATTRIBUTE_DATA data{};
        if (!GetFileAttributesExW(widen(path).c_str(), GetFileExInfoStandard, &data)) return s;
        s.exists = true;
        s.is_directory = (data.dwFileAttributes & FILE_ATTRIBUTE_DIRECTORY) != 0;
        s.is_regular_file = !s.is_directory && (data.dwFileAttributes & FILE_ATTRIBUTE_DEVICE) == 0;
        s.size = (std::uint64_t(data.nFileSizeHigh) << 32) | data.nFileSizeLow;
    } catch (const Error&) {
    }
    return s;
}

std::filesystem::path native_path(const std::string& path) { return std::filesystem::path(widen(path)); }

std::FILE* open_stdio(const std::string& path, const char* mode) {
    try {
        return _wfopen(widen(path).c_str(), widen(mode).c_str());
    } catch (const Error&) {
        errno = EINVAL;
        return nullptr;
    }
}

FileView::FileView(const std::string& path) {
    const std::wstring wide = widen(path);
    const PathStatus status = path_status(path);
    if (status.is_directory) throw Error("is a directory, not a file");
    // FILE_SHARE_DELETE: another process may rename or delete the file while it is read, as on POSIX.
    HANDLE file = CreateFileW(wide.c_str(), GENERIC_READ, FILE_SHARE_READ | FILE_SHARE_WRITE | FILE_SHARE_DELETE, nullptr,
                              OPEN_EXISTING, FILE_FLAG_SEQUENTIAL_SCAN, nullptr);
    if (file == INVALID_HANDLE_VALUE) fail_last();
    LARGE_INTEGER size{};
    if (!GetFileSizeEx(file, &size)) {
        const DWORD e = GetLastError();
        CloseHandle(file);
        throw Error(error_text(e));
    }
    size_ = std::size_t(size.QuadPart);
    if (size_ == 0) {
        CloseHandle(file);
        return;
    }
    // The view keeps the file open; both handles can be closed once it exists.
    HANDLE mapping = CreateFileMappingW(file, nullptr, PAGE_READONLY, 0, 0, nullptr);
    if (mapping) {
        view_ = MapViewOfFile(mapping, FILE_MAP_READ, 0, 0, 0);
        CloseHandle(mapping);
    }
    if (view_) {
        CloseHandle(file);
        data_ = static_cast<const std::uint8_t*>(view_);
        return;
    }
    // Not mappable: read it.
    buffer_.resize(size_);
    std::size_t done = 0;
    while (done < size_) {
        DWORD got = 0;
        const DWORD want = DWORD(std::min<std::size_t>(size_ - done, std::size_t(1) << 30));
        if (!ReadFile(file, buffer_.data() + done, want, &got, nullptr) || got == 0) {
            const DWORD e = GetLastError();
            CloseHandle(file);
            throw Error(got == 0 && e == ERROR_SUCCESS ? std::string("unexpected end of file") : error_text(e));
        }
        done += got;
    }
    CloseHandle(file);
    data_ = buffer_.data();
}

FileView::~FileView() {
    if (view_) UnmapViewOfFile(view_);
}

bool NewFile::create(const std::string& path) {
    close();
    HANDLE h = CreateFileW(widen(path).c_str(), GENERIC_WRITE, 0, nullptr, CREATE_NEW, FILE_ATTRIBUTE_NORMAL, nullptr);
    if (h == INVALID_HANDLE_VALUE) {
        const DWORD e = GetLastError();
        if (e == ERROR_FILE_EXISTS || e == ERROR_ALREADY_EXISTS) return false;
        throw Error(error_text(e));
    }
    handle_ = reinterpret_cast<std::intptr_t>(h);
    return true;
}

void NewFile::write(const void* data, std::size_t size) {
    if (!is_open()) throw Error("the file is not open");
    const char* p = static_cast<const char*>(data);
    while (size > 0) {
        DWORD written = 0;
        const DWORD chunk = DWORD(std::min<std::size_t>(size, std::size_t(1) << 30));
        if (!WriteFile(as_handle(handle_), p, chunk, &written, nullptr) || written == 0) fail_last();
        p += written;
        size -= written;
    }
}

void NewFile::finish() {
    if (!is_open()) throw Error("the file is not open");
    if (!FlushFileBuffers(as_handle(handle_))) fail_last();
    HANDLE h = as_handle(handle_);
    handle_ = -1;
    if (!CloseHandle(h)) fail_last();
}

void NewFile::close() noexcept {
    if (is_open()) CloseHandle(as_handle(handle_));
    handle_ = -1;
}

bool NewFile::is_open() const { return handle_ != -1; }

NewFile::~NewFile() { close(); }

void replace_file(const std::string& from, const std::string& to) {
    const std::wstring source = widen(from), target = widen(to);
    // A virus scanner or the search indexer may hold the old file open for a moment after it was written or read;
    // MoveFileExW then fails with a sharing violation or access denied. Retrying for up to half a second outlasts
    // such scans; a file that stays locked (or a read-only target) still fails with the system's message.
    for (int attempt = 0;; ++attempt) {
        if (MoveFileExW(source.c_str(), target.c_str(), MOVEFILE_REPLACE_EXISTING | MOVEFILE_WRITE_THROUGH)) return;
        const DWORD error = GetLastError();
        if (attempt == 10 || (error != ERROR_SHARING_VIOLATION && error != ERROR_ACCESS_DENIED)) break;
        Sleep(50);
    }
    fail_last();
}

void remove_file(const std::string& path) noexcept {
    try {
        DeleteFileW(widen(path).c_str());
    } catch (const Error&) {
    }
}

unsigned long process_id() noexcept { return GetCurrentProcessId(); }

#else  // POSIX

namespace {
[[noreturn]] void fail_errno(int e) { throw Error(std::strerror(e)); }
}  // namespace

PathStatus path_status(const std::string& path) noexcept {
    PathStatus s;
    struct stat st {};
    if (::stat(path.c_str(), &st) != 0) return s;
    s.exists = true;
    s.is_directory = S_ISDIR(st.st_mode);
    s.is_regular_file = S_ISREG(st.st_mode);
    s.size = std::uint64_t(st.st_size);
    return s;
}

std::filesystem::path native_path(const std::string& path) { return std::filesystem::path(path); }

std::FILE* open_stdio(const std::string& path, const char* mode) { return std::fopen(path.c_str(), mode); }

FileView::FileView(const std::string& path) {
    const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) fail_errno(errno);
    struct stat st {};
    if (::fstat(fd, &st) != 0) {
        const int e = errno;
        ::close(fd);
        fail_errno(e);
    }
    if (S_ISDIR(st.st_mode)) {
        ::close(fd);
        throw Error("is a directory, not a file");
    }
    size_ = static_cast<std::size_t>(st.st_size);
    if (size_ == 0) {
        ::close(fd);
        return;
    }
    void* p = ::mmap(nullptr, size_, PROT_READ, MAP_PRIVATE, fd, 0);
    if (p != MAP_FAILED) {
        ::madvise(p, size_, MADV_SEQUENTIAL | MADV_WILLNEED);
        view_ = p;
        data_ = static_cast<const std::uint8_t*>(p);
        ::close(fd);
        return;
    }
    // Not mappable (a pipe, some network file systems): read it.
    buffer_.resize(size_);
    std::size_t done = 0;
    while (done < size_) {
        const ssize_t r = ::read(fd, buffer_.data() + done, size_ - done);
        if (r < 0 && errno == EINTR) continue;
        if (r <= 0) {
            const int e = errno;
            ::close(fd);
            throw Error(r == 0 ? std::string("unexpected end of file") : std::string(std::strerror(e)));
        }
        done += static_cast<std::size_t>(r);
    }
    ::close(fd);
    data_ = buffer_.data();
}

FileView::~FileView() {
    if (view_) ::munmap(view_, size_);
}

bool NewFile::create(const std::string& path) {
    close();
    // Mode 0666 so that the process umask applies, as for any ordinarily created file.
    const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
    if (fd < 0) {
        if (errno == EEXIST) return false;
        fail_errno(errno);
    }
    handle_ = fd;
    return true;
}

void NewFile::write(const void* data, std::size_t size) {
    if (!is_open()) throw Error("the file is not open");
    const char* p = static_cast<const char*>(data);
    while (size > 0) {
        const ssize_t w = ::write(int(handle_), p, std::min<std::size_t>(size, std::size_t(1) << 30));
        if (w < 0 && errno == EINTR) continue;
        if (w <= 0) fail_errno(w < 0 ? errno : EIO);
        p += w;
        size -= static_cast<std::size_t>(w);
    }
}

void NewFile::finish() {
    if (!is_open()) throw Error("the file is not open");
    if (::fsync(int(handle_)) != 0) fail_errno(errno);
    const int fd = int(handle_);
    handle_ = -1;
    if (::close(fd) != 0) fail_errno(errno);
}

void NewFile::close() noexcept {
    if (is_open()) ::close(int(handle_));
    handle_ = -1;
}

bool NewFile::is_open() const { return handle_ >= 0; }

NewFile::~NewFile() { close(); }

void replace_file(const std::string& from, const std::string& to) {
    if (::rename(from.c_str(), to.c_str()) != 0) fail_errno(errno);
}

void remove_file(const std::string& path) noexcept { ::unlink(path.c_str()); }

unsigned long process_id() noexcept { return static_cast<unsigned long>(::getpid()); }

#endif

namespace {
std::atomic<unsigned> g_temp_counter{0};
}

std::string create_temporary_beside(const std::string& target, NewFile& file) {
    for (int attempt = 0; attempt < 100; ++attempt) {
        std::string name = target + ".tmp" + std::to_string(process_id()) + "_" + std::to_string(g_temp_counter++);
        if (file.create(name)) return name;
    }
    throw Error("every temporary name is taken");
}

void write_file_atomically(const std::string& path, const void* data, std::size_t size) {
    NewFile file;
    const std::string temp = create_temporary_beside(path, file);
    try {
        file.write(data, size);
        file.finish();
        replace_file(temp, path);
    } catch (const Error&) {
        file.close();
        remove_file(temp);
        throw;
    }
}

std::size_t last_separator(const std::string& path) noexcept {
#ifdef _WIN32
    return path.find_last_of("/\\");
#else
    return path.find_last_of('/');
#endif
}

}  // namespace os
}  // namespace raysplats
