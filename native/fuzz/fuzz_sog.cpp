// libFuzzer target: PlayCanvas SOG bundles (zip of WebP images and meta.json) (the contract: fuzz_contract.h).
#include "fuzz_contract.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    using namespace raysplats;
    fuzz::check_reader(data, size, "fuzz.sog", SplatFormat::Sog,
                       [](const std::uint8_t* d, std::size_t n, const std::string& name, LoadReport* report) {
                           return read_sog_bundle(d, n, name, {}, report);
                       });
    return 0;
}
