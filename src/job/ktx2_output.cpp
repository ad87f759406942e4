#include "job/ktx2_output.hpp"

#include <cmath>

#include "core/version.hpp"
#include "io/ktx2.hpp"
#include "job/formats.hpp"

namespace specbake {

TextureFormats parse_texture_formats(const yaml::At& job, nlohmann::json& norm,
                                     const std::vector<std::string>& kind_keys) {
  TextureFormats f;
  const std::set<std::string> chosen = parse_formats(job, {"bin", "exr", "ktx2"}, {"bin", "exr"}, norm);
  f.bin = chosen.count("bin") > 0;
  f.exr = chosen.count("exr") > 0;
  Ktx2Settings& s = f.ktx2;
  s.enabled = chosen.count("ktx2") > 0;
  if (job.has("ktx2")) {
    const yaml::At k = job.child("ktx2");
    if (!s.enabled) k.fail("expected ktx2 settings only with ktx2 in formats");
    k.expect_map("KTX2 settings {format: rgba16f | rgba32f, zstd: true | false}");
    std::vector<std::string> keys = {"format", "zstd"};
    keys.insert(keys.end(), kind_keys.begin(), kind_keys.end());
    k.allow_keys(keys);
    if (k.has("format")) s.half = k.child("format").choice<int>({{"rgba16f", 1}, {"rgba32f", 0}}) == 1;
    if (k.has("zstd")) s.zstd = k.child("zstd").choice<int>({{"true", 1}, {"false", 0}}) == 1;
  }
  if (s.enabled) norm["ktx2"] = {{"format", s.half ? "rgba16f" : "rgba32f"}, {"zstd", s.zstd}};
  return f;
}

void add_ktx2_file(const Ktx2Settings& settings, const Ktx2Texture& t, const JobContext& ctx, BakeResult& r) {
  Ktx2Image img;
  img.width = t.width;
  img.height = t.height;
  img.depth = t.depth;
  img.layers = t.layers;
  img.channels = t.channels;
  img.texels = t.texels;
  Ktx2Options o;
  o.format = settings.half ? Ktx2Format::rgba16f : Ktx2Format::rgba32f;
  o.zstd = settings.zstd;
  o.writer = std::string("specbake ") + kVersion;
  o.metadata = t.metadata;
  o.metadata["specbake.layout"] = t.layout;
  o.metadata["specbake.units"] = t.units;
  if (!ctx.bundle_hash.empty()) o.metadata["specbake.bundle_hash"] = ctx.bundle_hash;
  std::vector<std::int64_t> shape;
  if (t.depth) shape.push_back(t.depth);
  if (t.layers) shape.push_back(t.layers);
  shape.insert(shape.end(), {t.height, t.width, 4});
  const char* fill = t.channels == 2 ? "; blue = 0, alpha = 1" : t.channels == 3 ? "; alpha = 1" : "";
  r.files.push_back({t.file, write_ktx2(img, o), settings.half ? "half" : "float32", shape,
                     std::string("KTX2 ") + (settings.half ? "R16G16B16A16_SFLOAT" : "R32G32B32A32_SFLOAT") +
                         (settings.zstd ? ", Zstandard" : "") + "; " + t.layout + fill,
                     t.units, t.description});
  if (!settings.half) return;
  const HalfPrecision h = measure_half(t.texels);
  // Round to nearest even: |h - x| <= 2^-11 |x| for normal halfs (values >= 2^-14).
  Accuracy a = Accuracy::judged("half:" + t.file, "max relative error of the half values (|x| >= 2^-14)",
                                h.max_rel_error, std::ldexp(1.0, -11), "the float32 data (.bin)", h.to_json());
  if (h.overflow_to_inf > 0) a.passed = false;
  r.accuracy.push_back(a);
  if (!a.passed)
    r.warnings.push_back(t.file + ": half precision cannot hold these values (" + std::to_string(h.overflow_to_inf) +
                         " overflow); use ktx2: {format: rgba32f}");
}

}  // namespace specbake
