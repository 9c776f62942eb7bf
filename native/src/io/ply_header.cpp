// The PLY header parser shared by the PLY-based splat readers (io/ply_header.h).
#include "io/ply_header.h"

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cstring>

#include "raysplats/errors.h"

namespace raysplats {
namespace io {

bool parse_ply_type(const std::string& s, PlyType& t) {
    if (s == "char" || s == "int8") t = PlyType::Int8;
    else if (s == "uchar" || s == "uint8") t = PlyType::UInt8;
    else if (s == "short" || s == "int16") t = PlyType::Int16;
    else if (s == "ushort" || s == "uint16") t = PlyType::UInt16;
    else if (s == "int" || s == "int32") t = PlyType::Int32;
    else if (s == "uint" || s == "uint32") t = PlyType::UInt32;
    else if (s == "float" || s == "float32") t = PlyType::Float32;
    else if (s == "double" || s == "float64") t = PlyType::Float64;
    else return false;
    return true;
}

std::size_t ply_type_size(PlyType t) {
    switch (t) {
        case PlyType::Int8:
        case PlyType::UInt8: return 1;
        case PlyType::Int16:
        case PlyType::UInt16: return 2;
        case PlyType::Int32:
        case PlyType::UInt32:
        case PlyType::Float32: return 4;
        case PlyType::Float64: return 8;
    }
    return 0;
}

const char* ply_type_name(PlyType t) {
    switch (t) {
        case PlyType::Int8: return "char";
        case PlyType::UInt8: return "uchar";
        case PlyType::Int16: return "short";
        case PlyType::UInt16: return "ushort";
        case PlyType::Int32: return "int";
        case PlyType::UInt32: return "uint";
        case PlyType::Float32: return "float";
        case PlyType::Float64: return "double";
    }
    return "unknown";
}

namespace {

std::vector<std::string> split_ws(const std::string& line) {
    std::vector<std::string> out;
    std::size_t i = 0;
    while (i < line.size()) {
        while (i < line.size() && std::isspace(static_cast<unsigned char>(line[i]))) ++i;
        std::size_t j = i;
        while (j < line.size() && !std::isspace(static_cast<unsigned char>(line[j]))) ++j;
        if (j > i) out.push_back(line.substr(i, j - i));
        i = j;
    }
    return out;
}


}  // namespace

PlyHeader parse_ply_header(const std::uint8_t* data, std::size_t size, const std::string& path) {
    const char* d = reinterpret_cast<const char*>(data);
    if (size == 0) throw FileFormatError(path, "file is empty");
    PlyHeader h;
    std::size_t pos = 0;
    bool have_format = false, ended = false;
    int line_no = 0;
    while (!ended) {
        if (pos >= size) throw FileFormatError(path, "PLY header has no 'end_header' line (file ends in the header)", pos);
        if (pos >= kMaxPlyHeaderBytes)
            throw FileFormatError(path, "PLY header has no 'end_header' line in its first " + std::to_string(kMaxPlyHeaderBytes) +
                                            " bytes", pos);
        const std::size_t line_start = pos;
        const void* nl = std::memchr(d + pos, '\n', std::min(size, kMaxPlyHeaderBytes + 1) - pos);
        const std::size_t end = nl ? static_cast<std::size_t>(static_cast<const char*>(nl) - d) : size;
        std::string line(d + pos, end - pos);
        if (!line.empty() && line.back() == '\r') line.pop_back();
        pos = nl ? end + 1 : end;
        ++line_no;
        if (line_no == 1) {
            if (line != "ply") throw FileFormatError(path, "not a PLY file: first line is not 'ply'", 0);
            continue;
        }
        const auto tok = split_ws(line);
        if (tok.empty()) continue;
        const std::string& kw = tok[0];
        if (kw == "comment" || kw == "obj_info") continue;
        if (kw == "format") {
            if (tok.size() < 2) throw FileFormatError(path, "PLY 'format' line has no format name", line_start);
            if (tok[1] == "ascii") h.format = PlyFormat::Ascii;
            else if (tok[1] == "binary_little_endian") h.format = PlyFormat::BinaryLE;
            else if (tok[1] == "binary_big_endian") h.format = PlyFormat::BinaryBE;
            else throw FileFormatError(path, "unknown PLY format '" + tok[1] + "'", line_start);
            have_format = true;
        } else if (kw == "element") {
            if (!have_format) throw FileFormatError(path, "PLY header has no 'format' line before its first element", line_start);
            if (tok.size() != 3) throw FileFormatError(path, "malformed PLY element line '" + line + "'", line_start);
            PlyElement e;
            e.name = tok[1];
            e.header_offset = line_start;
            const auto r = std::from_chars(tok[2].data(), tok[2].data() + tok[2].size(), e.count);
            if (r.ec != std::errc() || r.ptr != tok[2].data() + tok[2].size())
                throw FileFormatError(path, "bad element count '" + tok[2] + "' for element '" + e.name + "'", line_start);
            h.elements.push_back(std::move(e));
        } else if (kw == "property") {
            if (h.elements.empty()) throw FileFormatError(path, "PLY property before any element", line_start);
            PlyElement& e = h.elements.back();
            PlyProperty p;
            p.header_offset = line_start;
            if (tok.size() >= 2 && tok[1] == "list") {
                if (tok.size() != 5) throw FileFormatError(path, "malformed PLY list property line '" + line + "'", line_start);
                if (!parse_ply_type(tok[2], p.count_type) || !parse_ply_type(tok[3], p.type))
                    throw FileFormatError(path, "unknown PLY type in '" + line + "'", line_start);
                // A count is a number of items: a float count has no meaning, and converting a huge or NaN one
                // to an integer is undefined behaviour.
                if (p.count_type == PlyType::Float32 || p.count_type == PlyType::Float64)
                    throw FileFormatError(path, "list property '" + tok[4] + "' of element '" + e.name + "' has a " +
                                                    tok[2] + " count; a list count must be an integer type",
                                          line_start);
                p.is_list = true;
                p.name = tok[4];
                e.has_list = true;
            } else {
                if (tok.size() != 3) throw FileFormatError(path, "malformed PLY property line '" + line + "'", line_start);
                if (!parse_ply_type(tok[1], p.type))
                    throw FileFormatError(path, "unknown PLY type '" + tok[1] + "' of property '" + tok[2] + "'", line_start);
                p.name = tok[2];
                p.offset = e.record_size;
                e.record_size += ply_type_size(p.type);
            }
            e.props.push_back(std::move(p));
        } else if (kw == "end_header") {
            ended = true;
        } else {
            throw FileFormatError(path, "unexpected PLY header line '" + line + "'", line_start);
        }
    }
    if (!have_format) throw FileFormatError(path, "PLY header has no 'format' line", 0);
    // Records without properties occupy no bytes, so nothing in the file bounds their count: skipping 2^64 - 1
    // of them would loop for minutes. Such an element holds no data; refuse it rather than guess.
    for (const PlyElement& e : h.elements)
        if (e.props.empty() && e.count > 0)
            throw FileFormatError(path, "PLY element '" + e.name + "' declares " + std::to_string(e.count) +
                                            " records but no properties", e.header_offset);
    h.data_offset = pos;
    return h;
}


}  // namespace io
}  // namespace raysplats
