// libFuzzer target: the dispatch of read_splat_file on bytes (io::read_splat_bytes, detect_splat_format), under a
// file name the input's first byte picks (the name decides where the content does not: .splat, .gltf, meta.json).
// The contract of fuzz_contract.h, with the probe's format as the one to compare with.
#include "fuzz_contract.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    using namespace raysplats;
    static const char* const kNames[] = {"fuzz.ply", "fuzz.splat", "fuzz.spz", "fuzz.sog", "fuzz.glb", "fuzz.gltf",
                                         "fuzz.compressed.ply", "scene/meta.json", "fuzz.xyz", "fuzz"};
    if (size == 0) return 0;
    const std::string name = kNames[data[0] % (sizeof kNames / sizeof kNames[0])];
    ++data, --size;
    SplatFormat format = SplatFormat::Ply;
    try {
        format = io::detect_splat_format(data, size, name);
    } catch (const FileFormatError& e) {
        if (std::string(e.what()).find("'" + name + "'") == std::string::npos)
            fuzz::finding(std::string("FileFormatError does not name the file: ") + e.what());
    }
    fuzz::check_reader(data, size, name, format,
                       [](const std::uint8_t* d, std::size_t n, const std::string& file, LoadReport* report) {
                           return io::read_splat_bytes(d, n, file, {}, report);
                       });
    return 0;
}
