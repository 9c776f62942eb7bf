// `raysplats render`: renders a splat file, optional OBJ meshes, and a camera, lights and world given on the
// command line or in a small JSON scene file, to PNG (8-bit sRGB) and/or PFM (linear float).
//
//   raysplats render SPLATS [MESH.obj ...] [options]
//   raysplats render --scene scene.json [options]          (command-line options override the file)
//
// The "render" and "camera" objects use the core's names, the same the Blender add-on passes
// (raysplats/render/render_settings.h, raysplats/render/camera_parameters.h); an unknown name is an error.
// Angles are radians, matrices row-major 4x4 like Blender's matrix_world. Every key is optional:
//   {"splats": {"file": "scene.ply", "matrix": [16 numbers]},
//    "meshes": [{"file": "floor.obj", "matrix": [...], "material": "name"}],
//    "materials": {"name": {"base_color": [r,g,b], "metallic": 0, "roughness": 0.5, "specular": 0.5,
//                           "transmission": 0, "ior": 1.45, "emission": [r,g,b], "emission_strength": 1,
//                           "alpha": 1}},
//    "camera": {"type": "PERSP|ORTHO|EQUIRECTANGULAR|FISHEYE_EQUIDISTANT|FISHEYE_EQUISOLID",
//               "position": [x,y,z], "target": [x,y,z], "up": [0,0,1]  (or "matrix": [...]),
//               "lens": 50, "sensor_width": 36, "sensor_height": 24, "sensor_fit": "AUTO|HORIZONTAL|VERTICAL",
//               "shift_x": 0, "shift_y": 0, "clip_start": 0.1, "clip_end": 1000, "ortho_scale": 6,
//               "fisheye_fov": 3.14159, "fisheye_lens": 10.5, "longitude_min": -3.14159, "longitude_max": 3.14159,
//               "latitude_min": -1.5708, "latitude_max": 1.5708,
//               "use_dof": false, "focus_distance": 10, "aperture_fstop": 2.8, "aperture_blades": 0,
//               "aperture_rotation": 0, "aperture_ratio": 1},   (depth of field: Blender's Camera.dof)
//    "lights": [{"type": "point|sun|spot|area|disk", "color": [1,1,1], "power": 1000,
//                "position": [...], "target": [...]  (or "matrix"), "size": [x,y], "spot_size": 0.785,
//                "spot_blend": 0.15, "angle": 0}],
//    "world": {"color": [r,g,b], "strength": 1, "mist_start": 0, "mist_depth": 100, "mist_falloff": 1},
//    "render": {"width": 1280, "height": 720, "samples": 16, "max_bounces": 4, "seed": 0,
//               "gaussian_mode": "FLAT|VOLUMETRIC", "compositing": "SORTED|STOCHASTIC",
//               "blend_space": "DISPLAY|LINEAR",
//               "transmittance_threshold": 0.001, "meshes_shadow_gaussians": false,
//               "gaussian_shading": "BAKED|LIT|BAKED_SHADOWED",
//               "transparent_background": false, ...every render setting}}
#include <algorithm>
#include <cctype>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "raysplats/errors.h"
#include "raysplats/render/camera_parameters.h"
#include "raysplats/render/renderer.h"
#include "raysplats/splat_io.h"

namespace raysplats {
namespace {

using json = nlohmann::json;
using Clock = std::chrono::steady_clock;

double since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

// An OBJ mesh un-indexed into one vertex per distinct (v, vt, vn) corner; polygons are fan-triangulated.
struct LoadedMesh {
    std::vector<float> vertices, normals, uvs;
    std::vector<std::uint32_t> indices, face_materials;
    std::vector<std::string> material_names;  // per usemtl group, indexed by face_materials
};

LoadedMesh read_obj(const std::string& path) {
    std::ifstream in(std::filesystem::u8path(path));
    if (!in) throw FileFormatError(path, "cannot open");
    std::vector<float> v, vt, vn;
    LoadedMesh m;
    std::map<std::tuple<long, long, long>, std::uint32_t> corners;
    std::uint32_t current_material = 0;
    m.material_names.push_back("");
    bool any_uv = false, any_normal = false;
    std::string line;
    std::size_t line_no = 0;
    auto fail = [&](const std::string& what) { throw FileFormatError(path, "line " + std::to_string(line_no) + ": " + what); };
    while (std::getline(in, line)) {
        ++line_no;
        std::istringstream ls(line);
        std::string tag;
        ls >> tag;
        if (tag == "v" || tag == "vn") {
            float x, y, z;
            if (!(ls >> x >> y >> z)) fail("expected three numbers");
            auto& dst = tag == "v" ? v : vn;
            dst.insert(dst.end(), {x, y, z});
        } else if (tag == "vt") {
            float x, y = 0;
            if (!(ls >> x)) fail("expected a texture coordinate");
            ls >> y;
            vt.insert(vt.end(), {x, y});
        } else if (tag == "usemtl") {
            std::string name;
            ls >> name;
            current_material = std::uint32_t(m.material_names.size());
            for (std::size_t i = 0; i < m.material_names.size(); ++i)
                if (m.material_names[i] == name) current_material = std::uint32_t(i);
            if (current_material == m.material_names.size()) m.material_names.push_back(name);
        } else if (tag == "f") {
            std::vector<std::uint32_t> poly;
            std::string corner;
            while (ls >> corner) {
                long idx[3] = {0, 0, 0};
                std::size_t start = 0;
                for (int k = 0; k < 3 && start <= corner.size(); ++k) {
                    const std::size_t slash = corner.find('/', start);
                    const std::string part = corner.substr(start, slash == std::string::npos ? std::string::npos : slash - start);
                    if (!part.empty()) idx[k] = std::stol(part);
                    if (slash == std::string::npos) break;
                    start = slash + 1;
                }
                const long counts[3] = {long(v.size() / 3), long(vt.size() / 2), long(vn.size() / 3)};
                for (int k = 0; k < 3; ++k) {
                    if (idx[k] < 0) idx[k] += counts[k] + 1;  // negative indices count from the end
                    if (idx[k] > counts[k] || (k == 0 && idx[k] <= 0)) fail("index out of range in '" + corner + "'");
                }
                const auto key = std::make_tuple(idx[0], idx[1], idx[2]);
                auto it = corners.find(key);
                if (it == corners.end()) {
                    const std::uint32_t id = std::uint32_t(m.vertices.size() / 3);
                    m.vertices.insert(m.vertices.end(), &v[3 * (idx[0] - 1)], &v[3 * (idx[0] - 1)] + 3);
                    if (idx[1] > 0) any_uv = true;
                    if (idx[2] > 0) any_normal = true;
                    const float* t = idx[1] > 0 ? &vt[2 * (idx[1] - 1)] : nullptr;
                    const float* n = idx[2] > 0 ? &vn[3 * (idx[2] - 1)] : nullptr;
                    m.uvs.insert(m.uvs.end(), {t ? t[0] : 0.0f, t ? t[1] : 0.0f});
                    m.normals.insert(m.normals.end(), {n ? n[0] : 0.0f, n ? n[1] : 0.0f, n ? n[2] : 0.0f});
                    it = corners.emplace(key, id).first;
                }
                poly.push_back(it->second);
            }
            if (poly.size() < 3) fail("a face needs at least three corners");
            for (std::size_t k = 1; k + 1 < poly.size(); ++k) {
                m.indices.insert(m.indices.end(), {poly[0], poly[k], poly[k + 1]});
                m.face_materials.push_back(current_material);
            }
        }
    }
    if (m.indices.empty()) throw FileFormatError(path, "no faces");
    if (!any_uv) m.uvs.clear();
    if (!any_normal) m.normals.clear();
    m.vertices.push_back(0.0f);  // padding: Embree shares the array (see MeshDesc::vertices_padded)
    return m;
}

std::array<float, 3> vec3(const json& j, const char* what) {
    if (!j.is_array() || j.size() != 3) throw InvalidArgument(std::string(what) + ": expected [x, y, z]");
    return {j[0].get<float>(), j[1].get<float>(), j[2].get<float>()};
}

Matrix4 matrix(const json& j, const char* what) {
    if (!j.is_array() || j.size() != 16) throw InvalidArgument(std::string(what) + ": expected 16 numbers (row-major 4x4)");
    Matrix4 m;
    for (int i = 0; i < 16; ++i) m.m[i] = j[i].get<float>();
    return m;
}

// Placement from "matrix", or "position" + "target" (+ "up"), or "position" + "direction".
Matrix4 placement(const json& j, const char* what, std::array<float, 3> default_up) {
    if (j.contains("matrix")) return matrix(j["matrix"], what);
    const auto up = j.contains("up") ? vec3(j["up"], what) : default_up;
    const auto pos = j.contains("position") ? vec3(j["position"], what) : std::array<float, 3>{0, 0, 0};
    if (j.contains("target")) return Matrix4::look_at(pos, vec3(j["target"], what), up);
    if (j.contains("direction")) {
        const auto d = vec3(j["direction"], what);
        std::array<float, 3> up2 = up;
        if (std::abs(d[0] * up[0] + d[1] * up[1] + d[2] * up[2]) > 0.999f * std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]))
            up2 = {0, 1, 0};
        return Matrix4::look_at(pos, {pos[0] + d[0], pos[1] + d[1], pos[2] + d[2]}, up2);
    }
    return Matrix4::translation(pos[0], pos[1], pos[2]);
}

// A JSON value as a ParameterValue of its own type; the table checks it against the parameter's.
ParameterValue parameter_value_from(const json& j, const std::string& name, const char* what) {
    if (j.is_boolean()) return j.get<bool>();
    if (j.is_number_integer()) return j.get<std::int64_t>();
    if (j.is_number()) return j.get<double>();
    if (j.is_string()) return j.get<std::string>();
    if (j.is_array()) return matrix(j, name.c_str());
    throw InvalidArgument(std::string(what) + " '" + name + "' cannot be " + j.type_name());
}

// Sets `target` from every key of `object` but those in `skip`, through `table`: unknown names are errors.
template <typename Target>
void apply_json(const json& object, const ParameterTable<Target>& table, Target& target,
                std::initializer_list<const char*> skip = {}) {
    if (!object.is_object()) throw InvalidArgument(std::string(table.what()) + "s: expected a JSON object");
    for (const auto& [key, value] : object.items()) {
        if (std::find_if(skip.begin(), skip.end(), [&](const char* s) { return key == s; }) != skip.end()) continue;
        table.find(key);  // an unknown name is the error, whatever its value
        table.set(target, key, parameter_value_from(value, key, table.what()));
    }
}

Camera parse_camera(const json& j) {
    Camera c;
    // position / target / up / direction place the camera as a convenience of this tool; "matrix" is the core's.
    apply_json(j, camera_parameters(), c, {"position", "target", "up", "direction"});
    if (!j.contains("matrix")) c.camera_to_world = placement(j, "camera", {0, 0, 1});
    return c;
}

Light parse_light(const json& j) {
    Light l;
    const std::string type = j.value("type", "point");
    if (type == "point") l.type = LightType::Point;
    else if (type == "sun") l.type = LightType::Sun;
    else if (type == "spot") l.type = LightType::Spot;
    else if (type == "area") l.type = LightType::AreaRectangle;
    else if (type == "disk") l.type = LightType::AreaDisk;
    else throw InvalidArgument("light: unknown type '" + type + "'");
    if (j.contains("color")) l.color = vec3(j["color"], "light color");
    l.power = j.value("power", l.power);
    l.light_to_world = placement(j, "light", {0, 0, 1});
    if (j.contains("size")) {
        const json& s = j["size"];
        l.size_x = s.is_array() ? s[0].get<float>() : s.get<float>();
        l.size_y = s.is_array() ? s[1].get<float>() : l.size_x;
    }
    l.spot_size = j.value("spot_size", l.spot_size);
    l.spot_blend = j.value("spot_blend", l.spot_blend);
    l.sun_angle = j.value("angle", l.sun_angle);
    return l;
}

Material parse_material(const json& j) {
    Material m;
    if (j.contains("base_color")) m.base_color = vec3(j["base_color"], "base_color");
    m.metallic = j.value("metallic", m.metallic);
    m.roughness = j.value("roughness", m.roughness);
    m.specular = j.value("specular", m.specular);
    m.transmission = j.value("transmission", m.transmission);
    m.ior = j.value("ior", m.ior);
    if (j.contains("emission")) m.emission_color = vec3(j["emission"], "emission");
    m.emission_strength = j.value("emission_strength", m.emission_strength);
    m.alpha = j.value("alpha", m.alpha);
    return m;
}

// "x,y,z" -> json array
json csv(const std::string& s) {
    json a = json::array();
    std::stringstream ss(s);
    std::string item;
    while (std::getline(ss, item, ',')) a.push_back(std::stof(item));
    return a;
}

// "--max-bounces" -> "max_bounces"; empty when `option` is not a render setting's option.
std::string render_setting_of_option(const std::string& option) {
    if (option.rfind("--", 0) != 0) return "";
    std::string name = option.substr(2);
    std::replace(name.begin(), name.end(), '-', '_');
    for (const auto& p : render_setting_parameters().parameters())
        if (name == p.name) return name;
    return "";
}

// A name typed on the command line, matched to the setting's choices without regard to case ("stochastic" is
// STOCHASTIC); a name that matches none is passed on as typed, so that the core's error lists the known ones.
std::string choice_named(const std::string& setting, const std::string& typed) {
    auto lower = [](std::string s) {
        for (char& c : s) c = char(std::tolower(static_cast<unsigned char>(c)));
        return s;
    };
    for (const std::string& choice : render_setting_parameters().find(setting).choices)
        if (lower(choice) == lower(typed)) return choice;
    return typed;
}

void usage() {
    std::string settings;
    for (const auto& p : render_setting_parameters().parameters()) {
        std::string option = p.name;
        std::replace(option.begin(), option.end(), '_', '-');
        std::string line = "  --" + option;
        if (p.type == ParameterType::Bool) {
            line = "  --[no-]" + option;
        } else if (p.type == ParameterType::Name) {
            line += " ";
            for (std::size_t i = 0; i < p.choices.size(); ++i) line += (i ? "|" : "") + p.choices[i];
        } else {
            line += p.type == ParameterType::Integer ? " N" : " X";
        }
        line.resize(std::max<std::size_t>(line.size() + 1, 42), ' ');
        settings += line + p.description + "\n";
    }
    std::string models;
    for (const auto& m : camera_model_names().values) models += (models.empty() ? "" : "|") + std::string(m.name);
    std::fprintf(stderr,
                 "usage: raysplats render [SPLATS] [MESH.obj ...] [options]\n"
                 "  --scene FILE.json        scene description (see native/tools/render_command.cpp)\n"
                 "  -o, --output FILE        .png (8-bit sRGB) or .pfm (linear); default render.png\n"
                 "  --pfm FILE               also write the linear image as PFM\n"
                 "render settings (the JSON \"render\" object's names):\n%s"
                 "  --camera-pos x,y,z --camera-target x,y,z --camera-up x,y,z --lens MM\n"
                 "  --camera TYPE            %s\n"
                 "  --sun dx,dy,dz,strength  (direction the light travels)   --point x,y,z,watts\n"
                 "  --world r,g,b,strength\n",
                 settings.c_str(), models.c_str());
}

}  // namespace

int render_command(int argc, char** argv) {
    // argv[0] is "render".
    json scene_json = json::object();
    json cli_render = json::object(), cli_camera = json::object();
    std::vector<json> cli_lights;
    std::vector<std::string> positional;
    std::string output = "render.png", pfm;
    try {
        for (int i = 1; i < argc; ++i) {
            const std::string a = argv[i];
            auto next = [&]() -> std::string {
                if (i + 1 >= argc) throw InvalidArgument("option " + a + " needs a value");
                return argv[++i];
            };
            if (a == "--scene") {
                const std::string path = next();
                std::ifstream in(std::filesystem::u8path(path));
                if (!in) throw FileFormatError(path, "cannot open");
                try {
                    scene_json = json::parse(in);
                } catch (const json::exception& e) {
                    throw FileFormatError(path, e.what());
                }
            } else if (a == "-o" || a == "--output") output = next();
            else if (a == "--pfm") pfm = next();
            else if (const std::string name = render_setting_of_option(a); !name.empty()) {
                switch (render_setting_parameters().find(name).type) {
                    case ParameterType::Bool: cli_render[name] = true; break;
                    case ParameterType::Integer: cli_render[name] = std::stoll(next()); break;
                    case ParameterType::Real: cli_render[name] = std::stod(next()); break;
                    case ParameterType::Name: cli_render[name] = choice_named(name, next()); break;
                    default: cli_render[name] = next(); break;
                }
            } else if (const std::string negated = a.rfind("--no-", 0) == 0 ? render_setting_of_option("--" + a.substr(5)) : "";
                       !negated.empty() && render_setting_parameters().find(negated).type == ParameterType::Bool) {
                cli_render[negated] = false;
            }
            else if (a == "--camera") cli_camera["type"] = next();
            else if (a == "--camera-pos") cli_camera["position"] = csv(next());
            else if (a == "--camera-target") cli_camera["target"] = csv(next());
            else if (a == "--camera-up") cli_camera["up"] = csv(next());
            else if (a == "--lens") cli_camera["lens"] = std::stof(next());
            else if (a == "--sun") {
                const json v = csv(next());
                if (v.size() != 4) throw InvalidArgument("--sun wants dx,dy,dz,strength");
                cli_lights.push_back({{"type", "sun"}, {"direction", {v[0], v[1], v[2]}}, {"power", v[3]}});
            } else if (a == "--point") {
                const json v = csv(next());
                if (v.size() != 4) throw InvalidArgument("--point wants x,y,z,watts");
                cli_lights.push_back({{"type", "point"}, {"position", {v[0], v[1], v[2]}}, {"power", v[3]}});
            } else if (a == "--world") {
                const json v = csv(next());
                if (v.size() != 4) throw InvalidArgument("--world wants r,g,b,strength");
                scene_json["world"] = {{"color", {v[0], v[1], v[2]}}, {"strength", v[3]}};
            } else if (a == "-h" || a == "--help") {
                usage();
                return 0;
            } else if (!a.empty() && a[0] == '-') {
                throw InvalidArgument("unknown option " + a);
            } else {
                positional.push_back(a);
            }
        }
        // Command line over file.
        for (auto& [k, v] : cli_render.items()) scene_json["render"][k] = v;
        for (auto& [k, v] : cli_camera.items()) scene_json["camera"][k] = v;
        for (auto& l : cli_lights) scene_json["lights"].push_back(l);
        for (const std::string& p : positional) {
            const std::string ext = p.size() > 4 ? p.substr(p.size() - 4) : "";
            if (ext == ".obj" || ext == ".OBJ") scene_json["meshes"].push_back({{"file", p}});
            else scene_json["splats"]["file"] = p;
        }
        if (!scene_json.contains("splats") && !scene_json.contains("meshes")) {
            usage();
            return 2;
        }

        RenderSettings st;
        st.width = 1280;  // the tool's default image: 720p
        st.height = 720;
        apply_json(scene_json.value("render", json::object()), render_setting_parameters(), st);
        st.validate();

        Scene scene;
        auto t = Clock::now();
        GaussianCloud cloud;
        if (scene_json.contains("splats")) {
            const json& s = scene_json["splats"];
            LoadReport report;
            cloud = read_splat_file(s.at("file").get<std::string>(), {}, &report);
            for (const auto& w : report.warnings) std::fprintf(stderr, "warning: %s\n", w.c_str());
            scene.add_gaussians(cloud, s.contains("matrix") ? matrix(s["matrix"], "splats") : Matrix4{});
            std::printf("load splats   %8.3f s  (%zu splats, SH degree %d)\n", since(t), cloud.size(), cloud.sh_degree);
        }
        std::map<std::string, std::uint32_t> material_ids;
        scene.add_material(Material{});  // 0: default
        if (scene_json.contains("materials"))
            for (auto& [name, mj] : scene_json["materials"].items()) material_ids[name] = scene.add_material(parse_material(mj));
        t = Clock::now();
        std::vector<std::unique_ptr<LoadedMesh>> meshes;  // alive as long as the scene (shared with Embree)
        std::size_t triangles = 0;
        if (scene_json.contains("meshes"))
            for (const json& mj : scene_json["meshes"]) {
                auto mesh = std::make_unique<LoadedMesh>(read_obj(mj.at("file").get<std::string>()));
                // usemtl names map to JSON materials of that name; a mesh-level "material" overrides all faces.
                std::vector<std::uint32_t> remap(mesh->material_names.size(), 0);
                for (std::size_t i = 0; i < remap.size(); ++i) {
                    auto it = material_ids.find(mesh->material_names[i]);
                    if (it != material_ids.end()) remap[i] = it->second;
                }
                if (mj.contains("material")) {
                    const auto it = material_ids.find(mj["material"].get<std::string>());
                    if (it == material_ids.end()) throw InvalidArgument("unknown material " + mj["material"].dump());
                    std::fill(remap.begin(), remap.end(), it->second);
                }
                for (auto& f : mesh->face_materials) f = remap[f];
                MeshDesc d;
                d.vertices = mesh->vertices.data();
                d.vertex_count = (mesh->vertices.size() - 1) / 3;
                d.vertices_padded = true;
                d.indices = mesh->indices.data();
                d.triangle_count = mesh->indices.size() / 3;
                d.normals = mesh->normals.empty() ? nullptr : mesh->normals.data();
                d.uvs = mesh->uvs.empty() ? nullptr : mesh->uvs.data();
                d.face_materials = mesh->face_materials.data();
                if (mj.contains("matrix")) d.object_to_world = matrix(mj["matrix"], "mesh");
                scene.add_mesh(d);
                triangles += d.triangle_count;
                meshes.push_back(std::move(mesh));
            }
        if (!meshes.empty()) std::printf("load meshes   %8.3f s  (%zu meshes, %zu triangles)\n", since(t), meshes.size(), triangles);
        if (scene_json.contains("lights"))
            for (const json& lj : scene_json["lights"]) scene.add_light(parse_light(lj));
        if (scene_json.contains("world")) {
            World w;
            w.color = vec3(scene_json["world"].at("color"), "world color");
            w.strength = scene_json["world"].value("strength", 1.0f);
            w.mist_start = scene_json["world"].value("mist_start", w.mist_start);
            w.mist_depth = scene_json["world"].value("mist_depth", w.mist_depth);
            w.mist_falloff = scene_json["world"].value("mist_falloff", w.mist_falloff);
            scene.set_world(w);
        }
        const Camera camera = parse_camera(scene_json.value("camera", json::object()));

        t = Clock::now();
        const double build = scene.build(st.gaussian_mode);
        std::printf("build BVH     %8.3f s\n", build);
        t = Clock::now();
        int last_percent = -1;
        const Film film = render(scene, camera, st, [&](float f) {
            const int percent = int(f * 100.0f);
            if (percent == last_percent) return;
            last_percent = percent;
            const int bar = percent / 4;
            std::fprintf(stderr, "\r[%.*s%*s] %3d%%", bar, "#########################", 25 - bar, "", percent);
            std::fflush(stderr);
        });
        std::fprintf(stderr, "\n");
        const double rays = double(film.stats.camera_rays);
        std::printf("render        %8.3f s  (%dx%d, %d spp, %.2f Mrays/s, %.1f Gaussian hits per camera ray)\n",
                    film.stats.render_seconds, st.width, st.height, st.samples, rays / film.stats.render_seconds / 1e6,
                    double(film.stats.gaussian_hits) / rays);
        t = Clock::now();
        const std::string ext = output.size() > 4 ? output.substr(output.size() - 4) : "";
        if (ext == ".pfm") film.write_pfm(output);
        else film.write_png(output);
        if (!pfm.empty()) film.write_pfm(pfm);
        std::printf("write         %8.3f s  (%s%s%s)\n", since(t), output.c_str(), pfm.empty() ? "" : ", ", pfm.c_str());
    } catch (const std::exception& e) {
        std::fprintf(stderr, "raysplats render: %s\n", e.what());
        return 1;
    }
    return 0;
}

}  // namespace raysplats
