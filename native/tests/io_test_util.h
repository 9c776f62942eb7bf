// Helpers for the splat file tests. The raw-byte readers here are written independently of the library's
// readers (own header parsing, memcpy at computed offsets) so that tests compare against the file itself.
#pragma once

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "raysplats/errors.h"

namespace raysplats {
namespace testutil {

inline std::string data_path(const std::string& name) { return std::string(RAYSPLATS_DATA_DIR) + "/" + name; }

inline std::string tmp_path(const std::string& name) {
    std::filesystem::create_directories(RAYSPLATS_TEST_TMP);
    return std::string(RAYSPLATS_TEST_TMP) + "/" + name;
}

inline std::vector<std::uint8_t> read_bytes(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    return std::vector<std::uint8_t>((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

inline void write_bytes(const std::string& path, const std::vector<std::uint8_t>& b) {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(b.data()), std::streamsize(b.size()));
}

inline void write_text(const std::string& path, const std::string& s) {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out << s;
}

// Independent reader of a binary little-endian PLY whose vertex properties are all 'float'.
struct RawPly {
    std::vector<std::uint8_t> bytes;
    std::size_t data_offset = 0, record_size = 0, count = 0;
    std::map<std::string, std::size_t> offset;  // property name -> byte offset in the record
    std::vector<std::string> names;

    explicit RawPly(const std::string& path) : bytes(read_bytes(path)) {
        const std::string text(bytes.begin(), bytes.begin() + std::min<std::size_t>(bytes.size(), 100000));
        const std::size_t end = text.find("end_header\n");
        if (end == std::string::npos) throw std::runtime_error("test: no end_header");
        data_offset = end + std::strlen("end_header\n");
        std::istringstream ss(text.substr(0, end));
        std::string line;
        bool in_vertex = false;
        while (std::getline(ss, line)) {
            std::istringstream ls(line);
            std::string kw;
            ls >> kw;
            if (kw == "element") {
                std::string name;
                ls >> name;
                in_vertex = name == "vertex";
                if (in_vertex) ls >> count;
            } else if (kw == "property" && in_vertex) {
                std::string type, name;
                ls >> type >> name;
                if (type != "float") throw std::runtime_error("test: non-float property");
                offset[name] = record_size;
                names.push_back(name);
                record_size += 4;
            }
        }
    }
    bool has(const std::string& name) const { return offset.count(name) != 0; }
    float get(std::size_t i, const std::string& name) const {
        float v;
        std::memcpy(&v, bytes.data() + data_offset + i * record_size + offset.at(name), 4);
        return v;
    }
    std::size_t rest_count() const {
        std::size_t n = 0;
        for (const auto& nm : names) n += nm.rfind("f_rest_", 0) == 0;
        return n;
    }
};

// Runs fn, expects a FileFormatError whose message names `file` and contains every string of `problems`.
inline void expect_format_error(const std::function<void()>& fn, const std::string& file,
                                const std::vector<std::string>& problems) {
    try {
        fn();
        ADD_FAILURE() << "expected FileFormatError for " << file;
    } catch (const FileFormatError& e) {
        const std::string msg = e.what();
        EXPECT_NE(msg.find(file), std::string::npos) << "message does not name the file: " << msg;
        for (const auto& p : problems) EXPECT_NE(msg.find(p), std::string::npos) << "message lacks '" << p << "': " << msg;
    } catch (const std::exception& e) {
        ADD_FAILURE() << "expected FileFormatError, got another exception: " << e.what();
    }
}

inline std::vector<std::size_t> sample_indices(std::size_t n) { return {0, 1, n / 2, n - 1}; }

inline double sigmoid(double x) { return 1.0 / (1.0 + std::exp(-x)); }

}  // namespace testutil
}  // namespace raysplats
