// The PLY header (Turk's format: "ply", "format", "element", "property", "end_header" lines), parsed once for every
// reader of a PLY-based splat format: the INRIA 3DGS layout (ply_format.cpp) and SuperSplat's compressed PLY
// (compressed_ply_format.cpp). Private to native/src/io.
//
// The parser checks the header's own consistency (known types, integer list counts, no records without properties,
// at most kMaxHeaderBytes) and throws FileFormatError naming the file and the byte offset of the offending line. It
// checks nothing about the data after the header: each reader bounds its element counts by the bytes that follow.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

#include "io/io_common.h"

namespace raysplats {
namespace io {

enum class PlyType { Int8, UInt8, Int16, UInt16, Int32, UInt32, Float32, Float64 };

// "char"/"int8", "uchar"/"uint8", ... "double"/"float64"; false for anything else.
bool parse_ply_type(const std::string& s, PlyType& t);
std::size_t ply_type_size(PlyType t);
// The spelling used in error messages ("float", "uint", "uchar", ...).
const char* ply_type_name(PlyType t);

struct PlyProperty {
    std::string name;
    PlyType type = PlyType::Float32;
    bool is_list = false;
    PlyType count_type = PlyType::UInt8;
    std::size_t offset = 0;         // within a binary record (fixed-size elements only)
    std::size_t header_offset = 0;  // byte offset of its 'property' line, for errors
};

struct PlyElement {
    std::string name;
    std::uint64_t count = 0;
    std::vector<PlyProperty> props;
    std::size_t record_size = 0;  // binary, when no list properties
    bool has_list = false;
    std::size_t header_offset = 0;  // byte offset of its 'element' line, for errors

    // The property of that name, or null.
    const PlyProperty* property(const std::string& property_name) const {
        for (const PlyProperty& p : props)
            if (p.name == property_name) return &p;
        return nullptr;
    }
};

enum class PlyFormat { Ascii, BinaryLE, BinaryBE };

struct PlyHeader {
    PlyFormat format = PlyFormat::BinaryLE;
    std::vector<PlyElement> elements;
    std::size_t data_offset = 0;  // first byte after end_header's newline

    // The element of that name, or null.
    const PlyElement* element(const std::string& element_name) const {
        for (const PlyElement& e : elements)
            if (e.name == element_name) return &e;
        return nullptr;
    }
};

constexpr std::size_t kMaxPlyHeaderBytes = 1 << 20;

// Parses the header of the PLY file `path` whose bytes are data[0, size).
PlyHeader parse_ply_header(const std::uint8_t* data, std::size_t size, const std::string& path);
inline PlyHeader parse_ply_header(const FileBytes& f) { return parse_ply_header(f.data(), f.size(), f.path()); }

// One scalar of type t at p (either byte order), as a double.
template <bool BigEndian>
inline double load_ply_value(const std::uint8_t* p, PlyType t) {
    std::uint8_t b[8];
    const std::size_t n = ply_type_size(t);
    if (BigEndian) {
        for (std::size_t i = 0; i < n; ++i) b[i] = p[n - 1 - i];
    } else {
        std::memcpy(b, p, n);
    }
    switch (t) {
        case PlyType::Int8: return double(static_cast<std::int8_t>(b[0]));
        case PlyType::UInt8: return double(b[0]);
        case PlyType::Int16: { std::int16_t v; std::memcpy(&v, b, 2); return v; }
        case PlyType::UInt16: { std::uint16_t v; std::memcpy(&v, b, 2); return v; }
        case PlyType::Int32: { std::int32_t v; std::memcpy(&v, b, 4); return v; }
        case PlyType::UInt32: { std::uint32_t v; std::memcpy(&v, b, 4); return v; }
        case PlyType::Float32: { float v; std::memcpy(&v, b, 4); return v; }
        case PlyType::Float64: { double v; std::memcpy(&v, b, 8); return v; }
    }
    return 0.0;
}

}  // namespace io
}  // namespace raysplats
