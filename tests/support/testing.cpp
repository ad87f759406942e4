#include "support/testing.hpp"

#include <gtest/gtest.h>
#include <fcntl.h>
#include <sys/wait.h>
#include <png.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <random>
#include <sstream>

#include "core/hash.hpp"

namespace specbake::testing {

Image read_png(const fs::path& p) {
  png_image img{};
  img.version = PNG_IMAGE_VERSION;
  Image out;
  if (!png_image_begin_read_from_file(&img, p.c_str())) return out;
  img.format = PNG_FORMAT_RGBA;
  out.rgba.resize(PNG_IMAGE_SIZE(img));
  if (!png_image_finish_read(&img, nullptr, out.rgba.data(), 0, nullptr)) return {};
  out.width = static_cast<int>(img.width);
  out.height = static_cast<int>(img.height);
  return out;
}

bool have_glslang() { return std::system("command -v glslangValidator > /dev/null 2>&1") == 0; }

std::pair<int, std::string> glslang_validate(const fs::path& dir, const std::string& name, const std::string& source) {
  write_file(dir / name, source);
  const std::string log = (dir / (name + ".log")).string();
  const int status = std::system(("glslangValidator '" + (dir / name).string() + "' > '" + log + "' 2>&1").c_str());
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, read_file(log)};
}

cl_util::Device& shared_device() {
  static cl_util::Device dev(cl_util::select_device("auto"));
  return dev;
}

fs::path refdata_dir() {
  const fs::path p = SPECBAKE_REFDATA_DIR;
  if (!fs::is_directory(p))
    ADD_FAILURE() << "reference data not found at " << p << " (configure with -DSPECBAKE_REFDATA_DIR=...)";
  return p;
}
fs::path source_dir() { return SPECBAKE_SOURCE_DIR; }
fs::path specbake_exe() { return SPECBAKE_EXE; }

std::string read_file(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  if (!in) throw std::runtime_error("cannot read " + p.string());
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

nlohmann::json read_json(const fs::path& p) { return nlohmann::json::parse(read_file(p)); }

std::vector<float> read_f32(const fs::path& p) {
  const std::string b = read_file(p);
  std::vector<float> v(b.size() / 4);
  std::memcpy(v.data(), b.data(), v.size() * 4);
  return v;
}

void write_file(const fs::path& p, const std::string& text) {
  fs::create_directories(p.parent_path());
  std::ofstream(p, std::ios::binary) << text;
}

TempDir::TempDir() {
  std::random_device rd;
  path_ = fs::temp_directory_path() / ("specbake-test-" + std::to_string(::getpid()) + "-" + std::to_string(rd()));
  fs::create_directories(path_);
}
TempDir::~TempDir() {
  std::error_code ec;
  // Restore permissions a test may have removed, then delete.
  for (auto it = fs::recursive_directory_iterator(path_, ec); it != fs::recursive_directory_iterator(); it.increment(ec))
    fs::permissions(it->path(), fs::perms::owner_all, fs::perm_options::add, ec);
  fs::remove_all(path_, ec);
}

pid_t spawn_cli(const std::vector<std::string>& args, const fs::path& cwd, const fs::path& out_file,
                const fs::path& err_file, const std::vector<std::string>& env) {
  // Everything the child needs is prepared before fork: the test process may have OpenCL
  // threads, so the child makes only async-signal-safe calls until it execs.
  const std::string exe = specbake_exe().string();
  std::vector<char*> argv;
  argv.push_back(const_cast<char*>(exe.c_str()));
  for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  std::vector<char*> envp;
  // `env` entries replace variables of the same name.
  for (char** e = environ; *e; ++e) {
    const std::string entry = *e;
    const std::string name = entry.substr(0, entry.find('='));
    bool replaced = false;
    for (const auto& x : env) replaced = replaced || x.substr(0, x.find('=')) == name;
    if (!replaced) envp.push_back(*e);
  }
  for (const auto& e : env) envp.push_back(const_cast<char*>(e.c_str()));
  envp.push_back(nullptr);
  const pid_t pid = ::fork();
  if (pid == 0) {
    if (!cwd.empty() && ::chdir(cwd.c_str()) != 0) _exit(127);
    const int o = ::open(out_file.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    const int e = ::open(err_file.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (o < 0 || e < 0) _exit(127);
    ::dup2(o, 1);
    ::dup2(e, 2);
    ::execve(exe.c_str(), argv.data(), envp.data());
    _exit(127);
  }
  if (pid < 0) ADD_FAILURE() << "fork failed: " << std::strerror(errno);
  return pid;
}

CliResult run_cli(const std::vector<std::string>& args, const fs::path& cwd, const std::vector<std::string>& env) {
  // stdout and stderr go to temp files (no pipe deadlock on large output).
  TempDir tmp;
  const fs::path out_path = tmp / "stdout", err_path = tmp / "stderr";
  const pid_t pid = spawn_cli(args, cwd, out_path, err_path, env);
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  CliResult r;
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  r.out = read_file(out_path);
  r.err = read_file(err_path);
  return r;
}

TreeSnapshot snapshot(const fs::path& root) {
  TreeSnapshot s;
  std::error_code ec;
  if (!fs::exists(fs::symlink_status(root, ec))) return s;
  for (auto it = fs::recursive_directory_iterator(root); it != fs::recursive_directory_iterator(); ++it) {
    const std::string rel = fs::relative(it->path(), root).string();
    if (it->is_symlink()) s.links[rel] = fs::read_symlink(it->path()).string();
    else if (it->is_directory()) s.dirs.push_back(rel);
    else if (it->is_regular_file()) s.files[rel] = sha256_file(it->path());
  }
  std::sort(s.dirs.begin(), s.dirs.end());
  return s;
}

std::map<std::string, fs::file_time_type> mtimes(const fs::path& root) {
  std::map<std::string, fs::file_time_type> m;
  for (auto it = fs::recursive_directory_iterator(root); it != fs::recursive_directory_iterator(); ++it)
    if (it->is_regular_file() && !it->is_symlink()) m[fs::relative(it->path(), root).string()] = it->last_write_time();
  return m;
}

std::string line_col(const std::string& text, const std::string& needle, int occurrence) {
  std::size_t pos = std::string::npos, from = 0;
  for (int k = 0; k < occurrence; ++k) {
    pos = text.find(needle, from);
    if (pos == std::string::npos) {
      ADD_FAILURE() << "'" << needle << "' occurs fewer than " << occurrence << " times in:\n" << text;
      return "?";
    }
    from = pos + 1;
  }
  const std::size_t line_start = text.rfind('\n', pos == 0 ? 0 : pos - 1);
  const long line = 1 + std::count(text.begin(), text.begin() + static_cast<long>(pos), '\n');
  const std::size_t col = line_start == std::string::npos || pos == 0 ? pos + 1 : pos - line_start;
  return std::to_string(line) + ":" + std::to_string(col);
}

bool running_as_root() { return ::geteuid() == 0; }

void write_gl_figure(const std::string& name, int w, int h, const std::vector<float>& gl_rgb,
                     const std::vector<float>& host_rgb, const std::vector<float>& over_bound,
                     const nlohmann::json& meta) {
  const char* dir = std::getenv("SPECBAKE_GL_FIGURES");
  if (!dir || !*dir) return;
  const std::size_t n = static_cast<std::size_t>(w) * h;
  ASSERT_EQ(gl_rgb.size(), 3 * n);
  ASSERT_EQ(host_rgb.size(), 3 * n);
  ASSERT_EQ(over_bound.size(), n);
  fs::create_directories(dir);
  nlohmann::json j = meta;
  j["width"] = w;
  j["height"] = h;
  std::ofstream(fs::path(dir) / (name + ".json")) << j.dump(2) << "\n";
  std::ofstream out(fs::path(dir) / (name + ".f32"), std::ios::binary);
  for (const auto* v : {&gl_rgb, &host_rgb, &over_bound})
    out.write(reinterpret_cast<const char*>(v->data()), static_cast<std::streamsize>(v->size() * sizeof(float)));
}

}  // namespace specbake::testing
