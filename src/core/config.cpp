#include "core/config.hpp"

#include <yaml-cpp/eventhandler.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstring>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <map>
#include <sstream>
#include <regex>
#include <set>
#include <vector>

#include "core/yaml_at.hpp"

namespace specbake {

std::string closest_word(const std::string& word, const std::vector<std::string>& candidates) {
  // Edit distance with adjacent transpositions (optimal string alignment), case-insensitive; a
  // candidate qualifies within a third of the word's length (at least 1).
  auto lower = [](std::string t) {
    for (auto& c : t) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    return t;
  };
  const std::string w = lower(word);
  std::string best;
  std::size_t best_d = std::max<std::size_t>(1, w.size() / 3) + 1;
  for (const auto& cand : candidates) {
    const std::string c = lower(cand);
    std::vector<std::vector<std::size_t>> d(w.size() + 1, std::vector<std::size_t>(c.size() + 1));
    for (std::size_t i = 0; i <= w.size(); ++i) d[i][0] = i;
    for (std::size_t j = 0; j <= c.size(); ++j) d[0][j] = j;
    for (std::size_t i = 1; i <= w.size(); ++i)
      for (std::size_t j = 1; j <= c.size(); ++j) {
        d[i][j] = std::min({d[i - 1][j] + 1, d[i][j - 1] + 1, d[i - 1][j - 1] + (w[i - 1] == c[j - 1] ? 0 : 1)});
        if (i > 1 && j > 1 && w[i - 1] == c[j - 2] && w[i - 2] == c[j - 1]) d[i][j] = std::min(d[i][j], d[i - 2][j - 2] + 1);
      }
    if (d[w.size()][c.size()] < best_d) best_d = d[w.size()][c.size()], best = cand;
  }
  return best;
}

using yaml::At;

void allow_job_keys(const At& job, std::initializer_list<const char*> own) {
  std::vector<std::string> keys = {"name", "kind", "tolerance_advisory"};
  keys.insert(keys.end(), own.begin(), own.end());
  job.allow_keys(keys);
}

namespace {
constexpr std::size_t kMaxConfigBytes = 1 << 20;  // a config is a few kB; refuse huge documents
constexpr std::size_t kMaxExpandedNodes = 100000;  // nodes counted with every alias expanded

// Pre-scan of the event stream: counts nodes as if every alias were expanded (so "billion
// laughs" alias bombs are refused before any traversal) and the number of documents.
class NodeBudget : public YAML::EventHandler {
 public:
  std::size_t expanded = 0, documents = 0;
  YAML::Mark worst;

  void OnDocumentStart(const YAML::Mark&) override { ++documents; }
  void OnDocumentEnd() override {}
  void OnNull(const YAML::Mark& m, YAML::anchor_t a) override { leaf(m, a, 1); }
  void OnAlias(const YAML::Mark& m, YAML::anchor_t a) override { leaf(m, 0, size_of_.count(a) ? size_of_[a] : 1); }
  void OnScalar(const YAML::Mark& m, const std::string&, YAML::anchor_t a, const std::string&) override { leaf(m, a, 1); }
  void OnSequenceStart(const YAML::Mark& m, const std::string&, YAML::anchor_t a, YAML::EmitterStyle::value) override {
    open(m, a);
  }
  void OnSequenceEnd() override { close(); }
  void OnMapStart(const YAML::Mark& m, const std::string&, YAML::anchor_t a, YAML::EmitterStyle::value) override {
    open(m, a);
  }
  void OnMapEnd() override { close(); }

 private:
  struct Open {
    YAML::anchor_t anchor;
    std::size_t size;
  };
  std::vector<Open> stack_;
  bool over_ = false;
  std::map<YAML::anchor_t, std::size_t> size_of_;

  void add(const YAML::Mark& m, std::size_t n) {
    expanded += n;
    if (!stack_.empty()) stack_.back().size += n;
    if (expanded > kMaxExpandedNodes && !over_) over_ = true, worst = m;
  }
  void leaf(const YAML::Mark& m, YAML::anchor_t a, std::size_t n) {
    if (a) size_of_[a] = n;
    add(m, n);
  }
  void open(const YAML::Mark& m, YAML::anchor_t a) {
    stack_.push_back({a, 1});
    expanded += 1;
    if (expanded > kMaxExpandedNodes && !over_) over_ = true, worst = m;
  }
  void close() {
    const Open o = stack_.back();
    stack_.pop_back();
    if (o.anchor) size_of_[o.anchor] = o.size;
    if (!stack_.empty()) stack_.back().size += o.size;
  }
};
// A YAML syntax error, located where the broken construct begins when that can be told: a tab
// in the indentation, or a '[' / '{' that is never closed (the parser notices those only
// lines later, where it gives up).
InputError syntax_error(const std::string& text, const fs::path& file, const YAML::ParserException& e) {
  const int err_line = e.mark.line + 1;
  // Tabs in leading whitespace up to the error line.
  int line = 1;
  for (std::size_t i = 0, start = 0; i <= text.size() && line <= err_line; ++i) {
    if (i == text.size() || text[i] == '\n') {
      for (std::size_t k = start; k < i && (text[k] == ' ' || text[k] == '\t'); ++k)
        if (text[k] == '\t')
          return InputError({file, line, static_cast<int>(k - start) + 1, ""},
                            "a tab in the indentation; YAML indents with spaces only (the parser says: " + e.msg + ")");
      start = i + 1;
      ++line;
    }
  }
  // Flow collections never closed: scan brackets outside quotes and comments.
  struct Open {
    char c;
    int line, column;
  };
  std::vector<Open> open;
  line = 1;
  int column = 0;
  char quote = 0;
  bool comment = false;
  for (std::size_t i = 0; i < text.size(); ++i) {
    const char c = text[i];
    ++column;
    if (c == '\n') {
      ++line;
      column = 0;
      comment = false;
      continue;
    }
    if (comment) continue;
    if (quote) {
      if (c == quote) quote = 0;
      continue;
    }
    if (c == '#' && (i == 0 || text[i - 1] == ' ' || text[i - 1] == '\t')) comment = true;
    else if (c == '"' || c == '\'') quote = c;
    else if (c == '[' || c == '{') open.push_back({c, line, column});
    else if ((c == ']' || c == '}') && !open.empty() && open.back().c == (c == ']' ? '[' : '{')) open.pop_back();
  }
  if (!open.empty() && open.front().line <= err_line)
    return InputError({file, open.front().line, open.front().column, ""},
                      std::string("'") + open.front().c + "' is never closed (expected '" +
                          (open.front().c == '[' ? "]" : "}") + "'; the parser gave up at line " +
                          std::to_string(err_line) + ": " + e.msg + ")");
  return InputError({file, err_line, e.mark.column + 1, ""}, "malformed YAML: " + e.msg);
}

}  // namespace

YAML::Node parse_yaml(const std::string& text, const fs::path& file) {
  if (text.size() > kMaxConfigBytes)
    throw InputError({file, 0, 0, ""}, "config is " + std::to_string(text.size()) +
                                            " bytes; expected at most " + std::to_string(kMaxConfigBytes));
  YAML::Node root;
  try {
    NodeBudget budget;
    std::istringstream scan(text);
    YAML::Parser parser(scan);
    while (parser.HandleNextDocument(budget)) {
      if (budget.expanded > kMaxExpandedNodes)
        throw InputError({file, budget.worst.line + 1, budget.worst.column + 1, ""},
                         "document expands to more than " + std::to_string(kMaxExpandedNodes) +
                             " nodes (alias bomb?); expected a small config");
    }
    if (budget.documents > 1)
      throw InputError({file, 0, 0, ""}, "expected one YAML document, found " + std::to_string(budget.documents));
    root = YAML::Load(text);
  } catch (const YAML::ParserException& e) {
    throw syntax_error(text, file, e);
  }
  return root;
}

Config parse_config(const std::string& text, const fs::path& file, const std::vector<KindSyntax>& kinds,
                    std::vector<InvalidJob>* job_errors) {
  return parse_config(parse_yaml(text, file), file, kinds, job_errors);
}

Config parse_config(const YAML::Node& root, const fs::path& file, const std::vector<KindSyntax>& kinds,
                    std::vector<InvalidJob>* job_errors) {
  const At top{root, "", &file};
  if (!root.IsMap()) top.fail("expected a mapping with keys specbake, output, device, jobs");
  top.allow_keys({"specbake", "output", "device", "jobs"});

  Config cfg;
  cfg.file = file;
  if (!top.has("specbake")) top.fail("expected 'specbake: 1' (the schema version)");
  const At ver = top.child("specbake");
  if (ver.integer() != kSchemaVersion)
    ver.fail("unsupported schema version " + ver.shown() + "; this specbake reads version 1");
  if (top.has("output")) {
    std::string out = top.child("output").string();
    if (out.empty()) top.child("output").fail("expected a folder path");
    if (out == "~" || out.rfind("~/", 0) == 0) {  // the home folder, as a shell would expand it
      const char* home = std::getenv("HOME");
      if (!home || !*home) top.child("output").fail("expected a folder path; '~' needs HOME to be set");
      out = std::string(home) + out.substr(1);
    } else if (out[0] == '~') {
      top.child("output").fail("expected a folder path; '~user' is not expanded, write the full path");
    }
    cfg.output = (file.parent_path() / out).lexically_normal();  // configs/../assets prints as assets
    cfg.output_given = true;
  } else {
    cfg.output = "assets";
  }
  if (top.has("device")) {
    cfg.device = top.child("device").string();
    if (cfg.device.empty()) top.child("device").fail("expected auto | cpu | gpu | part of a device name");
  }
  if (!top.has("jobs")) top.fail("expected a 'jobs' list");
  const At jobs = top.child("jobs");
  if (!jobs.node.IsSequence() || jobs.node.size() == 0) jobs.fail("expected a non-empty list of jobs");

  std::string kind_list;
  std::vector<std::string> kind_names;
  for (const auto& k : kinds) {
    kind_list += (kind_list.empty() ? "" : " | ") + k.name;
    kind_names.push_back(k.name);
  }
  static const std::regex name_re("[a-z0-9][a-z0-9._-]*");
  std::map<std::string, Location> names;
  for (std::size_t i = 0; i < jobs.node.size(); ++i) {
    const At job = jobs.item(i);
    // what names the job in reports, read before anything about it is checked
    auto scalar = [&](const char* k) {
      return job.node.IsMap() && job.node[k] && job.node[k].IsScalar() ? job.node[k].Scalar() : std::string();
    };
    const std::string read_name = std::regex_match(scalar("name"), name_re) ? scalar("name") : "";
    const std::string read_kind = scalar("kind");
    try {
      job.expect_map("a job");
      if (!job.has("name")) job.fail("expected a 'name'");
      if (!job.has("kind")) job.fail("expected a 'kind' (" + kind_list + ")");
      const At name_at = job.child("name");
      JobSpec js;
      js.name = name_at.string();
      if (!std::regex_match(js.name, name_re) || js.name.size() > 100)
        name_at.fail("expected a job name matching [a-z0-9][a-z0-9._-]* (at most 100 characters), got " +
                     name_at.shown());
      if (auto it = names.find(js.name); it != names.end())
        name_at.fail("duplicate job name '" + js.name + "' (first used at " + it->second.str() + ")");
      names.emplace(js.name, name_at.loc());
      js.where = job.loc();
      const At kind_at = job.child("kind");
      js.kind = kind_at.string();
      const auto kind = std::find_if(kinds.begin(), kinds.end(), [&](const KindSyntax& k) { return k.name == js.kind; });
      if (kind == kinds.end()) {
        const std::string near = closest_word(js.kind, kind_names);
        kind_at.fail("expected kind " + kind_list + ", got " + kind_at.shown() +
                     (near.empty() ? "" : " (did you mean '" + near + "'?)"));
      }
      js.spec = kind->parse(job, js.normalised, js.inputs);
      if (job.has("tolerance_advisory"))
        js.tolerance_advisory = job.child("tolerance_advisory").choice<bool>({{"true", true}, {"false", false}});
      // in the hash only when set: a job made advisory, or strict again, is baked (and judged) again
      if (js.tolerance_advisory) js.normalised["tolerance_advisory"] = true;
      cfg.jobs.push_back(std::move(js));
    } catch (const InputError& e) {
      if (!job_errors) throw;
      const bool known_kind = std::find(kind_names.begin(), kind_names.end(), read_kind) != kind_names.end();
      job_errors->push_back({e, read_name, known_kind ? read_kind : ""});
    }
  }
  return cfg;
}

YAML::Node load_yaml(const fs::path& file) {
  std::error_code ec;
  const auto st = fs::status(file, ec);
  if (!fs::is_regular_file(st)) {
    const std::string what = !fs::exists(st) ? (ec ? ec.message() : "no such file")
                             : fs::is_directory(st) ? "a folder" : "not a regular file";
    throw IoError("cannot read config " + file.string() + ": " + what + "; expected a YAML file");
  }
  if (fs::file_size(file, ec) > kMaxConfigBytes)
    throw InputError({file, 0, 0, ""}, "config larger than " + std::to_string(kMaxConfigBytes) + " bytes");
  std::ifstream in(file, std::ios::binary);
  if (!in)
    throw IoError("cannot read config " + file.string() + ": " + std::strerror(errno) +
                  " (expected a file this user can read)");
  std::stringstream ss;
  ss << in.rdbuf();
  return parse_yaml(ss.str(), file);
}

Config load_config(const fs::path& file, const std::vector<KindSyntax>& kinds, std::vector<InvalidJob>* job_errors) {
  return parse_config(load_yaml(file), file, kinds, job_errors);
}

}  // namespace specbake
