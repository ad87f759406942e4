#pragma once
// KTX2 copies of a bundle's textures, for every kind (docs/ktx2.md): the config keys
// `formats: [bin, exr, ktx2]` and `ktx2: {format: rgba16f | rgba32f, zstd: true | false}`, and
// the file with its half-precision record.
#include <cstdint>
#include <map>
#include <span>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/config.hpp"
#include "job/kind.hpp"

namespace specbake {

struct Ktx2Settings {
  bool enabled = false;  // ktx2 in formats
  bool half = true;      // rgba16f (measured half error in the manifest) or rgba32f
  bool zstd = false;     // Zstandard supercompression
};

// What a texture kind's bundle holds: `formats:` any non-empty choice of bin (float32 .bin),
// exr and ktx2 (default [bin, exr]; job/formats.hpp), and the `ktx2:` settings, which are only
// accepted with ktx2 in formats. Fails at the key with what was expected. `norm` gets the
// normalised keys where they differ from the defaults (they enter the bundle hash). `kind_keys`:
// further keys of `ktx2` the kind reads itself (and normalises into norm["ktx2"]).
struct TextureFormats {
  bool bin = true, exr = true;
  Ktx2Settings ktx2;
};
TextureFormats parse_texture_formats(const yaml::At& job, nlohmann::json& norm,
                                     const std::vector<std::string>& kind_keys = {});

// One texture to write as KTX2: a 2D, 3D or 2D array texture of 2, 3 or 4 channels.
struct Ktx2Texture {
  std::string file;         // e.g. "scattering.ktx2"
  std::uint32_t width = 0, height = 0, depth = 0, layers = 0;
  int channels = 3;
  std::span<const float> texels;
  std::string layout;       // what each axis and channel holds (also the specbake.layout key)
  std::string units;
  std::string description;
  std::map<std::string, std::string> metadata;  // further specbake.* keys
};

// Appends the KTX2 file to r.files and, for rgba16f, the accuracy record `half:<file>` (the
// half values' max relative error against the float32 data, judged against 2^-11; overflow
// fails it with a warning naming the file). Its key/value data: KTXwriter (the tool and its
// version), specbake.bundle_hash (ctx.bundle_hash, where there is one), specbake.layout,
// specbake.units and the texture's own keys.
void add_ktx2_file(const Ktx2Settings& settings, const Ktx2Texture& t, const JobContext& ctx, BakeResult& r);

}  // namespace specbake
