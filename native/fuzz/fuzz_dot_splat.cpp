// libFuzzer target: antimatter15 .splat records (the contract: fuzz_contract.h).
#include "fuzz_contract.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    using namespace raysplats;
    fuzz::check_reader(data, size, "fuzz.splat", SplatFormat::Splat,
                       [](const std::uint8_t* d, std::size_t n, const std::string& name, LoadReport* report) {
                           return io::read_dot_splat(io::FileBytes(d, n, name), {}, report);
                       });
    return 0;
}
