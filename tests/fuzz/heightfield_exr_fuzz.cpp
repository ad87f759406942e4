// libFuzzer target: the EXR heightfield reader (src/io/heightfield.*). Any bytes must
// decode into a finite heightfield or be refused with specbake::Error; nothing else may
// escape, crash, hang or leak.
#include <cstddef>
#include <cstdint>
#include <string>

#include "io/heightfield.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string bytes(reinterpret_cast<const char*>(data), size);
  specbake::HeightfieldRead how;
  how.file = "fuzz.exr";
  how.format = specbake::HeightfieldFormat::exr;
  how.dx_um = 0.05;
  how.height_um = 0.5;
  try {
    const specbake::Heightfield h = specbake::decode_heightfield(bytes, how);
    (void)h;
  } catch (const specbake::Error&) {
  }
  return 0;
}
