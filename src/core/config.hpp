#pragma once
// The config model (schema v1): a file of jobs, each of a kind. This layer knows the file's
// top-level keys and the fields every job has (name, kind); each kind's own keys are parsed by
// that kind (src/kinds/<kind>/config.cpp), which it is handed through a `KindSyntax` table
// (built by src/registry/ from the registered kinds). Jobs only ever see typed specs: every
// value has been range-checked and every path resolved against the config file's folder.
#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <typeinfo>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/errors.hpp"
#include "core/yaml_at.hpp"

namespace specbake {

namespace fs = std::filesystem;

// The typed spec of one job; each kind derives its own (e.g. AtmosphereSpec).
struct KindSpec {
  virtual ~KindSpec() = default;
};

// (label, sha256) of each input file a job reads: their contents enter the bundle hash.
using Inputs = std::vector<std::pair<std::string, std::string>>;

struct JobSpec {
  std::string name;
  std::string kind;
  Location where;             // the job's entry in its config
  std::shared_ptr<const KindSpec> spec;
  nlohmann::json normalised;  // canonical form of everything that defines the result
  Inputs inputs;
  // `tolerance_advisory: true` (any kind): an accuracy record that misses its tolerance is a
  // warning and the bundle is published; by default such a job fails (exit 1).
  bool tolerance_advisory = false;

  // The kind's spec; std::bad_cast if the job is of another kind (a programming error).
  template <class S>
  const S& as() const {
    if (const auto* s = dynamic_cast<const S*>(spec.get())) return *s;
    throw std::bad_cast();
  }
};

struct Config {
  fs::path file;
  fs::path output;     // absolute or relative to cwd; already resolved against the file's folder
  bool output_given = false;
  std::string device = "auto";
  std::vector<JobSpec> jobs;
};

// How one kind reads its keys of a job entry: `job` is the whole entry (name, kind and
// tolerance_advisory included; allow_job_keys rejects keys it does not know); fills `norm` with the canonical form of everything
// that defines the result and `inputs` with the data files it read.
struct KindSyntax {
  std::string name;
  std::function<std::shared_ptr<const KindSpec>(const yaml::At& job, nlohmann::json& norm, Inputs& inputs)> parse;
};

// A job entry that failed validation, with its name and kind where they could be read ("" else).
struct InvalidJob {
  InputError error;
  std::string name, kind;
};

inline constexpr int kSchemaVersion = 1;
// Rejects a job entry's unknown and duplicate keys: those every job has, whatever its kind
// (name, kind, tolerance_advisory), and the kind's `own`.
void allow_job_keys(const yaml::At& job, std::initializer_list<const char*> own);

// Parses and validates; throws InputError (file:line:col + key path) or IoError. With
// `job_errors` set, an invalid job entry is recorded there and left out instead (errors in the
// file's top level still throw).
Config parse_config(const std::string& text, const fs::path& file_for_messages, const std::vector<KindSyntax>& kinds,
                    std::vector<InvalidJob>* job_errors = nullptr);
Config load_config(const fs::path& file, const std::vector<KindSyntax>& kinds,
                   std::vector<InvalidJob>* job_errors = nullptr);
// The two halves of parse_config: the text read into a YAML tree (size, alias and syntax checks;
// InputError with file:line:col), and a tree validated into a Config. A tree edited after
// reading (`specbake sweep` sets keys) is validated like a file; keys it added carry no
// line, so their errors name the key path alone.
YAML::Node parse_yaml(const std::string& text, const fs::path& file_for_messages);
// A config file read and parsed into a tree (IoError when it cannot be read).
YAML::Node load_yaml(const fs::path& file);
Config parse_config(const YAML::Node& root, const fs::path& file_for_messages, const std::vector<KindSyntax>& kinds,
                    std::vector<InvalidJob>* job_errors = nullptr);

}  // namespace specbake
