#include "io/bundle_texture.hpp"

#include <cstdint>
#include <cstring>
#include <fstream>
#include <sstream>

#include "core/errors.hpp"
#include "io/exr.hpp"
#include "io/ktx2.hpp"

namespace specbake {

namespace fs = std::filesystem;

namespace {

std::string read_bytes(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  if (!in) throw IoError("cannot read " + p.string());
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

const char* kExtensions[] = {".bin", ".exr", ".ktx2"};

}  // namespace

bool has_bundle_texture(const fs::path& bundle, const std::string& name) {
  std::error_code ec;
  for (const char* e : kExtensions)
    if (fs::exists(bundle / (name + e), ec)) return true;
  return false;
}

BundleTexture read_bundle_texture(const fs::path& bundle, const std::string& name, int channels, std::size_t texels) {
  const std::size_t count = texels * static_cast<std::size_t>(channels);
  std::error_code ec;
  for (const char* e : kExtensions) {
    const fs::path p = bundle / (name + e);
    if (!fs::exists(p, ec)) continue;
    BundleTexture t;
    t.file = name + e;
    const Location at{p, 0, 0, ""};
    auto expect = [&](std::size_t got, const std::string& what) {
      if (got != count)
        throw InputError(at, t.file + " with " + std::to_string(count) + " values (" + std::to_string(texels) + " texels x " +
                                 std::to_string(channels) + " channels, the manifest's sizes), found " + what);
    };
    const std::string bytes = read_bytes(p);
    if (std::string(e) == ".bin") {
      expect(bytes.size() / 4, std::to_string(bytes.size()) + " bytes");
      t.values.resize(count);
      for (std::size_t i = 0; i < count; ++i) {
        std::uint32_t u = 0;
        for (int k = 0; k < 4; ++k) u |= static_cast<std::uint32_t>(static_cast<unsigned char>(bytes[4 * i + k])) << (8 * k);
        std::memcpy(&t.values[i], &u, 4);
      }
    } else if (std::string(e) == ".exr") {
      std::vector<std::string> names{"R", "G", "B", "A"};
      names.resize(static_cast<std::size_t>(channels));
      ExrImage img = exr_read(bytes, names);
      expect(img.pixels.size(), std::to_string(img.pixels.size()) + " values");
      t.values = std::move(img.pixels);
      t.half = img.half;
    } else {
      const Ktx2File k = read_ktx2(bytes, p.string());
      expect(k.rgba.size() / 4 * static_cast<std::size_t>(channels), std::to_string(k.rgba.size() / 4) + " texels");
      t.values.resize(count);
      for (std::size_t i = 0; i < texels; ++i)
        for (int c = 0; c < channels; ++c) t.values[i * channels + c] = k.rgba[4 * i + c];
      t.half = k.type_size == 2;
    }
    return t;
  }
  throw InputError(Location{bundle, 0, 0, ""}, "a bundle holding " + name + ".bin, " + name + ".exr or " + name +
                                                   ".ktx2 (none is there)");
}

}  // namespace specbake
