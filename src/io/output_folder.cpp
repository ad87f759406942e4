#include "io/output_folder.hpp"

#include <algorithm>
#include <cstdio>
#include <ctime>
#include <fstream>

#include "core/errors.hpp"
#include "core/text.hpp"

namespace specbake {

using nlohmann::json;

namespace {

json read_manifest(const fs::path& bundle) {
  const fs::path p = bundle / "manifest.json";
  std::ifstream in(p);
  if (!in) throw IoError("cannot read " + p.string());
  try {
    json m = json::parse(in);
    if (!m.is_object()) throw InputError({p, 0, 0, ""}, "expected a JSON object (a bundle manifest)");
    return m;
  } catch (const json::exception& e) {
    throw InputError({p, 0, 0, ""}, std::string("expected a JSON manifest: ") + e.what());
  }
}

}  // namespace

std::uint64_t bundle_bytes(const fs::path& bundle, const json& manifest) {
  std::error_code ec;
  std::uint64_t n = fs::file_size(bundle / "manifest.json", ec);
  if (ec) n = 0;
  for (const auto& f : manifest.value("files", json::array()))
    if (f.is_object()) n += f.value("bytes", std::uint64_t{0});
  return n;
}

fs::path previous_bundle(const fs::path& bundle) {
  std::error_code ec;
  fs::path best_path;
  std::string best;
  for (const auto& b : fs::directory_iterator(bundle.parent_path(), ec)) {
    const std::string n = b.path().filename().string();
    if (!b.is_directory(ec) || b.is_symlink(ec) || n.empty() || n.front() == '.' || fs::equivalent(b.path(), bundle, ec))
      continue;
    if (!fs::exists(b.path() / "manifest.json", ec)) continue;
    try {
      const std::string created = read_manifest(b.path()).value("created_utc", "");
      if (best_path.empty() || created > best) best = created, best_path = b.path();
    } catch (const Error&) {
      // an unreadable older manifest: not a bundle to compare with
    }
  }
  return best_path;
}

bool is_output_folder(const fs::path& dir) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) return false;
  for (const auto& e : fs::directory_iterator(dir, ec))
    if (e.is_directory(ec) && fs::exists(e.path() / "latest" / "manifest.json", ec)) return true;
  return false;
}

std::vector<OutputJob> scan_output_folder(const fs::path& dir) {
  if (!is_output_folder(dir))
    throw InputError({dir, 0, 0, ""}, "expected an output folder (job folders, each with a `latest` bundle)");
  std::vector<OutputJob> jobs;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(dir, ec)) {
    const fs::path job_dir = e.path();
    if (!e.is_directory(ec) || !fs::exists(job_dir / "latest" / "manifest.json", ec)) continue;
    OutputJob j;
    j.name = job_dir.filename().string();
    j.bundle = fs::canonical(job_dir / "latest", ec);
    if (ec) j.bundle = job_dir / "latest";
    j.manifest = read_manifest(j.bundle);
    j.bytes = bundle_bytes(j.bundle, j.manifest);
    j.age_s = seconds_since_utc(j.manifest.value("created_utc", ""));
    j.previous = previous_bundle(j.bundle);
    jobs.push_back(std::move(j));
  }
  std::sort(jobs.begin(), jobs.end(), [](const OutputJob& a, const OutputJob& b) { return a.name < b.name; });
  return jobs;
}

json OutputJob::to_json() const {
  const json job = manifest.value("job", json::object());
  const std::string hash = job.is_object() ? job.value("hash", "") : "";
  return {{"name", name},
          {"kind", job.is_object() ? job.value("kind", "") : ""},
          {"bundle", bundle.string()},
          {"hash", hash},
          {"bytes", bytes},
          {"created_utc", manifest.value("created_utc", "")},
          {"age_s", age_s < 0 ? json(nullptr) : json(age_s)},
          {"headline", accuracy_headline(manifest.value("accuracy", json::array()))},
          {"accuracy_passed", [&] {
             for (const auto& a : manifest.value("accuracy", json::array()))
               if (a.is_object() && a.contains("passed") && a["passed"] == false) return false;
             return true;
           }()},
          {"previous", previous.empty() ? json(nullptr) : json(previous.string())}};
}

std::string accuracy_headline(const json& accuracy) {
  if (!accuracy.is_array() || accuracy.empty() || !accuracy[0].is_object()) return "-";
  const json& a = accuracy[0];
  std::string s = a.value("name", "?") + " ";
  const json v = a.value("value", json(nullptr));
  s += v.is_number() ? format_g(v.get<double>(), 3) : v.dump();
  if (a.contains("unit") && a["unit"].is_string()) s += " " + a["unit"].get<std::string>();
  if (a.contains("tolerance") && a["tolerance"].is_number())
    s += (a.value("passed", false) ? " <= " : " > ") + format_g(a["tolerance"].get<double>(), 3);
  return s;
}

double seconds_since_utc(const std::string& utc) {
  std::tm t{};
  int n = 0;
  if (std::sscanf(utc.c_str(), "%d-%d-%dT%d:%d:%dZ%n", &t.tm_year, &t.tm_mon, &t.tm_mday, &t.tm_hour, &t.tm_min,
                  &t.tm_sec, &n) != 6 || n != static_cast<int>(utc.size()))
    return -1.0;
  t.tm_year -= 1900;
  t.tm_mon -= 1;
  const std::time_t then = timegm(&t);
  return std::max(0.0, std::difftime(std::time(nullptr), then));
}

std::string human_bytes(std::uint64_t bytes) {
  const char* units[] = {"B", "KiB", "MiB", "GiB", "TiB"};
  double v = static_cast<double>(bytes);
  int u = 0;
  while (v >= 1024.0 && u < 4) v /= 1024.0, ++u;
  char b[32];
  if (u == 0) std::snprintf(b, sizeof b, "%llu B", static_cast<unsigned long long>(bytes));
  else std::snprintf(b, sizeof b, v < 10 ? "%.1f %s" : "%.0f %s", v, units[u]);
  return b;
}

std::string human_age(double s) {
  char b[32];
  if (s < 0) return "?";
  if (s < 120) std::snprintf(b, sizeof b, "%.0f s", s);
  else if (s < 7200) std::snprintf(b, sizeof b, "%.0f min", s / 60);
  else if (s < 2 * 86400) std::snprintf(b, sizeof b, "%.1f h", s / 3600);
  else std::snprintf(b, sizeof b, "%.1f d", s / 86400);
  return b;
}

}  // namespace specbake
