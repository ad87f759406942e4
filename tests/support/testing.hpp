#pragma once
// Helpers shared by the tests: reference data, temporary folders, running the CLI.
#include <sys/types.h>

#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "cl/device.hpp"

namespace specbake::testing {

namespace fs = std::filesystem;

// The OpenCL device `auto` picks, opened once per test program.
cl_util::Device& shared_device();

fs::path refdata_dir();   // SPECBAKE_REFDATA_DIR; fails the test if missing
fs::path source_dir();    // the repository root
fs::path specbake_exe();  // the built CLI

nlohmann::json read_json(const fs::path& p);
std::string read_file(const fs::path& p);
std::vector<float> read_f32(const fs::path& p);
// A PNG decoded to 8-bit RGBA by libpng's simplified API (width 0 when unreadable).
struct Image {
  int width = 0, height = 0;
  std::vector<unsigned char> rgba;
};
Image read_png(const fs::path& p);

// For the docs' GL-against-host figures (scripts/docs_gl_figures.sh): where the environment
// variable SPECBAKE_GL_FIGURES names a folder, a GL test writes there <name>.json (its notes and
// the size) and <name>.f32 (float32: the GL image, the host image, each w·h·3 with row 0
// at the bottom, then w·h values of |GL − host| / bound, the worst channel). Otherwise nothing.
void write_gl_figure(const std::string& name, int w, int h, const std::vector<float>& gl_rgb,
                     const std::vector<float>& host_rgb, const std::vector<float>& over_bound,
                     const nlohmann::json& meta);

// glslangValidator (Debian glslang-tools): whether it is on PATH, and its exit status and output
// for `source` written to dir/name (the extension names the stage: .frag, .vert).
bool have_glslang();
std::pair<int, std::string> glslang_validate(const fs::path& dir, const std::string& name, const std::string& source);
void write_file(const fs::path& p, const std::string& text);

// A fresh folder under the system temp dir, removed when the object dies.
class TempDir {
 public:
  TempDir();
  ~TempDir();
  const fs::path& path() const { return path_; }
  fs::path operator/(const std::string& s) const { return path_ / s; }

 private:
  fs::path path_;
};

struct CliResult {
  int exit_code = -1;
  std::string out;  // stdout
  std::string err;  // stderr
};
// Runs the specbake binary with args (no shell), capturing its output. env: extra
// "NAME=value" entries on top of this process's environment (replacing variables of that name).
CliResult run_cli(const std::vector<std::string>& args, const fs::path& cwd = {},
                  const std::vector<std::string>& env = {});
// Starts the specbake binary without waiting; stdout/stderr go to the given files.
pid_t spawn_cli(const std::vector<std::string>& args, const fs::path& cwd, const fs::path& out_file,
                const fs::path& err_file, const std::vector<std::string>& env = {});

// Everything under root (dot-files included, symlinks not followed): regular files by their
// sha256, symlinks by their target, folders by name. Paths are relative to root.
struct TreeSnapshot {
  std::map<std::string, std::string> files;  // path -> sha256
  std::map<std::string, std::string> links;  // path -> link target
  std::vector<std::string> dirs;
  bool operator==(const TreeSnapshot&) const = default;
};
TreeSnapshot snapshot(const fs::path& root);
// Modification times of the regular files under root (relative path -> mtime).
std::map<std::string, fs::file_time_type> mtimes(const fs::path& root);

// "line:column" (1-based) where the occurrence-th copy of needle starts in text.
std::string line_col(const std::string& text, const std::string& needle, int occurrence = 1);

// Under root, chmod does not stop writes: tests that need an unwritable folder must use
// another way (a path below a regular file).
bool running_as_root();

}  // namespace specbake::testing
