#include "io/bundle_diff.hpp"

#include <cmath>
#include <cstring>
#include <fstream>
#include <map>
#include <sstream>

#include "core/errors.hpp"
#include "io/exr.hpp"
#include "io/inspect.hpp"
#include "io/ktx2.hpp"

namespace specbake {

using nlohmann::json;

namespace {

json read_manifest(const fs::path& dir) {
  std::ifstream in(dir / "manifest.json");
  if (!in) throw IoError("cannot read " + (dir / "manifest.json").string());
  try {
    return json::parse(in);
  } catch (const json::exception& e) {
    throw InputError({dir / "manifest.json", 0, 0, ""}, std::string("expected a JSON manifest: ") + e.what());
  }
}

std::string read_bytes(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  if (!in) throw IoError("cannot read " + p.string());
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

std::vector<float> as_floats(const std::string& b) {
  std::vector<float> v(b.size() / 4);
  std::memcpy(v.data(), b.data(), v.size() * 4);
  return v;
}

std::vector<std::int64_t> unravel(std::size_t flat, const std::vector<std::int64_t>& shape) {
  std::vector<std::int64_t> idx(shape.size());
  for (std::size_t k = shape.size(); k-- > 0;) {
    idx[k] = static_cast<std::int64_t>(flat % static_cast<std::size_t>(shape[k]));
    flat /= static_cast<std::size_t>(shape[k]);
  }
  return idx;
}

void flatten(const json& j, const std::string& prefix, std::map<std::string, json>& out) {
  if (j.is_object() && !j.empty()) {
    for (auto it = j.begin(); it != j.end(); ++it) flatten(it.value(), prefix.empty() ? it.key() : prefix + "." + it.key(), out);
  } else {
    out[prefix] = j;
  }
}

}  // namespace

BundleDiff diff_bundles(const fs::path& old_path, const fs::path& new_path, double fail_abs, double fail_rel) {
  const fs::path old_dir = resolve_bundle(old_path), new_dir = resolve_bundle(new_path);
  const json a = read_manifest(old_dir), b = read_manifest(new_dir);
  BundleDiff d;
  std::map<std::string, json> fa, fb;
  for (const char* k : {"config", "inputs", "kernels", "parameters", "tool", "device"}) {
    if (a.contains(k)) flatten(a[k], k, fa);
    if (b.contains(k)) flatten(b[k], k, fb);
  }
  d.changed = json::object();
  for (const auto& [k, v] : fa) {
    auto it = fb.find(k);
    if (it == fb.end()) d.changed[k] = {v, nullptr};
    else if (it->second != v) d.changed[k] = {v, it->second};
  }
  for (const auto& [k, v] : fb)
    if (!fa.count(k)) d.changed[k] = {nullptr, v};
  d.accuracy = json::object();
  const auto records = [](const json& m) {
    std::map<std::string, json> out;
    for (const auto& r : m.value("accuracy", json::array()))
      if (r.is_object() && r.contains("name"))
        out[r["name"].get<std::string>()] = {{"value", r.value("value", json())},
                                             {"tolerance", r.value("tolerance", json())},
                                             {"passed", r.value("passed", json())}};
    return out;
  };
  const auto ra = records(a), rb = records(b);
  for (const auto& [name, v] : ra) {
    auto it = rb.find(name);
    if (it == rb.end()) d.accuracy[name] = {{"old", v}, {"new", nullptr}};
    else if (it->second != v) d.accuracy[name] = {{"old", v}, {"new", it->second}};
  }
  for (const auto& [name, v] : rb)
    if (!ra.count(name)) d.accuracy[name] = {{"old", nullptr}, {"new", v}};

  std::map<std::string, json> files_a, files_b;
  for (const auto& f : a.at("files")) files_a[f.at("path")] = f;
  for (const auto& f : b.at("files")) files_b[f.at("path")] = f;
  for (const auto& [path, fa_entry] : files_a) {
    FileDiff fd;
    fd.path = path;
    auto it = files_b.find(path);
    if (it == files_b.end()) {
      fd.status = "removed";
      d.files.push_back(fd);
      continue;
    }
    const json& fb_entry = it->second;
    const bool numeric = fa_entry.value("dtype", "") == "float32" && fb_entry.value("dtype", "") == "float32";
    if (fa_entry.value("shape", json::array()) != fb_entry.value("shape", json::array())) {
      fd.status = "shape-changed";
      d.files.push_back(fd);
      continue;
    }
    // The files themselves are compared, not the sha256 the manifests claim.
    const std::string ba = read_bytes(old_dir / path), bb = read_bytes(new_dir / path);
    fd.numeric = numeric;
    if (ba == bb) {
      fd.status = "same";
      d.files.push_back(fd);
      continue;
    }
    fd.status = "differs";
    const bool exr = fs::path(path).extension() == ".exr", ktx2 = fs::path(path).extension() == ".ktx2";
    if (numeric || exr || ktx2) {
      std::vector<float> va, vb;
      std::vector<std::int64_t> dims;
      if (exr) {  // decoded (half or float) and compared pixel by pixel, [row][column][channel]
        try {
          const auto channels = exr_channels(ba);
          const ExrImage ia = exr_read(ba, channels), ib = exr_read(bb, exr_channels(bb));
          if (ib.channels != ia.channels || ib.width != ia.width || ib.height != ia.height) {
            fd.status = "shape-changed";
            d.files.push_back(fd);
            continue;
          }
          va = ia.pixels;
          vb = ib.pixels;
          dims = {ia.height, ia.width, static_cast<std::int64_t>(channels.size())};
          fd.channels = channels;
        } catch (const InputError& e) {
          throw InputError({path, 0, 0, ""}, std::string("cannot compare ") + path + ": " + e.what());
        }
      } else if (ktx2) {
        // KTX2 files are decoded (half or float, Zstandard or not) and compared texel by texel;
        // their key/value data (the bundle hash among it) is not a value.
        try {
          va = read_ktx2(ba, path).rgba;
          vb = read_ktx2(bb, path).rgba;
        } catch (const InputError& e) {
          throw InputError({path, 0, 0, ""}, std::string("cannot compare ") + path + ": " + e.what());
        }
      } else {
        va = as_floats(ba);
        vb = as_floats(bb);
      }
      if (!exr) {  // indexed by the manifest's shape
        const auto shape = fa_entry.value("shape", std::vector<std::int64_t>{});
        dims = shape.empty() ? std::vector<std::int64_t>{static_cast<std::int64_t>(va.size())} : shape;
      }
      fd.numeric = true;
      if (va.size() != vb.size()) {
        fd.status = "shape-changed";
      } else {
        std::size_t ia = 0, ir = 0;
        for (std::size_t i = 0; i < va.size(); ++i) {
          const double x = va[i], y = vb[i];
          if (std::isnan(x) || std::isnan(y)) {
            if (std::isnan(x) && std::isnan(y)) continue;  // NaN in both: not a change
            ++fd.nan_mismatches;
            ++fd.exceeding;
            continue;
          }
          if (x == y) continue;  // equal values (inf included)
          const double ab = std::fabs(x - y);
          const double den = std::max(std::fabs(x), std::fabs(y));
          const double rel = den > 0.0 ? ab / den : 0.0;
          if (!(ab <= fd.max_abs)) fd.max_abs = ab, ia = i;
          if (!(rel <= fd.max_rel)) fd.max_rel = rel, ir = i;
          if (!(ab <= fail_abs + fail_rel * den)) ++fd.exceeding;
        }
        fd.at_abs = unravel(ia, dims);
        fd.at_rel = unravel(ir, dims);
        if (fd.max_abs == 0.0 && fd.nan_mismatches == 0) fd.status = "same-values";  // bytes differ, values do not
      }
    }
    d.files.push_back(fd);
  }
  for (const auto& [path, entry] : files_b)
    if (!files_a.count(path)) {
      FileDiff fd;
      fd.path = path;
      fd.status = "added";
      d.files.push_back(fd);
    }
  return d;
}

bool diff_passes(const BundleDiff& d) {
  for (const auto& f : d.files) {
    if (f.status == "same" || f.status == "same-values") continue;
    if (f.status != "differs") return false;
    if (f.exceeding > 0) return false;
  }
  return true;
}

}  // namespace specbake
