#include "io/inspect.hpp"

#include <fstream>

#include "core/errors.hpp"
#include "core/hash.hpp"

namespace specbake {

using nlohmann::json;

fs::path resolve_bundle(const fs::path& path) {
  std::error_code ec;
  if (fs::exists(path / "manifest.json", ec)) return path;
  if (fs::exists(path / "latest" / "manifest.json", ec)) {
    fs::path bundle = fs::canonical(path / "latest", ec);
    return ec ? path / "latest" : bundle;
  }
  throw InputError({path, 0, 0, ""}, "expected a bundle folder (with manifest.json) or a job folder (with a "
                                     "`latest` bundle)");
}

Inspection inspect_bundle(const fs::path& path) {
  Inspection in;
  in.bundle = resolve_bundle(path);
  std::ifstream f(in.bundle / "manifest.json");
  if (!f) throw IoError("cannot read " + (in.bundle / "manifest.json").string());
  try {
    in.manifest = json::parse(f);
  } catch (const json::exception& e) {
    throw InputError({in.bundle / "manifest.json", 0, 0, ""}, std::string("expected a JSON manifest: ") + e.what());
  }
  if (!in.manifest.is_object() || !in.manifest.contains("files") || !in.manifest["files"].is_array())
    throw InputError({in.bundle / "manifest.json", 0, 0, "files"}, "expected a bundle manifest with a 'files' list");
  for (const auto& e : in.manifest["files"]) {
    InspectedFile file;
    file.path = e.value("path", "");
    file.bytes = e.value("bytes", std::uint64_t{0});
    file.dtype = e.contains("dtype") && e["dtype"].is_string() ? e["dtype"].get<std::string>() : "";
    if (e.contains("shape")) file.shape = e["shape"];
    try {
      file.status = sha256_file(in.bundle / file.path) == e.value("sha256", "") ? "ok" : "sha256-mismatch";
    } catch (const IoError&) {
      file.status = "missing";
    }
    in.bad += file.status != "ok";
    in.files.push_back(std::move(file));
  }
  return in;
}

json Inspection::to_json() const {
  json files_json = json::array();
  for (const auto& f : files) {
    json j = {{"path", f.path}, {"status", f.status}, {"bytes", f.bytes}};
    if (!f.dtype.empty()) j["dtype"] = f.dtype;
    if (!f.shape.is_null()) j["shape"] = f.shape;
    files_json.push_back(j);
  }
  return {{"bundle", bundle.string()},
          {"job", manifest.value("job", json::object())},
          {"tool", manifest.value("tool", json::object())},
          {"created_utc", manifest.value("created_utc", "")},
          {"device", manifest.value("device", json::object())},
          {"accuracy", manifest.value("accuracy", json::array())},
          {"warnings", manifest.value("warnings", json::array())},
          {"files", files_json},
          {"files_bad", bad},
          {"ok", bad == 0}};
}

}  // namespace specbake
