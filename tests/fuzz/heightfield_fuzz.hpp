#pragma once
// Shared body of the heightfield fuzz targets: any bytes must decode into a finite
// heightfield or be refused with specbake::Error; nothing else may escape, crash, hang or leak.
#include <cstddef>
#include <cstdint>
#include <string>

#include "core/errors.hpp"
#include "io/heightfield.hpp"

inline int fuzz_heightfield(const std::uint8_t* data, std::size_t size, specbake::HeightfieldFormat format,
                            const char* file_name) {
  const std::string bytes(reinterpret_cast<const char*>(data), size);
  specbake::HeightfieldRead how;
  how.file = file_name;
  how.format = format;
  how.dx_um = 0.05;
  how.height_um = 0.5;
  if (format == specbake::HeightfieldFormat::raw) {
    // Raw files carry no size: take it from the byte count (square when it is one), so both
    // the matching and the mismatching cases are reached.
    const std::size_t n = size / 4;
    std::size_t w = 1;
    while ((w + 1) * (w + 1) <= n) ++w;
    how.raw_size = std::make_pair(static_cast<int>(w), static_cast<int>(w));
  }
  try {
    const specbake::Heightfield h = specbake::decode_heightfield(bytes, how);
    (void)h;
  } catch (const specbake::Error&) {
  }
  return 0;
}
