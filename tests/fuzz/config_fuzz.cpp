// libFuzzer target: the YAML config loader. Any input must either parse into a valid
// Config or be refused with specbake::Error (InputError/IoError); nothing else may escape,
// crash, hang or leak.
#include <cstddef>
#include <cstdint>
#include <string>

#include "registry/registry.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  try {
    const specbake::Config c = specbake::parse_config(text, "fuzz.yaml");
    (void)c;
  } catch (const specbake::Error&) {
  }
  return 0;
}
