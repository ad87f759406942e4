#include "runner/night_report.hpp"

#include <algorithm>
#include <fstream>
#include <set>
#include <sstream>

#include "core/errors.hpp"

namespace specbake {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

bool is_failure(const std::string& status) { return status == "failed" || status == "invalid"; }

// 1-based line and column of a byte offset.
Location at_byte(const fs::path& file, const std::string& text, std::size_t byte) {
  Location where{file, 1, 1, ""};
  for (std::size_t i = 0; i < std::min(byte, text.size()); ++i) {
    if (text[i] == '\n') {
      ++where.line;
      where.column = 1;
    } else {
      ++where.column;
    }
  }
  return where;
}

NightShard read_shard(const fs::path& file, json& doc) {
  std::ifstream in(file, std::ios::binary);
  if (!in) throw IoError("cannot read report " + file.string());
  std::stringstream ss;
  ss << in.rdbuf();
  if (in.bad()) throw IoError("cannot read report " + file.string());
  const std::string text = ss.str();
  try {
    doc = json::parse(text);
  } catch (const json::parse_error& e) {
    throw InputError(at_byte(file, text, e.byte == 0 ? 0 : e.byte - 1),
                     "a specbake --report JSON file; it does not parse: " + std::string(e.what()));
  }
  const Location whole{file, 0, 0, ""};
  if (!doc.is_object() || doc.value("schema", "") != "specbake.report/1" || !doc.contains("jobs") ||
      !doc["jobs"].is_array())
    throw InputError(whole, "a specbake --report JSON file (schema specbake.report/1 with a jobs list)");
  NightShard s;
  s.file = file;
  const json& shard = doc.value("shard", json());
  if (shard.is_object()) {
    if (!shard.contains("index") || !shard["index"].is_number_integer() || !shard.contains("count") ||
        !shard["count"].is_number_integer())
      throw InputError(Location{file, 0, 0, "shard"}, "shard.index and shard.count integers");
    s.index = shard["index"].get<int>();
    s.count = shard["count"].get<int>();
    s.source = shard.value("source", "");
  }
  s.created_utc = doc.value("created_utc", "");
  if (doc.contains("tool") && doc["tool"].is_object()) s.tool_version = doc["tool"].value("version", "");
  s.error = doc.value("error", "");
  s.summary = doc.value("summary", json::object());
  for (std::size_t k = 0; k < doc["jobs"].size(); ++k) {
    const json& j = doc["jobs"][k];
    const Location where{file, 0, 0, "jobs[" + std::to_string(k) + "]"};
    if (!j.is_object() || !j.contains("name") || !j["name"].is_string() || !j.contains("status") ||
        !j["status"].is_string())
      throw InputError(where, "a job with a name and a status");
    const auto& known = night_statuses();
    if (std::find(known.begin(), known.end(), j["status"].get<std::string>()) == known.end())
      throw InputError(where, "status one of built, up-to-date, planned, failed, invalid, interrupted, not-run; got '" +
                                  j["status"].get<std::string>() + "'");
  }
  return s;
}

std::vector<fs::path> report_files(const std::vector<fs::path>& inputs) {
  std::vector<fs::path> files;
  for (const auto& in : inputs) {
    std::error_code ec;
    if (fs::is_directory(in, ec)) {
      std::vector<fs::path> here;
      for (fs::directory_iterator it(in, ec), end; !ec && it != end; it.increment(ec))
        if (it->path().extension() == ".json" && it->is_regular_file()) here.push_back(it->path());
      if (ec) throw IoError("cannot read folder " + in.string() + ": " + ec.message());
      if (here.empty())
        throw UsageError("report: " + in.string() + " holds no *.json report; expected shard reports (run --report FILE)");
      std::sort(here.begin(), here.end());
      files.insert(files.end(), here.begin(), here.end());
    } else if (fs::exists(in, ec)) {
      files.push_back(in);
    } else {
      throw IoError("cannot read report " + in.string() + ": no such file or folder");
    }
  }
  // The same file named twice (a file and its folder) is read once.
  std::vector<fs::path> unique;
  std::set<std::string> seen;
  for (const auto& f : files)
    if (seen.insert(fs::weakly_canonical(f).string()).second) unique.push_back(f);
  return unique;
}

std::string seconds_text(double s) {
  if (s < 0) return "-";
  std::ostringstream o;
  o.setf(std::ios::fixed);
  o.precision(s < 10 ? 1 : 0);
  o << s << " s";
  return o.str();
}

}  // namespace

std::string NightShard::label() const {
  return index ? std::to_string(*index) + "/" + std::to_string(*count) : std::string("-");
}

bool NightJob::ok() const { return status == "built" || status == "up-to-date" || status == "planned"; }

const std::vector<std::string>& night_statuses() {
  static const std::vector<std::string> order = {"built",  "up-to-date",  "planned", "failed",
                                                 "invalid", "interrupted", "not-run"};
  return order;
}

NightReport merge_night(const std::vector<fs::path>& inputs) {
  NightReport night;
  std::map<std::string, NightJob> jobs;
  for (const auto& file : report_files(inputs)) {
    json doc;
    night.shards.push_back(read_shard(file, doc));
    NightShard& shard = night.shards.back();
    const std::size_t s = night.shards.size() - 1;
    for (const json& j : doc["jobs"]) {
      NightEntry e;
      e.shard = s;
      e.status = j["status"].get<std::string>();
      e.reason = j.value("reason", "");
      if (j.contains("timings") && j["timings"].is_object() && j["timings"].contains("total_s") &&
          j["timings"]["total_s"].is_number())
        e.seconds = j["timings"]["total_s"].get<double>();
      e.job = j;
      if (is_failure(e.status)) shard.failed = true;
      const std::string name = j["name"].get<std::string>();
      NightJob& job = jobs[name];
      if (job.entries.empty()) {
        job.name = name;
        job.kind = j.value("kind", "");
        job.config = j.value("config", "");
      }
      job.entries.push_back(std::move(e));
    }
    if (!shard.error.empty()) shard.failed = true;
    if (shard.failed) {
      std::string why = shard.error;
      for (const json& j : doc["jobs"])
        if (is_failure(j["status"].get<std::string>()))
          why += std::string(why.empty() ? "" : "; ") + j["name"].get<std::string>() + " " +
                 j["status"].get<std::string>();
      night.problems.push_back("shard " + shard.label() + " (" + file.string() + ") failed: " + why);
    }
  }

  const auto& order = night_statuses();
  const auto rank = [&](const std::string& s) { return std::find(order.begin(), order.end(), s) - order.begin(); };
  for (auto& [name, job] : jobs) {
    for (std::size_t k = 0; k < job.entries.size(); ++k) {
      if (rank(job.entries[k].status) < rank(job.entries[job.decided_by].status)) job.decided_by = k;
      if (job.entries[k].status == "built") ++job.builds;
    }
    job.status = job.decision().status;
    const auto where = [&](const NightEntry& e) {
      return night.shards[e.shard].label() + " (" + night.shards[e.shard].file.filename().string() + ")";
    };
    if (job.builds > 1) {
      std::string shards;
      for (const auto& e : job.entries)
        if (e.status == "built") shards += (shards.empty() ? "" : ", ") + where(e);
      job.notes.push_back("built " + std::to_string(job.builds) + " times, in shards " + shards);
      ++night.built_twice;
    }
    for (const auto& e : job.entries)
      if (e.status != job.status && e.status != "up-to-date")
        job.notes.push_back(e.status + " in shard " + where(e) + (e.reason.empty() ? "" : ": " + e.reason));
    if (!job.ok())
      night.problems.push_back(job.name + " " + job.status + " in shard " + where(job.decision()) +
                               (job.decision().reason.empty() ? "" : ": " + job.decision().reason));
    ++night.counts[job.status];
    night.jobs.push_back(std::move(job));
  }

  // Every shard of an I/N split reported (several splits may share a night: each is checked).
  std::map<int, std::set<int>> seen;
  for (const auto& s : night.shards)
    if (s.index) seen[*s.count].insert(*s.index);
  for (const auto& [count, indices] : seen) {
    std::string missing;
    for (int i = 0; i < count; ++i)
      if (!indices.count(i)) missing += (missing.empty() ? "" : ", ") + std::to_string(i) + "/" + std::to_string(count);
    if (!missing.empty()) night.problems.push_back("no report from shard " + missing);
  }
  return night;
}

json night_json(const NightReport& night) {
  json shards = json::array();
  for (const auto& s : night.shards)
    shards.push_back({{"file", s.file.string()},
                      {"index", s.index ? json(*s.index) : json(nullptr)},
                      {"count", s.count ? json(*s.count) : json(nullptr)},
                      {"source", s.source},
                      {"created_utc", s.created_utc},
                      {"tool_version", s.tool_version},
                      {"error", s.error},
                      {"summary", s.summary},
                      {"failed", s.failed}});
  json jobs = json::array();
  for (const auto& j : night.jobs) {
    json entries = json::array();
    for (const auto& e : j.entries)
      entries.push_back({{"shard", night.shards[e.shard].label()},
                         {"file", night.shards[e.shard].file.string()},
                         {"status", e.status},
                         {"reason", e.reason},
                         {"seconds", e.seconds < 0 ? json(nullptr) : json(e.seconds)},
                         {"bundle", e.job.value("bundle", json())}});
    const NightEntry& d = j.decision();
    jobs.push_back({{"name", j.name},
                    {"kind", j.kind},
                    {"config", j.config},
                    {"status", j.status},
                    {"reason", d.reason},
                    {"shard", night.shards[d.shard].label()},
                    {"seconds", d.seconds < 0 ? json(nullptr) : json(d.seconds)},
                    {"bundle", d.job.value("bundle", json())},
                    {"builds", j.builds},
                    {"notes", j.notes},
                    {"entries", entries}});
  }
  json counts = json::object();
  for (const auto& s : night_statuses()) counts[s] = night.counts.count(s) ? night.counts.at(s) : 0;
  return {{"schema", "specbake.night/1"},
          {"shards", shards},
          {"jobs", jobs},
          {"summary", {{"jobs", night.jobs.size()}, {"statuses", counts}, {"built_twice", night.built_twice}}},
          {"problems", night.problems},
          {"failed", night.failed()}};
}

std::string night_text(const NightReport& night) {
  std::ostringstream o;
  o << "shard  report  (created, source)\n";
  for (const auto& s : night.shards) {
    o << s.label() << "  " << s.file.string() << "  (" << (s.created_utc.empty() ? "?" : s.created_utc)
      << (s.source.empty() ? "" : ", " + s.source) << ")";
    if (!s.error.empty()) o << "  error: " << s.error;
    o << "\n";
  }
  o << "\n";
  std::vector<std::vector<std::string>> rows = {{"job", "kind", "status", "shard", "time", "reason"}};
  for (const auto& j : night.jobs) {
    const NightEntry& d = j.decision();
    std::string status = j.status;
    if (j.builds > 1) status += " x" + std::to_string(j.builds);
    std::string shard = night.shards[d.shard].label();
    if (j.entries.size() > 1) shard += " +" + std::to_string(j.entries.size() - 1);
    rows.push_back({j.name, j.kind, status, shard, seconds_text(d.seconds), j.ok() ? "" : d.reason});
  }
  std::vector<std::size_t> width(rows.front().size(), 0);
  for (const auto& r : rows)
    for (std::size_t c = 0; c < r.size(); ++c) width[c] = std::max(width[c], r[c].size());
  for (const auto& r : rows) {
    std::string line;
    for (std::size_t c = 0; c < r.size(); ++c) {
      line += r[c];
      if (c + 1 < r.size()) line += std::string(width[c] - r[c].size() + 2, ' ');
    }
    while (!line.empty() && line.back() == ' ') line.pop_back();
    o << line << "\n";
  }
  bool any_note = false;
  for (const auto& j : night.jobs)
    for (const auto& n : j.notes) {
      if (!any_note) o << "\nnotes:\n";
      any_note = true;
      o << "  " << j.name << ": " << n << "\n";
    }
  if (night.failed()) {
    o << "\nproblems:\n";
    for (const auto& p : night.problems) o << "  " << p << "\n";
  }
  const auto count = [&](const char* s) { return night.counts.count(s) ? night.counts.at(s) : 0; };
  o << "\n" << night.jobs.size() << " jobs from " << night.shards.size() << " shard reports: " << count("built")
    << " built, " << count("up-to-date") << " up to date, " << count("failed") << " failed, " << count("invalid")
    << " invalid, " << count("interrupted") << " interrupted, " << count("not-run") << " not run";
  if (count("planned")) o << ", " << count("planned") << " planned";
  if (night.built_twice) o << "; " << night.built_twice << " built in more than one shard";
  o << (night.failed() ? "; the night FAILED\n" : "; the night is complete\n");
  return o.str();
}

}  // namespace specbake
