// libFuzzer target: the PLY reader (INRIA PLY; a compressed PLY's header hands it over) (the contract: fuzz_contract.h).
#include "fuzz_contract.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    using namespace raysplats;
    fuzz::check_reader(data, size, "fuzz.ply", SplatFormat::Ply,
                       [](const std::uint8_t* d, std::size_t n, const std::string& name, LoadReport* report) {
                           return io::read_ply(io::FileBytes(d, n, name), {}, report);
                       });
    return 0;
}
