// Builders of PlayCanvas SOG scenes for the tests, written from the format's specification (see
// native/src/io/sog_format.cpp), independently of the reader: lossless WebP images encoded with libwebp, a meta.json
// as text, and zip archives written byte by byte (stored or deflated members, with sizes that may lie on purpose).
#pragma once

#include <webp/encode.h>
#include <zlib.h>

#include <cstdint>
#include <cstring>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace raysplats {
namespace testutil {

using ByteVector = std::vector<std::uint8_t>;

// An RGBA image of width x height, all pixels `fill`, encoded as a lossless WebP.
struct RgbaImage {
    int width, height;
    ByteVector rgba;
    RgbaImage(int w, int h, std::uint32_t fill = 0xff000000u) : width(w), height(h), rgba(std::size_t(w) * h * 4) {
        for (std::size_t i = 0; i < std::size_t(w) * h; ++i)
            for (int c = 0; c < 4; ++c) rgba[4 * i + c] = std::uint8_t(fill >> (8 * c));
    }
    std::uint8_t* pixel(std::size_t i) { return &rgba[4 * i]; }
    void set(std::size_t i, std::uint8_t r, std::uint8_t g, std::uint8_t b, std::uint8_t a) {
        std::uint8_t* p = pixel(i);
        p[0] = r, p[1] = g, p[2] = b, p[3] = a;
    }
    // Lossless WebP with the RGB under transparent pixels kept (libwebp's lossless encoders keep it exactly).
    ByteVector webp() const {
        WebPConfig config;
        WebPPicture picture;
        if (!WebPConfigInit(&config) || !WebPPictureInit(&picture)) throw std::runtime_error("test: libwebp init");
        config.lossless = 1;
        config.exact = 1;
        config.method = 0;
        picture.use_argb = 1;
        picture.width = width, picture.height = height;
        WebPMemoryWriter writer;
        WebPMemoryWriterInit(&writer);
        picture.writer = WebPMemoryWrite;
        picture.custom_ptr = &writer;
        if (!WebPPictureImportRGBA(&picture, rgba.data(), width * 4) || !WebPEncode(&config, &picture))
            throw std::runtime_error("test: WebP encoding failed");
        ByteVector out(writer.mem, writer.mem + writer.size);
        WebPPictureFree(&picture);
        WebPMemoryWriterClear(&writer);
        return out;
    }
};

// A zip archive written by hand (APPNOTE.TXT 4.3: local headers, central directory, end of central directory).
struct ZipMember {
    std::string name;
    ByteVector data;
    bool deflate = false;
    // When set, the size written in the headers instead of the real uncompressed size (a lying member).
    long long claimed_size = -1;
};

inline void put16(ByteVector& b, std::uint32_t v) { b.push_back(std::uint8_t(v)), b.push_back(std::uint8_t(v >> 8)); }
inline void put32(ByteVector& b, std::uint32_t v) { put16(b, v & 0xffff), put16(b, v >> 16); }

inline ByteVector raw_deflate(const ByteVector& in) {
    z_stream z{};
    if (deflateInit2(&z, 9, Z_DEFLATED, -15, 9, Z_DEFAULT_STRATEGY) != Z_OK) throw std::runtime_error("test: deflateInit2");
    ByteVector out(deflateBound(&z, uLong(in.size())));
    z.next_in = const_cast<Bytef*>(in.data());
    z.avail_in = uInt(in.size());
    z.next_out = out.data();
    z.avail_out = uInt(out.size());
    if (deflate(&z, Z_FINISH) != Z_STREAM_END) throw std::runtime_error("test: deflate");
    out.resize(z.total_out);
    deflateEnd(&z);
    return out;
}

inline ByteVector make_zip(const std::vector<ZipMember>& members) {
    ByteVector zip, central;
    for (const ZipMember& m : members) {
        const ByteVector payload = m.deflate ? raw_deflate(m.data) : m.data;
        const std::uint32_t crc = std::uint32_t(crc32(0, m.data.data(), uInt(m.data.size())));
        const std::uint32_t usize = m.claimed_size >= 0 ? std::uint32_t(m.claimed_size) : std::uint32_t(m.data.size());
        const std::uint32_t offset = std::uint32_t(zip.size());
        const auto header = [&](ByteVector& b, bool is_central) {
            put32(b, is_central ? 0x02014b50u : 0x04034b50u);
            if (is_central) put16(b, 20);
            put16(b, 20), put16(b, 0), put16(b, m.deflate ? 8 : 0), put16(b, 0), put16(b, 0x21);
            put32(b, crc), put32(b, std::uint32_t(payload.size())), put32(b, usize);
            put16(b, std::uint32_t(m.name.size())), put16(b, 0);
            if (is_central) put16(b, 0), put16(b, 0), put16(b, 0), put32(b, 0), put32(b, offset);
            b.insert(b.end(), m.name.begin(), m.name.end());
        };
        header(zip, false);
        zip.insert(zip.end(), payload.begin(), payload.end());
        header(central, true);
    }
    const std::uint32_t central_offset = std::uint32_t(zip.size());
    zip.insert(zip.end(), central.begin(), central.end());
    put32(zip, 0x06054b50u), put16(zip, 0), put16(zip, 0);
    put16(zip, std::uint32_t(members.size())), put16(zip, std::uint32_t(members.size()));
    put32(zip, std::uint32_t(central.size())), put32(zip, central_offset), put16(zip, 0);
    return zip;
}

inline ByteVector bytes_of(const std::string& s) { return ByteVector(s.begin(), s.end()); }

// A meta.json (version 2) for `count` splats; codebooks are given as JSON text so that tests can break them.
inline std::string sog_meta_v2(std::size_t count, const std::string& scales_codebook, const std::string& sh0_codebook,
                               const std::string& shn = "", const std::string& mins = "[-1, -2, -3]",
                               const std::string& maxs = "[1, 2, 3]") {
    std::string s = "{\"version\": 2, \"count\": " + std::to_string(count) +
                    ", \"means\": {\"mins\": " + mins + ", \"maxs\": " + maxs +
                    ", \"files\": [\"means_l.webp\", \"means_u.webp\"]}, \"scales\": {\"codebook\": " + scales_codebook +
                    ", \"files\": [\"scales.webp\"]}, \"quats\": {\"files\": [\"quats.webp\"]}, \"sh0\": {\"codebook\": " +
                    sh0_codebook + ", \"files\": [\"sh0.webp\"]}";
    if (!shn.empty()) s += ", \"shN\": " + shn;
    return s + "}";
}

// A JSON list of n numbers first + k * step.
inline std::string json_ramp(int n, double first, double step) {
    std::string s = "[";
    for (int k = 0; k < n; ++k) s += (k ? ", " : "") + std::to_string(first + k * step);
    return s + "]";
}

// The members of a small valid version 2 scene of `count` splats without higher SH: every image w x h with pixels
// set to fixed patterns (each test that needs other values builds its own).
inline std::vector<ZipMember> small_sog_members(std::size_t count, int w, int h, const std::string& meta) {
    RgbaImage means(w, h, 0xff000000u), quats(w, h, 0xff000000u | 0x808080u), scales(w, h, 0xff000000u), sh0(w, h, 0x80000000u);
    for (std::size_t i = 0; i < count; ++i) quats.set(i, 128, 128, 128, 255);  // identity: x = y = z ~ 0, w largest
    return {{"meta.json", bytes_of(meta)},
            {"means_l.webp", means.webp()},
            {"means_u.webp", means.webp()},
            {"quats.webp", quats.webp()},
            {"scales.webp", scales.webp()},
            {"sh0.webp", sh0.webp()}};
}

}  // namespace testutil
}  // namespace raysplats
