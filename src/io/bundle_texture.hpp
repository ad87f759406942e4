#pragma once
// A texture of a published bundle read back from whichever copy the bundle holds (`formats:`
// chooses them): NAME.bin (float32 little-endian, exact), NAME.exr (float32 exact, or half) or
// NAME.ktx2 (rgba32f exact, or rgba16f; alpha and any channel past `channels` dropped). For the
// readers of bundles: `truth --bundle`, the report page's live views, tests.
#include <cstddef>
#include <filesystem>
#include <string>
#include <vector>

namespace specbake {

struct BundleTexture {
  std::vector<float> values;  // [texels][channels], the .bin order (3D textures: depth slices stacked)
  std::string file;           // the copy read, relative to the bundle
  bool half = false;          // that copy holds half-precision values (rounded to 2^-11 relative)
};

// The first of NAME.bin, NAME.exr, NAME.ktx2 that exists in `bundle`; InputError naming the
// bundle when none does or the copy does not hold texels × channels values.
BundleTexture read_bundle_texture(const std::filesystem::path& bundle, const std::string& name, int channels,
                                  std::size_t texels);
// Whether the bundle holds any copy of NAME.
bool has_bundle_texture(const std::filesystem::path& bundle, const std::string& name);

}  // namespace specbake
