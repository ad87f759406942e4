// Writes KTX2 files for an independent reader to check (tests/python/ktx2_validate.py):
//   ktx2_samples OUT_DIR
// For each case OUT_DIR gets <name>.ktx2, <name>.f32 (the source floats, little-endian, as
// handed to the writer) and one entry in OUT_DIR/claims.json: the parameters, the header,
// index and DFD words as specbake's reader sees them, and the key/value pairs.
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <vector>

#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include "io/ktx2.hpp"

namespace {

using specbake::Ktx2Format;

void write(const std::filesystem::path& p, const std::string& bytes) {
  std::ofstream f(p, std::ios::binary);
  f.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  if (!f) throw std::runtime_error("cannot write " + p.string());
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    spdlog::error("usage: ktx2_samples OUT_DIR");
    return 2;
  }
  const std::filesystem::path out = argv[1];
  std::filesystem::create_directories(out);
  struct Case {
    const char* name;
    Ktx2Format format;
    std::uint32_t w, h, d;
    int channels;
    bool zstd;
    std::uint32_t layers = 0;
  };
  const Case cases[] = {
      {"f16_2d", Ktx2Format::rgba16f, 33, 7, 0, 4, false}, {"f16_2d_rgb_zstd", Ktx2Format::rgba16f, 33, 7, 0, 3, true},
      {"f32_2d_rgb", Ktx2Format::rgba32f, 19, 11, 0, 3, false}, {"f32_2d_zstd", Ktx2Format::rgba32f, 19, 11, 0, 4, true},
      {"f16_3d", Ktx2Format::rgba16f, 8, 4, 5, 4, false},   {"f16_3d_zstd", Ktx2Format::rgba16f, 8, 4, 5, 3, true},
      {"f32_3d_rgb", Ktx2Format::rgba32f, 6, 5, 3, 3, false}, {"f32_3d_zstd", Ktx2Format::rgba32f, 6, 5, 3, 4, true},
      {"f32_array_rg", Ktx2Format::rgba32f, 9, 6, 0, 2, false, 5}, {"f16_array_rg_zstd", Ktx2Format::rgba16f, 9, 6, 0, 2, true, 4},
  };
  nlohmann::json claims = nlohmann::json::array();
  try {
    for (const Case& c : cases) {
      const std::size_t n =
          std::size_t{c.w} * c.h * std::max<std::uint32_t>(c.d, 1) * std::max<std::uint32_t>(c.layers, 1) * c.channels;
      std::vector<float> v(n);
      // Smooth values with a wide range (about 1e-6 to 3e4) and both signs.
      for (std::size_t i = 0; i < n; ++i)
        v[i] = static_cast<float>(std::sin(0.37 * i) * std::exp(10.0 * std::cos(0.011 * i) - 3.0 * (i % 5)));
      specbake::Ktx2Options o;
      o.format = c.format;
      o.zstd = c.zstd;
      o.writer = "specbake samples";
      o.metadata = {{"specbake.case", c.name}, {"specbake.layout", "[z][y][x][rgba], row 0 first"}};
      const std::string bytes = specbake::write_ktx2(specbake::Ktx2Image{c.w, c.h, c.d, c.channels, v, c.layers}, o);
      write(out / (std::string(c.name) + ".ktx2"), bytes);
      std::string src(n * 4, '\0');
      std::memcpy(src.data(), v.data(), src.size());
      write(out / (std::string(c.name) + ".f32"), src);

      const specbake::Ktx2File k = specbake::read_ktx2(bytes, c.name);
      nlohmann::json kv = nlohmann::json::object();
      for (const auto& [key, value] : k.kv) kv[key] = value;
      claims.push_back({{"name", c.name},
                        {"channels", c.channels},
                        {"vkFormat", k.vk_format},
                        {"typeSize", k.type_size},
                        {"pixelWidth", k.width},
                        {"pixelHeight", k.height},
                        {"pixelDepth", k.depth},
                        {"layerCount", k.layer_count},
                        {"faceCount", k.face_count},
                        {"levelCount", k.level_count},
                        {"supercompressionScheme", k.supercompression},
                        {"dfdByteOffset", k.dfd_offset},
                        {"dfdByteLength", k.dfd_length},
                        {"kvdByteOffset", k.kvd_offset},
                        {"kvdByteLength", k.kvd_length},
                        {"level", {k.level_offset, k.level_length, k.level_uncompressed_length}},
                        {"dfd", k.dfd},
                        {"kv", kv}});
    }
  } catch (const std::exception& e) {
    spdlog::error("{}", e.what());
    return 1;
  }
  write(out / "claims.json", claims.dump(2));
  spdlog::info("wrote {} KTX2 files to {}", claims.size(), out.string());
  return 0;
}
