// libFuzzer target: the EXR heightfield reader (src/io/heightfield.*).
#include "heightfield_fuzz.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  return fuzz_heightfield(data, size, specbake::HeightfieldFormat::exr, "fuzz.exr");
}
