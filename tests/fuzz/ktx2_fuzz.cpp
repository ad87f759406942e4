// libFuzzer target: the KTX2 reader. Any input must either read into a Ktx2File whose texel
// array matches its header or be refused with specbake::Error (InputError); nothing else may
// escape, crash, hang or leak.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string_view>

#include "core/errors.hpp"
#include "io/ktx2.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  try {
    const specbake::Ktx2File k = specbake::read_ktx2(std::string_view(reinterpret_cast<const char*>(data), size), "fuzz.ktx2");
    const std::uint64_t texels =
        std::uint64_t{k.width} * k.height * (k.depth ? k.depth : 1) * (k.layer_count ? k.layer_count : 1);
    if (k.rgba.size() != texels * 4) std::abort();
  } catch (const specbake::Error&) {
  }
  return 0;
}
