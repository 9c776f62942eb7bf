// Command-line front end of the core: convert and inspect splat files without Blender.
#include <cstdio>
#include <exception>
#include <string>
#include <vector>

#ifdef _WIN32
#ifndef WIN32_LEAN_AND_MEAN
#define WIN32_LEAN_AND_MEAN
#endif
#include <windows.h>
// after windows.h, which it needs
#include <shellapi.h>
#endif

#include "raysplats/splat_io.h"

namespace raysplats {
int render_command(int argc, char** argv);  // render_command.cpp
}

#ifdef _WIN32
namespace {
// Windows hands main() its arguments in the ANSI code page, which cannot hold every file name; the core takes UTF-8
// everywhere, so the arguments are taken again from the UTF-16 command line.
std::vector<std::string> utf8_arguments() {
    std::vector<std::string> out;
    int count = 0;
    wchar_t** wide = CommandLineToArgvW(GetCommandLineW(), &count);
    for (int i = 0; wide && i < count; ++i) {
        const int n = WideCharToMultiByte(CP_UTF8, 0, wide[i], -1, nullptr, 0, nullptr, nullptr);
        std::string s(n > 0 ? std::size_t(n - 1) : 0, '\0');
        if (n > 1) WideCharToMultiByte(CP_UTF8, 0, wide[i], -1, &s[0], n, nullptr, nullptr);
        out.push_back(s);
    }
    if (wide) LocalFree(wide);
    return out;
}
}  // namespace
#endif

int cli_main(int argc, char** argv);

int main(int argc, char** argv) {
#ifdef _WIN32
    std::vector<std::string> arguments = utf8_arguments();
    std::vector<char*> pointers;
    for (std::string& a : arguments) pointers.push_back(&a[0]);
    pointers.push_back(nullptr);
    if (!arguments.empty()) return cli_main(int(arguments.size()), pointers.data());
#endif
    return cli_main(argc, argv);
}

int cli_main(int argc, char** argv) {
    if (argc >= 2 && std::string(argv[1]) == "render") return raysplats::render_command(argc - 1, argv + 1);
    if (argc < 3) {
        // The formats from the core's table: those written, and those only read.
        std::string read_only;
        for (const raysplats::SplatFormatInfo& f : raysplats::splat_formats())
            if (!f.writable)
                for (const char* ending : f.extensions) read_only += (read_only.empty() ? "" : " ") + std::string(ending);
        std::fprintf(stderr,
                     "usage: raysplats info FILE\n"
                     "       raysplats convert IN OUT    (formats from the extensions: %s; %s in only)\n"
                     "       raysplats render SPLATS [MESH.obj ...] [options]   (raysplats render --help)\n",
                     raysplats::splat_endings_text(true, " ").c_str(), read_only.c_str());
        return 2;
    }
    const std::string command = argv[1];
    try {
        raysplats::LoadReport report;
        if (command == "info") {
            const auto cloud = raysplats::read_splat_file(argv[2], {}, &report);
            std::printf("%s: %zu splats, SH degree %d\n", argv[2], cloud.size(), cloud.sh_degree);
        } else if (command == "convert" && argc >= 4) {
            const auto cloud = raysplats::read_splat_file(argv[2], {}, &report);
            raysplats::write_splat_file(argv[3], cloud);
            std::printf("%s -> %s: %zu splats\n", argv[2], argv[3], cloud.size());
        } else {
            std::fprintf(stderr, "raysplats: unknown command '%s'\n", command.c_str());
            return 2;
        }
        for (const auto& w : report.warnings) std::fprintf(stderr, "warning: %s\n", w.c_str());
    } catch (const std::exception& e) {
        std::fprintf(stderr, "raysplats: %s\n", e.what());
        return 1;
    }
    return 0;
}
