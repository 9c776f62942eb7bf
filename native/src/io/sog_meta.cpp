#include "io/sog_meta.h"

#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>
#include <vector>

namespace raysplats {
namespace io {
namespace {

using Json = nlohmann::json;

constexpr std::uint64_t kMaxMetaBytes = std::uint64_t(1) << 20;  // a real meta.json: 16 kB (three 256-entry codebooks)
constexpr int kMaxJsonDepth = 64;

// Names in meta.json are relative to it; "..", absolute paths and NULs could reach files outside the scene.
void check_member_name(const SogFiles& files, const std::string& name, const std::string& field) {
    bool bad = name.empty() || name[0] == '/' || name.find('\0') != std::string::npos || name.find('\\') != std::string::npos;
    for (std::size_t start = 0; !bad && start <= name.size();) {
        const std::size_t end = std::min(name.find('/', start), name.size());
        if (name.compare(start, end - start, "..") == 0 && end - start == 2) bad = true;
        start = end + 1;
    }
    if (bad)
        throw files.error(files.meta_name(), "'" + field + "' is '" + name +
                                                 "': not a file name relative to meta.json (no '..', no absolute path)");
}

// The fields of a parsed meta.json, each checked as it is read; errors name the field by its path ("shN.bands").
class MetaReader {
public:
    MetaReader(const SogFiles& files, const Json& root) : files_(files), root_(root) {}

    SogMeta parse() const {
        SogMeta m;
        if (!root_.is_object()) fail("not a JSON object");
        if (root_.contains("version")) {
            const double v = number(root_["version"], "version");
            if (v != 2) fail("version " + root_["version"].dump() + " is not supported (this reader knows 2, and 1 without 'version')");
            m.version = 2;
        } else {
            m.version = 1;  // [st read-sog.ts]: "V1 (legacy) has no `version` field"
        }
        const Json& means = object(root_, "means", "means");
        m.count = splat_count(m.version, means);
        if (root_.contains("antialias") && root_["antialias"].is_boolean()) m.antialias = root_["antialias"].get<bool>();
        numbers(means, "mins", "means.mins", m.means_min, 3);
        numbers(means, "maxs", "means.maxs", m.means_max, 3);
        files(means, "means", m.means_files, 2);
        files(object(root_, "quats", "quats"), "quats", &m.quats_file, 1);

        const Json& scales = object(root_, "scales", "scales");
        const Json& sh0 = object(root_, "sh0", "sh0");
        files(scales, "scales", &m.scales_file, 1);
        files(sh0, "sh0", &m.sh0_file, 1);
        if (m.version == 2)
            codebook_tables(scales, sh0, m);
        else
            v1_range_tables(scales, sh0, m);

        if (root_.contains("shN") && !root_["shN"].is_null()) sh_palette(m);
        return m;
    }

private:
    [[noreturn]] void fail(const std::string& problem) const { throw files_.error(files_.meta_name(), "meta.json: " + problem); }

    const Json& object(const Json& parent, const char* key, const std::string& where) const {
        if (!parent.is_object() || !parent.contains(key)) fail("'" + where + "' is missing");
        const Json& v = parent[key];
        if (!v.is_object()) fail("'" + where + "' is not an object");
        return v;
    }
    double number(const Json& v, const std::string& where) const {
        if (v.is_null()) fail("'" + where + "' is null, not a number (JavaScript writes NaN and Infinity as null)");
        if (!v.is_number()) fail("'" + where + "' is not a number");
        const double d = v.get<double>();
        if (!std::isfinite(d)) fail("'" + where + "' is not finite");
        return d;
    }
    void numbers(const Json& parent, const char* key, const std::string& where, double* out, std::size_t n) const {
        if (!parent.contains(key)) fail("'" + where + "' is missing");
        const Json& a = parent[key];
        if (!a.is_array() || a.size() != n) fail("'" + where + "' is not a list of " + std::to_string(n) + " numbers");
        for (std::size_t k = 0; k < n; ++k) out[k] = number(a[k], where + "[" + std::to_string(k) + "]");
    }
    void files(const Json& parent, const std::string& where, std::string* out, std::size_t n) const {
        if (!parent.contains("files")) fail("'" + where + ".files' is missing");
        const Json& a = parent["files"];
        if (!a.is_array() || a.size() < n) fail("'" + where + ".files' is not a list of " + std::to_string(n) + " file names");
        for (std::size_t k = 0; k < n; ++k) {
            const std::string field = where + ".files[" + std::to_string(k) + "]";
            if (!a[k].is_string()) fail("'" + field + "' is not a file name");
            out[k] = a[k].get<std::string>();
            check_member_name(files_, out[k], field);
        }
    }
    // A v2 codebook: 1..256 finite numbers (a null first entry replaced as the engine does). Returns its size.
    int codebook(const Json& parent, const std::string& where, std::vector<double>& out) const {
        if (!parent.contains("codebook")) fail("'" + where + ".codebook' is missing");
        const Json& a = parent["codebook"];
        if (!a.is_array() || a.empty() || a.size() > 256) fail("'" + where + ".codebook' is not a list of 1 to 256 numbers");
        out.assign(a.size(), 0.0);
        for (std::size_t k = 0; k < a.size(); ++k)
            if (!(k == 0 && a[k].is_null() && a.size() == 256))
                out[k] = number(a[k], where + ".codebook[" + std::to_string(k) + "]");
        // [eng prepareCodebook]: "patch codebooks starting with a null entry".
        if (a[0].is_null()) out[0] = out[1] + (out[1] - out[255]) / 255.0;
        return int(out.size());
    }
    std::uint64_t whole_number(const Json& v, const std::string& where, std::uint64_t max) const {
        const double d = number(v, where);
        if (d < 0 || d != std::floor(d) || d > double(max))
            fail("'" + where + "' is " + v.dump() + ", not a whole number from 0 to " + std::to_string(max));
        return std::uint64_t(d);
    }

    // v2: "count"; v1: means.shape[0].
    std::uint64_t splat_count(int version, const Json& means) const {
        if (version == 2) {
            if (!root_.contains("count")) fail("'count' is missing");
            return whole_number(root_["count"], "count", kMaxSogSplats);
        }
        if (!means.contains("shape") || !means["shape"].is_array() || means["shape"].empty())
            fail("'means.shape' is missing (a version 1 meta.json gives the splat count as means.shape[0])");
        return whole_number(means["shape"][0], "means.shape[0]", kMaxSogSplats);
    }

    // v2 scale and colour tables: the codebooks [spec 3.3, 3.4]; opacity A / 255.
    void codebook_tables(const Json& scales, const Json& sh0, SogMeta& m) const {
        std::vector<double> book;
        m.scale_valid = codebook(scales, "scales", book);
        for (int c = 0; c < 3; ++c)
            for (int b = 0; b < m.scale_valid; ++b) m.scale_lut[c][b] = float(book[std::size_t(b)]);
        m.dc_valid = codebook(sh0, "sh0", book);
        for (int c = 0; c < 3; ++c)
            for (int b = 0; b < m.dc_valid; ++b) m.dc_lut[c][b] = float(book[std::size_t(b)]);
        for (int b = 0; b < 256; ++b) m.opacity_lut[b] = float(b / 255.0);  // [spec 3.4]: A / 255
    }

    // v1 scale and colour tables: lerp(mins, maxs, byte / 255), the opacity's through a sigmoid [st v1; eng].
    void v1_range_tables(const Json& scales, const Json& sh0, SogMeta& m) const {
        double smin[3], smax[3], cmin[4], cmax[4];
        numbers(scales, "mins", "scales.mins", smin, 3);
        numbers(scales, "maxs", "scales.maxs", smax, 3);
        numbers(sh0, "mins", "sh0.mins", cmin, 4);
        numbers(sh0, "maxs", "sh0.maxs", cmax, 4);
        for (int b = 0; b < 256; ++b) {
            const double t = b / 255.0;
            for (int c = 0; c < 3; ++c) {
                m.scale_lut[c][b] = float(smin[c] + (smax[c] - smin[c]) * t);
                m.dc_lut[c][b] = float(cmin[c] + (cmax[c] - cmin[c]) * t);
            }
            m.opacity_lut[b] = float(1.0 / (1.0 + std::exp(-(cmin[3] + (cmax[3] - cmin[3]) * t))));  // logit lerp
        }
    }

    // The higher SH bands' palette, "shN" [spec 3.5]: its two images and (v2) bands, size and codebook, (v1) range.
    void sh_palette(SogMeta& m) const {
        const Json& shn = object(root_, "shN", "shN");
        m.has_shn = true;
        std::string names[2];
        files(shn, "shN", names, 2);
        m.centroids_file = names[0], m.labels_file = names[1];
        if (m.version == 2) {
            if (!shn.contains("bands")) fail("'shN.bands' is missing");
            m.bands = int(whole_number(shn["bands"], "shN.bands", 3));
            if (m.bands < 1) fail("'shN.bands' is 0 (1 to 3 when shN is present)");
            if (!shn.contains("count")) fail("'shN.count' is missing");
            m.palette_count = whole_number(shn["count"], "shN.count", kMaxSogPaletteEntries);
            if (m.palette_count == 0) fail("'shN.count' is 0 (a palette of 1 to 65536 entries)");
            std::vector<double> book;
            m.shn_valid = codebook(shn, "shN", book);
            for (int b = 0; b < m.shn_valid; ++b) m.shn_lut[b] = float(book[std::size_t(b)]);
        } else {
            double lo = 0, hi = 0;
            if (!shn.contains("mins") || !shn.contains("maxs")) fail("'shN.mins' or 'shN.maxs' is missing");
            lo = number(shn["mins"], "shN.mins");
            hi = number(shn["maxs"], "shN.maxs");
            for (int b = 0; b < 256; ++b) m.shn_lut[b] = float(lo + (hi - lo) * (b / 255.0));
            if (shn.contains("shape") && shn["shape"].is_array() && shn["shape"].size() >= 2 && shn["shape"][1].is_number())
                m.v1_shn_shape_coeffs = std::int64_t(whole_number(shn["shape"][1], "shN.shape[1]", 1000));
        }
    }

    const SogFiles& files_;
    const Json& root_;
};

}  // namespace

SogMeta read_sog_meta(SogFiles& files) {
    const Bytes text = files.read(files.meta_name(), kMaxMetaBytes, "meta.json");
    Json root;
    try {
        // The callback bounds the nesting, so that a hostile "[[[[..." costs no more than a real meta.json.
        root = Json::parse(text.begin(), text.end(), [&](int depth, Json::parse_event_t, Json&) {
            if (depth > kMaxJsonDepth)
                throw files.error(files.meta_name(), "meta.json: nested more than " + std::to_string(kMaxJsonDepth) + " levels deep");
            return true;
        });
    } catch (const Json::exception& e) {
        const std::string hint = std::string(reinterpret_cast<const char*>(text.data()), text.size()).find("NaN") != std::string::npos
                                     ? " (JSON has no NaN or Infinity)"
                                     : "";
        throw files.error(files.meta_name(), std::string("meta.json: malformed JSON: ") + e.what() + hint);
    }
    return MetaReader(files, root).parse();
}

}  // namespace io
}  // namespace raysplats
