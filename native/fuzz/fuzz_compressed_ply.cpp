// libFuzzer target: SuperSplat's compressed PLY (the contract: fuzz_contract.h).
#include "fuzz_contract.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    using namespace raysplats;
    fuzz::check_reader(data, size, "fuzz.compressed.ply", SplatFormat::CompressedPly,
                       [](const std::uint8_t* d, std::size_t n, const std::string& name, LoadReport* report) {
                           return read_compressed_ply_bytes(d, n, name, {}, report);
                       });
    return 0;
}
