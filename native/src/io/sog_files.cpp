#include "io/sog_files.h"
#include "core/os_files.h"

#include <cerrno>
#include <cstring>

#include "io/zip_archive.h"

namespace raysplats {
namespace io {
namespace {

// A .sog bundle: the members of a zip, named as meta.json names them relative to the bundle's meta.json.
class ZipBundle : public SogFiles {
public:
    // `data` must outlive the bundle. `path` names the bundle in errors.
    ZipBundle(const std::uint8_t* data, std::size_t size, const std::string& path)
        : zip_(data, size, path, "a .sog is a zip of meta.json and WebP images") {
        find_meta();
    }

    FileFormatError error(const std::string& name, const std::string& problem) const override {
        return zip_.error(name, problem);
    }
    std::string meta_name() const override { return prefix_ + "meta.json"; }

    Bytes read(const std::string& name, std::uint64_t max_bytes, const std::string& role) override {
        const std::string member = name == meta_name() ? name : prefix_ + name;
        if (!zip_.contains(member))
            throw error("", name == meta_name() ? "the bundle has no meta.json"
                                                : "meta.json names '" + name + "' (" + role + "), which the bundle does not contain");
        return zip_.read(member, max_bytes, role);
    }

private:
    // meta.json at the root [spec 1.3], or else in the bundle's one folder (some tools zip the folder).
    void find_meta() {
        if (zip_.contains("meta.json")) return;
        std::string found;
        for (const std::string& n : zip_.names()) {
            if (n.size() > 10 && n.compare(n.size() - 10, 10, "/meta.json") == 0 && n.find('/') == n.size() - 10) {
                if (!found.empty()) throw zip_.error("", "the bundle has no meta.json at its root, and several in folders");
                found = n;
            }
        }
        if (found.empty()) throw zip_.error("", "the bundle has no meta.json: not a SOG bundle");
        prefix_ = found.substr(0, found.size() - 9);
    }

    ZipArchive zip_;
    std::string prefix_;  // the folder of meta.json inside the bundle, with its '/'; empty at the root
};

// Unbundled: meta.json and the images beside it.
class Folder : public SogFiles {
public:
    explicit Folder(const std::string& meta_path) : meta_path_(meta_path) {
        const std::size_t slash = os::last_separator(meta_path);
        dir_ = slash == std::string::npos ? "" : meta_path.substr(0, slash + 1);
    }
    FileFormatError error(const std::string& name, const std::string& problem) const override {
        return FileFormatError(name.empty() || name == meta_path_ ? meta_path_ : dir_ + name, problem);
    }
    std::string meta_name() const override { return meta_path_; }
    Bytes read(const std::string& name, std::uint64_t max_bytes, const std::string& role) override {
        const std::string path = name == meta_path_ ? name : dir_ + name;
        if (!os::path_status(path).exists)
            throw FileFormatError(path, "meta.json ('" + meta_path_ + "') names this file (" + role +
                                            "), which cannot be opened: it does not exist");
        const FileBytes f(path);
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

}  // namespace

std::unique_ptr<SogFiles> open_sog_files(const FileBytes& f) {
    const std::string& path = f.path();
    if (is_zip(f.data(), f.size())) return std::make_unique<ZipBundle>(f.data(), f.size(), path);
    if (lower_extension(path) == ".sog" || f.in_memory())
        throw FileFormatError(path, "not a SOG bundle: a .sog is a zip archive (no 'PK' zip magic)", 0);
    return std::make_unique<Folder>(path);
}

}  // namespace io
}  // namespace raysplats
