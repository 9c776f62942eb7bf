// libFuzzer target: glTF KHR_gaussian_splatting primitives (.glb, or .gltf with data: URIs) (the contract: fuzz_contract.h).
#include "fuzz_contract.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    using namespace raysplats;
    fuzz::check_reader(data, size, "fuzz.glb", SplatFormat::Gltf,
                       [](const std::uint8_t* d, std::size_t n, const std::string& name, LoadReport* report) {
                           return read_gltf_splats_from_memory(d, n, name, {}, report);
                       });
    return 0;
}
