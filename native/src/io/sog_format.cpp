// PlayCanvas SOG reader (read only: the core writes no SOG).
//
// A SOG scene is a meta.json plus lossless WebP images, either as files beside the meta.json ("unbundled") or as the
// members of one zip file, a .sog bundle (the same names at the archive's root; a bundle whose files sit in one
// folder is read too). Sources, cited beside each formula below:
//   [spec]  the SOG format specification, developer.playcanvas.com user-manual/gaussian-splatting/formats/sog
//           (playcanvas/developer-site docs/user-manual/gaussian-splatting/formats/sog.md), version 2;
//   [st]    @playcanvas/splat-transform src/lib/readers/read-sog.ts (v2) and read-sog-v1.ts (v1), whose decoding wrote
//           shared/data/unicorn_sh3_reordered.ply from unicorn_sh3.sog, and src/lib/writers/write-sog.ts;
//   [eng]   playcanvas/engine src/scene/gsplat/gsplat-sog-data.js (GSplatSogIterator, decompress, prepareCodebook)
//           and src/framework/parsers/sogs.js (upgradeMeta: v1 -> v2).
//
// Pixels: image width W, height H, splat i at pixel (i % W, i / W), row-major from the top left; every per-splat image
// has W*H >= count and the trailing pixels are ignored [spec 1.1]. Bytes are raw 8-bit values, no gamma [spec 2].
//
//   meta.json         version 2 ("version": 2, "count") or 1 (no "version"; count = means.shape[0]) [st, eng]
//   means_l, means_u  q = means_u.c << 8 | means_l.c per axis c of R,G,B; n = lerp(mins[c], maxs[c], q / 65535);
//                     position = sign(n) (exp|n| - 1), undoing the encoder's sign(x) ln(|x| + 1) [spec 3.1; st]
//   quats             R,G,B: three components a = (byte / 255 - 0.5) sqrt 2, in [-1/sqrt2, 1/sqrt2]; A - 252 in 0..3 is
//                     the index, in (w, x, y, z) order, of the largest component, left out and rebuilt as
//                     sqrt(max(0, 1 - a^2 - b^2 - c^2)); the kept ones fill the other places in order [spec 3.2; st
//                     unpackQuat; eng: mode 0 -> (x, y, z, w) = (a, b, c, d)]. A outside 252..255 is reserved: refused.
//   scales            v2: log scale = scales.codebook[byte] per axis R,G,B [spec 3.3; st];
//                     v1: log scale = lerp(scales.mins[c], scales.maxs[c], byte / 255) [st v1; eng]; scale = exp.
//   sh0               v2: SH DC coefficient = sh0.codebook[byte] per R,G,B; opacity = A / 255 [spec 3.4; st stores
//                     logit(A / 255) in its PLY]; v1: DC = lerp(sh0.mins[c], sh0.maxs[c], byte / 255), opacity =
//                     sigmoid(lerp(mins[3], maxs[3], A / 255)) [st v1; eng].
//   shN_labels        palette index n = R | G << 8 per splat, n < shN.count (v2) [spec 3.5; st]
//   shN_centroids     64 palette entries per row, each `coeffs` = 3, 8, 15 pixels wide (bands 1, 2, 3), so the image is
//                     64 * coeffs wide; coefficient k of entry n is pixel ((n % 64) coeffs + k, n / 64), its R,G,B the
//                     red, green, blue coefficient: v2 shN.codebook[byte], v1 lerp(shN.mins, shN.maxs, byte / 255)
//                     (scalars) [spec 3.5; st; eng]. v1 has no "bands": they follow from the width (192, 512, 960) [st v1,
//                     eng calcBands], and its palette holds (W / coeffs) H entries [st v1].
//   codebooks         256 numbers; a null first entry (JavaScript writes -Infinity as null) is replaced as the engine
//                     does: codebook[0] = codebook[1] + (codebook[1] - codebook[255]) / 255 [eng prepareCodebook].
//
// Axes: none converted. splat-transform's writer bakes its data to "PLY space" before encoding and its reader returns
// the table in PLY space (write-sog.ts, read-sog.ts: Transform.PLY), so a SOG holds the axes of the .ply it came from,
// the core's RDF (docs/design.md §4), like .ply and .splat. ([spec 1.2] says x right, y up, z back; the tools do not
// convert.)
//
// Hostile input: every bound is checked before what it bounds is allocated.
//   - meta.json (sog_meta.h): at most 1 MiB and 64 levels deep; each number finite; every name a relative path inside
//     the scene.
//   - a zip member (zip_archive.h): its claimed size at most what its role can need, and at most 1032 times its
//     deflated size (deflate's largest expansion); stored members as long as their data; the CRC is checked.
//   - an image's W*H at least count, at most 2 count + 65536 (writers pad to a multiple of 4 [st write-sog.ts]), and at
//     most 65536 pixels per byte of the WebP (see kMaxLosslessPixelsPerByte): count, which sizes the cloud, is thus
//     bounded by the bytes of the means image.
//   - every codebook index inside its codebook, every palette index below shN.count and inside the centroids image.
//
// Where the files come from (a bundle or a folder) is sog_files.h; meta.json's fields and their tables, sog_meta.h;
// this file opens and decodes the images.
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <webp/decode.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>

#include "io/io_common.h"
#include "io/sog_files.h"
#include "io/sog_meta.h"
#include "io/splat_formats.h"
#include "io/zip_archive.h"
#include "raysplats/splat_io.h"

namespace raysplats {
namespace io {
namespace {

// Pixels a lossless WebP (VP8L) can decode from one byte: a backward reference copies at most 4096 (packed) pixels and
// its length code for that needs 10 extra bits (VP8L spec 5.2.2: prefix code 23, (23 - 2) >> 1 extra bits), and the
// colour-indexing transform packs up to 8 pixels (palettes of 2 colours) into one, so at most 8 * 4096 pixels per
// 10 bits, 26214 pixels per byte; rounded up to 65536 for headroom.
constexpr std::uint64_t kMaxLosslessPixelsPerByte = 65536;
// Writers pad images to a multiple of 4 in each direction [st write-sog.ts: width = ceil(sqrt(n) / 4) * 4, height =
// ceil(n / width / 4) * 4]; older ones made them square. Anything far larger than the count needs is refused.
inline std::uint64_t max_pixels_for(std::uint64_t count) { return 2 * count + 65536; }
// Bytes of a lossless WebP of P pixels at worst: 4 Huffman codes of at most 15 bits per literal pixel, plus headers.
inline std::uint64_t max_webp_bytes(std::uint64_t pixels) { return 8 * pixels + (std::uint64_t(1) << 20); }

constexpr int kShCoeffsForBands[4] = {0, 3, 8, 15};
constexpr std::uint64_t kPaletteEntriesPerRow = 64;

struct Image {
    std::string name;
    std::uint32_t width = 0, height = 0;
    Bytes webp;  // the file, until decoded
    Bytes rgba;  // width * height * 4 once decoded
    std::uint64_t pixels() const { return std::uint64_t(width) * height; }
};

// Reads an image file and checks its size against what it must hold, without decoding it.
Image open_image(SogFiles& files, const std::string& name, const std::string& role, std::uint64_t min_pixels,
                 std::uint64_t max_pixels, const std::string& min_reason) {
    Image im;
    im.name = name;
    im.webp = files.read(name, max_webp_bytes(max_pixels), role);
    WebPBitstreamFeatures features;
    if (WebPGetFeatures(im.webp.data(), im.webp.size(), &features) != VP8_STATUS_OK)
        throw files.error(name, "not a WebP image (" + role + "; SOG images are lossless WebP)");
    if (features.format != 2)
        throw files.error(name, "a lossy WebP (" + role + "): SOG values are exact bytes that lossy compression corrupts");
    im.width = std::uint32_t(features.width), im.height = std::uint32_t(features.height);
    const std::string size = std::to_string(im.width) + " x " + std::to_string(im.height);
    if (im.pixels() < min_pixels)
        throw files.error(name, role + " is " + size + " = " + std::to_string(im.pixels()) + " pixels, fewer than " + min_reason);
    if (im.pixels() > max_pixels)
        throw files.error(name, role + " is " + size + " pixels, more than the " + std::to_string(max_pixels) +
                                    " it can need for " + min_reason);
    if (im.pixels() > std::uint64_t(im.webp.size()) * kMaxLosslessPixelsPerByte)
        throw files.error(name, role + " claims " + size + " pixels, more than a lossless WebP of " +
                                    std::to_string(im.webp.size()) + " bytes can hold");
    return im;
}

void decode_image(const SogFiles& files, Image& im) {
    im.rgba.resize(std::size_t(im.pixels()) * 4);
    if (!WebPDecodeRGBAInto(im.webp.data(), im.webp.size(), im.rgba.data(), im.rgba.size(), int(im.width) * 4))
        throw files.error(im.name, "corrupt WebP data (" + std::to_string(im.width) + " x " + std::to_string(im.height) + ")");
    Bytes().swap(im.webp);
}

void release(Image& im) { Bytes().swap(im.rgba), Bytes().swap(im.webp); }

// The first splat (lowest index) at which a check failed, across threads, with what was wrong there.
struct FirstBad {
    std::atomic<std::uint64_t> index{~std::uint64_t(0)};
    void note(std::uint64_t i) {
        std::uint64_t cur = index.load();
        while (i < cur && !index.compare_exchange_weak(cur, i)) {
        }
    }
    bool any() const { return index.load() != ~std::uint64_t(0); }
};

std::string pixel_of(const Image& im, std::uint64_t i) {
    return "pixel (" + std::to_string(i % im.width) + ", " + std::to_string(i / im.width) + ") (splat " + std::to_string(i) + ")";
}

// The shN centroids image, which meta.json's count does not bound: at most the largest palette, 64 entries of up to
// 15 coefficients per row.
Image open_centroids_image(SogFiles& files, const SogMeta& m) {
    const std::uint64_t max_centroid_pixels = kPaletteEntriesPerRow * 15 * (kMaxSogPaletteEntries / kPaletteEntriesPerRow);
    return open_image(files, m.centroids_file, "the shN centroids image", 1, max_centroid_pixels,
                      "a palette of 1 to 65536 entries");
}

// The palette's bands and size against the centroids image: v1 takes both from the image, v2 checks the image
// holds the palette meta.json gives.
void fit_palette_to_centroids(const SogFiles& files, const Image& centroids, SogMeta& m) {
    const std::uint32_t w = centroids.width;
    if (m.version == 1) {
        // [st v1, eng calcBands]: 192, 512, 960 pixels wide for 1, 2, 3 bands.
        m.bands = w == 192 ? 1 : w == 512 ? 2 : w == 960 ? 3 : 0;
        if (m.bands == 0)
            throw files.error(centroids.name, "the shN centroids image is " + std::to_string(w) +
                                                  " pixels wide; version 1 palettes are 192, 512 or 960 (1, 2, 3 bands)");
        m.palette_count = std::uint64_t(w / std::uint32_t(kShCoeffsForBands[m.bands])) * centroids.height;
        m.palette_count = std::min(m.palette_count, kMaxSogPaletteEntries);
    } else {
        const std::uint64_t want_w = kPaletteEntriesPerRow * std::uint64_t(kShCoeffsForBands[m.bands]);
        const std::uint64_t want_h = (m.palette_count + kPaletteEntriesPerRow - 1) / kPaletteEntriesPerRow;
        if (w != want_w || centroids.height < want_h)
            throw files.error(centroids.name,
                              "the shN centroids image is " + std::to_string(w) + " x " + std::to_string(centroids.height) +
                                  "; a palette of " + std::to_string(m.palette_count) + " entries of " +
                                  std::to_string(m.bands) + " bands needs " + std::to_string(want_w) + " x " +
                                  std::to_string(want_h) + " (64 entries per row)");
    }
}

struct SogScene {
    SogMeta meta;
    Image means_l, means_u, quats, scales, sh0, centroids, labels;
};

// Reads meta.json and checks every image's size before anything as large as the cloud is allocated.
SogScene open_scene(SogFiles& files) {
    SogScene s;
    s.meta = read_sog_meta(files);
    SogMeta& m = s.meta;
    const std::uint64_t n = m.count;
    const std::string reason = "the " + std::to_string(n) + " splats of meta.json's count";
    const std::uint64_t max_pixels = max_pixels_for(n);
    s.means_l = open_image(files, m.means_files[0], "the means image (low bytes)", n, max_pixels, reason);
    s.means_u = open_image(files, m.means_files[1], "the means image (high bytes)", n, max_pixels, reason);
    s.quats = open_image(files, m.quats_file, "the quats image", n, max_pixels, reason);
    s.scales = open_image(files, m.scales_file, "the scales image", n, max_pixels, reason);
    s.sh0 = open_image(files, m.sh0_file, "the sh0 image", n, max_pixels, reason);
    if (m.has_shn) {
        s.labels = open_image(files, m.labels_file, "the shN labels image", n, max_pixels, reason);
        s.centroids = open_centroids_image(files, m);
        fit_palette_to_centroids(files, s.centroids, m);
    }
    return s;
}

// Runs body(i) for every splat i < n, in parallel.
template <typename Body>
void for_each_splat(std::size_t n, Body&& body) {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, kGrain), [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i) body(i);
    });
}

// Positions [spec 3.1].
void decode_positions(SogFiles& files, SogScene& s, GaussianCloud& c) {
    const SogMeta& m = s.meta;
    decode_image(files, s.means_l);
    decode_image(files, s.means_u);
    const std::uint8_t* lo = s.means_l.rgba.data();
    const std::uint8_t* hi = s.means_u.rgba.data();
    for_each_splat(c.size(), [&](std::size_t i) {
        for (int a = 0; a < 3; ++a) {
            const unsigned q = unsigned(hi[4 * i + std::size_t(a)]) << 8 | lo[4 * i + std::size_t(a)];
            const double v = m.means_min[a] + (m.means_max[a] - m.means_min[a]) * (q / 65535.0);
            c.positions[3 * i + std::size_t(a)] = float(std::copysign(std::expm1(std::fabs(v)), v));
        }
    });
    release(s.means_l);
    release(s.means_u);
}

// Rotations [spec 3.2]: the components in (w, x, y, z) order, the largest left out.
void decode_rotations(SogFiles& files, SogScene& s, GaussianCloud& c) {
    decode_image(files, s.quats);
    constexpr int kKept[4][3] = {{1, 2, 3}, {0, 2, 3}, {0, 1, 3}, {0, 1, 2}};
    const std::uint8_t* q = s.quats.rgba.data();
    FirstBad bad;
    for_each_splat(c.size(), [&](std::size_t i) {
        const std::uint8_t* p = q + 4 * i;
        float* out = &c.rotations[4 * i];
        if (p[3] < 252) {
            bad.note(i);
            out[0] = 1.0f, out[1] = out[2] = out[3] = 0.0f;
            return;
        }
        const int largest = p[3] - 252;
        float sum = 0.0f;
        for (int k = 0; k < 3; ++k) {
            const float v = (float(p[k]) / 255.0f - 0.5f) * 1.41421356237309505f;
            out[kKept[largest][k]] = v;
            sum += v * v;
        }
        out[largest] = std::sqrt(std::max(0.0f, 1.0f - sum));
    });
    if (bad.any())
        throw files.error(s.quats.name, "the quats image's alpha at " + pixel_of(s.quats, bad.index) + " is " +
                                            std::to_string(q[4 * bad.index + 3]) + "; it must be 252 to 255 (the largest component)");
    release(s.quats);
}

// Throws where a pixel of the first n of `im` holds, in one of its first `channels` channels, an index at or beyond
// the `valid` entries of the codebook `book`.
void check_codebook_indices(const SogFiles& files, const Image& im, std::size_t n, int channels, int valid,
                            const char* book) {
    if (valid >= 256) return;
    const std::uint8_t* p = im.rgba.data();
    FirstBad bad;
    for_each_splat(n, [&](std::size_t i) {
        for (int ch = 0; ch < channels; ++ch)
            if (p[4 * i + std::size_t(ch)] >= valid) bad.note(i);
    });
    if (bad.any()) {
        int value = 0;
        for (int ch = 0; ch < channels; ++ch) value = std::max<int>(value, p[4 * bad.index + std::size_t(ch)]);
        throw files.error(im.name, "index " + std::to_string(value) + " at " + pixel_of(im, bad.index) + " is outside the " +
                                       std::to_string(valid) + "-entry " + book + " codebook of meta.json");
    }
}

// Scales through their codebook [spec 3.3]: scale = exp(log scale).
void decode_scales(SogFiles& files, SogScene& s, GaussianCloud& c) {
    const SogMeta& m = s.meta;
    decode_image(files, s.scales);
    check_codebook_indices(files, s.scales, c.size(), 3, m.scale_valid, "scales");
    const std::uint8_t* p = s.scales.rgba.data();
    float exp_lut[3][256];
    for (int a = 0; a < 3; ++a)
        for (int b = 0; b < 256; ++b) exp_lut[a][b] = std::exp(m.scale_lut[a][b]);
    for_each_splat(c.size(), [&](std::size_t i) {
        for (int a = 0; a < 3; ++a) c.scales[3 * i + std::size_t(a)] = exp_lut[a][p[4 * i + std::size_t(a)]];
    });
    release(s.scales);
}

// The SH DC colour through its codebook and the opacity [spec 3.4].
void decode_colours(SogFiles& files, SogScene& s, GaussianCloud& c) {
    const SogMeta& m = s.meta;
    const std::size_t K = std::size_t(c.coeffs_per_channel());
    decode_image(files, s.sh0);
    check_codebook_indices(files, s.sh0, c.size(), 3, m.dc_valid, "sh0");
    const std::uint8_t* p = s.sh0.rgba.data();
    for_each_splat(c.size(), [&](std::size_t i) {
        float* sh = &c.sh[i * K * 3];
        for (int ch = 0; ch < 3; ++ch) sh[ch] = m.dc_lut[ch][p[4 * i + std::size_t(ch)]];
        c.opacities[i] = m.opacity_lut[p[4 * i + 3]];
    });
    release(s.sh0);
}

// Higher SH bands through the palette [spec 3.5].
void decode_sh_palette(SogFiles& files, SogScene& s, GaussianCloud& c) {
    const SogMeta& m = s.meta;
    const std::size_t K = std::size_t(c.coeffs_per_channel());
    decode_image(files, s.labels);
    decode_image(files, s.centroids);
    const int coeffs = kShCoeffsForBands[m.bands];
    const std::uint8_t* labels = s.labels.rgba.data();
    const std::uint8_t* cent = s.centroids.rgba.data();
    const std::size_t cw = s.centroids.width;
    const std::uint64_t palette = m.palette_count;
    FirstBad bad_label, bad_index;
    for_each_splat(c.size(), [&](std::size_t i) {
        const std::uint64_t label = std::uint64_t(labels[4 * i]) | std::uint64_t(labels[4 * i + 1]) << 8;
        if (label >= palette) {
            bad_label.note(i);
            return;
        }
        const std::size_t u = std::size_t(label % kPaletteEntriesPerRow) * std::size_t(coeffs);
        const std::size_t v = std::size_t(label / kPaletteEntriesPerRow);
        const std::uint8_t* entry = cent + (v * cw + u) * 4;
        float* sh = &c.sh[i * K * 3];
        for (int k = 0; k < coeffs; ++k)
            for (int ch = 0; ch < 3; ++ch) {
                const std::uint8_t b = entry[4 * k + ch];
                if (b >= m.shn_valid) bad_index.note(i);
                sh[3 * (1 + std::size_t(k)) + std::size_t(ch)] = m.shn_lut[b];
            }
    });
    if (bad_label.any()) {
        const std::size_t i = bad_label.index;
        throw files.error(s.labels.name, "palette index " + std::to_string(labels[4 * i] | labels[4 * i + 1] << 8) + " at " +
                                             pixel_of(s.labels, i) + " is not below the palette's " +
                                             std::to_string(palette) + " entries");
    }
    if (bad_index.any())
        throw files.error(s.centroids.name, "the palette entry of " + pixel_of(s.labels, bad_index.index) +
                                                " holds an index outside the " + std::to_string(m.shn_valid) +
                                                "-entry shN codebook of meta.json");
    release(s.labels);
    release(s.centroids);
}

// Decodes the images into a cloud (activations applied: linear scales and opacities; rotations not yet normalised).
GaussianCloud decode_scene(SogFiles& files, SogScene& s) {
    const SogMeta& m = s.meta;
    GaussianCloud c;
    c.resize(std::size_t(m.count), m.has_shn ? m.bands : 0);
    decode_positions(files, s, c);
    decode_rotations(files, s, c);
    decode_scales(files, s, c);
    decode_colours(files, s, c);
    if (m.has_shn) decode_sh_palette(files, s, c);
    return c;
}

GaussianCloud read_scene(SogFiles& files, const ReadOptions& options, LoadReport* report) {
    SogScene scene = open_scene(files);
    GaussianCloud c = decode_scene(files, scene);
    finalize_cloud(c, options, report);
    if (report && scene.meta.antialias)
        report->warnings.push_back("meta.json says the scene was trained with anti-aliasing ('antialias': true), which this "
                                   "renderer does not model: it may look slightly different than in PlayCanvas");
    if (report && scene.meta.version == 1)
        report->warnings.push_back("a version 1 (legacy) SOG: PlayCanvas's tools write version 2 now");
    return c;
}

}  // namespace

bool is_sog_file(const std::string& path, const std::uint8_t* head, std::size_t head_size) {
    if (is_zip(head, head_size)) return true;
    const std::string e = lower_extension(path);
    if (e == ".sog") return true;
    std::string lower = path;
    for (char& ch : lower) ch = char(std::tolower(static_cast<unsigned char>(ch)));
    return lower.size() >= 9 && lower.compare(lower.size() - 9, 9, "meta.json") == 0;
}

// A zip is a .sog bundle; an unbundled SOG is its meta.json, known by name (as a .sog that lacks the zip magic,
// which the reader then refuses with its own message).
Evidence detect_sog(const std::uint8_t* d, std::size_t size, const std::string& name, bool) {
    if (is_zip(d, size)) return Evidence::Signature;
    return is_sog_file(name, nullptr, 0) ? Evidence::Name : Evidence::None;
}

SplatFileSummary probe_sog(const FileBytes& f) {
    const std::unique_ptr<SogFiles> files = open_sog_files(f);
    const SogMeta m = read_sog_meta(*files);
    SplatFileSummary s{SplatFormat::Sog, m.count, 0};
    if (!m.has_shn) return s;
    if (m.version == 2) {
        s.sh_degree = m.bands;
    } else if (m.v1_shn_shape_coeffs >= 0) {
        const std::int64_t k = m.v1_shn_shape_coeffs;  // per channel (15) or all three (45)
        s.sh_degree = (k == 45 || k == 15) ? 3 : (k == 24 || k == 8) ? 2 : (k == 9 || k == 3) ? 1 : 0;
    } else {
        const Image centroids = open_centroids_image(*files, m);
        s.sh_degree = centroids.width == 192 ? 1 : centroids.width == 512 ? 2 : centroids.width == 960 ? 3 : 0;
    }
    return s;
}

GaussianCloud read_sog(const FileBytes& f, const ReadOptions& options, LoadReport* report) {
    return read_scene(*open_sog_files(f), options, report);
}
}  // namespace io

GaussianCloud read_sog(const std::string& path, const ReadOptions& options, LoadReport* report) {
    return io::read_sog(io::FileBytes(path), options, report);
}

GaussianCloud read_sog_bundle(const std::uint8_t* data, std::size_t size, const std::string& name, const ReadOptions& options,
                              LoadReport* report) {
    return io::read_sog(io::FileBytes(data, size, name), options, report);
}

}  // namespace raysplats
