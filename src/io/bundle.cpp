#include "io/bundle.hpp"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <signal.h>
#include <stdio.h>
#include <unistd.h>

#include <algorithm>
#include <bit>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <map>
#include <optional>
#include <set>
#include <limits>

#include <spdlog/spdlog.h>

#include "core/errors.hpp"
#include "core/hash.hpp"
#include "core/parallel.hpp"
#include "io/result_store.hpp"

namespace specbake {

static_assert(std::endian::native == std::endian::little, "bundle .bin files are written as little-endian");
static_assert(sizeof(float) == 4 && std::numeric_limits<float>::is_iec559, "float32 must be IEEE 754 binary32");

namespace {
template <class T>
std::string float32_le_of(const std::vector<T>& values, const std::string& what) {
  std::string out(values.size() * sizeof(float), '\0');
  for (std::size_t i = 0; i < values.size(); ++i) {
    const float f = static_cast<float>(values[i]);
    if (!std::isfinite(f))
      throw JobError(what + ": non-finite value " + std::to_string(values[i]) + " at flat index " + std::to_string(i));
    std::memcpy(out.data() + i * sizeof(float), &f, sizeof(float));
  }
  return out;
}
}  // namespace

std::string float32_le(const std::vector<double>& values, const std::string& what) {
  return float32_le_of(values, what);
}
std::string float32_le(const std::vector<float>& values, const std::string& what) {
  return float32_le_of(values, what);
}

namespace {

[[noreturn]] void io_fail(const std::string& what, const fs::path& p, int err = errno) {
  throw IoError(what + " " + p.string() + ": " + std::strerror(err));
}

void write_file_synced(const fs::path& p, std::string_view bytes) {
  const int fd = ::open(p.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) io_fail("cannot create", p);
  std::size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t w = ::write(fd, bytes.data() + done, bytes.size() - done);
    if (w < 0) {
      if (errno == EINTR) continue;
      const int err = errno;
      ::close(fd);
      io_fail("cannot write", p, err);
    }
    done += static_cast<std::size_t>(w);
  }
  if (::fsync(fd) != 0) {
    const int err = errno;
    ::close(fd);
    io_fail("cannot flush", p, err);
  }
  if (::close(fd) != 0) io_fail("cannot close", p);
}

void sync_dir(const fs::path& p) {
  const int fd = ::open(p.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd >= 0) {
    ::fsync(fd);
    ::close(fd);
  }
}

void make_dirs(const fs::path& p) {
  std::error_code ec;
  fs::create_directories(p, ec);
  if (ec) throw IoError("cannot create folder " + p.string() + ": " + ec.message());
}

}  // namespace

void BundleStore::check_writable() const {
  make_dirs(root_);
  const fs::path probe = root_ / (".write-test-" + std::to_string(::getpid()));
  const int fd = ::open(probe.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
  if (fd < 0) io_fail("output folder is not writable:", root_);
  ::close(fd);
  ::unlink(probe.c_str());
}

bool BundleStore::is_complete(const std::string& job, const std::string& hash12) const {
  const fs::path dir = bundle_dir(job, hash12);
  std::ifstream in(dir / "manifest.json");
  if (!in) return false;
  try {
    const auto m = nlohmann::json::parse(in);
    for (const auto& f : m.at("files")) {
      std::error_code ec;
      const auto size = fs::file_size(dir / f.at("path").get<std::string>(), ec);
      if (ec || size != f.at("bytes").get<std::uintmax_t>()) return false;
    }
    return true;
  } catch (const std::exception&) {
    return false;
  }
}

void BundleStore::set_latest(const std::string& job, const std::string& hash12) const {
  const fs::path dir = job_dir(job);
  const fs::path tmp = dir / (".latest-" + std::to_string(::getpid()));
  std::error_code ec;
  fs::remove(tmp, ec);
  if (::symlink(hash12.c_str(), tmp.c_str()) != 0) io_fail("cannot create link", tmp);
  if (::rename(tmp.c_str(), (dir / "latest").c_str()) != 0) io_fail("cannot update", dir / "latest");
  sync_dir(dir);
}

bool JobLock::held_by_live_process(const fs::path& job_dir) {
  const int fd = ::open((job_dir / ".lock").c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return false;
  const bool held = ::flock(fd, LOCK_SH | LOCK_NB) != 0 && errno == EWOULDBLOCK;
  ::close(fd);
  return held;
}

JobLock::JobLock(const fs::path& job_dir, const std::string& job, bool wait) {
  make_dirs(job_dir);
  const fs::path p = job_dir / ".lock";
  path_ = p;
  bool waited = false;
  for (;;) {
    fd_ = ::open(p.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
    if (fd_ < 0) io_fail("cannot open lock", p);
    if (::flock(fd_, LOCK_EX | LOCK_NB) != 0) {
      if (!wait) {
        ::close(fd_);
        fd_ = -1;
        return;
      }
      if (!waited) spdlog::info("{}: another run holds {}; waiting for it", job, p.string());
      waited = true;
      while (::flock(fd_, LOCK_EX) != 0)
        if (errno != EINTR) io_fail("cannot lock", p);
    }
    // The holder removes the file when it lets go: a lock taken on a file that is no longer
    // at the path guards nothing, so take the one that is there now.
    struct stat held {}, now {};
    if (::fstat(fd_, &held) == 0 && ::stat(p.c_str(), &now) == 0 && held.st_ino == now.st_ino &&
        held.st_dev == now.st_dev)
      break;
    ::close(fd_);
    fd_ = -1;
  }
  const std::string pid = std::to_string(::getpid()) + "\n";
  if (::ftruncate(fd_, 0) == 0 && ::write(fd_, pid.data(), pid.size()) < 0) {
    // the pid is for people looking at the file; the lock does not need it
  }
}

JobLock::~JobLock() {
  if (fd_ < 0) return;
  ::unlink(path_.c_str());  // while still holding it: no one can take the removed file after us
  ::close(fd_);             // releases the lock
}

void BundleStore::clean_stale(const std::string& job) const {
  std::error_code ec;
  const fs::path dir = job_dir(job);
  if (!fs::is_directory(dir, ec)) return;
  for (const auto& e : fs::directory_iterator(dir, ec)) {
    const std::string name = e.path().filename().string();
    if (name.rfind(".tmp-", 0) != 0 && name.rfind(".latest-", 0) != 0) continue;
    spdlog::info("removing {} left by an interrupted run", e.path().string());
    fs::remove_all(e.path(), ec);
  }
}

GcResult BundleStore::gc(int keep, bool dry_run) const {
  GcResult out;
  const fs::file_time_type started = fs::file_time_type::clock::now();
  std::error_code ec;
  if (!fs::is_directory(root_, ec)) throw IoError("no output folder " + root_.string());
  // a job or bundle folder given for the output folder above it would prune nothing: say so
  const fs::path above = fs::absolute(root_).lexically_normal().parent_path();
  if (fs::exists(root_ / "latest", ec) || fs::is_symlink(root_ / "latest", ec))
    throw UsageError(root_.string() + " is a job folder (it holds `latest`); gc takes the output folder that holds "
                     "the job folders: " + above.string());
  if (fs::exists(root_ / "manifest.json", ec))
    throw UsageError(root_.string() + " is a bundle folder; gc takes the output folder that holds the job folders: " +
                     above.parent_path().string());
  std::vector<fs::path> jobs;
  for (const auto& job : fs::directory_iterator(root_, ec))
    if (job.is_directory() && !job.is_symlink() && job.path().filename().string().front() != '.') jobs.push_back(job.path());
  std::sort(jobs.begin(), jobs.end());
  std::set<std::string> listed;  // kept results some remaining bundle lists
  for (const auto& job : jobs) {
    const std::string name = job.filename().string();
    // A job a live run holds is left alone (not waited for); a lock whose holder died is free.
    std::optional<JobLock> lock;
    if (!dry_run) {
      if (fs::exists(job / ".lock", ec) && !JobLock::held_by_live_process(job))
        out.temporaries.push_back(job / ".lock");  // its holder died; released (removed) below
      lock.emplace(job, name, false);
      if (!lock->held()) {
        out.busy.push_back(job);
        continue;
      }
    } else if (JobLock::held_by_live_process(job)) {
      out.busy.push_back(job);
      continue;
    }
    fs::path latest;
    if (fs::is_symlink(job / "latest", ec)) latest = fs::read_symlink(job / "latest", ec);
    std::vector<std::pair<std::string, fs::path>> bundles;  // (created, dir)
    std::map<fs::path, std::vector<std::string>> lists;      // dir -> its manifest's results_kept
    for (const auto& b : fs::directory_iterator(job, ec)) {
      const std::string entry = b.path().filename().string();
      if (entry.rfind(".tmp-", 0) == 0 || entry.rfind(".latest-", 0) == 0) {
        out.temporaries.push_back(b.path());  // left by an interrupted run: no live run holds the job
        continue;
      }
      if (entry == ".lock" && dry_run) {
        out.temporaries.push_back(b.path());  // a lock file no live process holds
        continue;
      }
      if (!b.is_directory() || b.is_symlink() || entry.front() == '.') continue;
      std::string created;
      try {
        std::ifstream in(b.path() / "manifest.json");
        const nlohmann::json m = nlohmann::json::parse(in);
        created = m.value("created_utc", "");
        if (m.contains("results_kept")) lists[b.path()] = m["results_kept"].get<std::vector<std::string>>();
      } catch (const std::exception&) {
        continue;  // not a bundle: leave it alone
      }
      bundles.emplace_back(created, b.path());
    }
    // The `keep` newest (ties by name) and `latest`, wherever it is in that order.
    std::sort(bundles.begin(), bundles.end(), [](const auto& a, const auto& b) { return a > b; });
    int kept = 0;
    for (const auto& [created, dir] : bundles) {
      if (dir.filename() == latest.filename() || kept < keep) {
        ++kept;
        for (const auto& r : lists[dir]) listed.insert(r);
        continue;
      }
      out.bundles.push_back(dir);
    }
    if (dry_run) continue;
    for (const auto& p : out.temporaries)
      if (p.parent_path() == job && p.filename() != ".lock") fs::remove_all(p, ec);
    for (const auto& dir : out.bundles)
      if (dir.parent_path() == job) {
        spdlog::info("gc: removing {}", dir.string());
        fs::remove_all(dir, ec);
        if (ec) throw IoError("cannot remove " + dir.string() + ": " + ec.message());
      }
    lock.reset();         // removes the lock file
    fs::remove(job, ec);  // a job folder nothing is left in
  }
  // Kept results (io/result_store.hpp) that no remaining bundle lists (the manifest key
  // `results_kept` the runner writes), and temporary files of writers that died. None while a
  // run holds a job (it may be about to list what it kept), and none written since gc began (by
  // a run that took a job after gc had passed it).
  const fs::path results = results_dir(root_);
  if (out.busy.empty() && fs::is_directory(results, ec)) {
    std::vector<fs::path> unlisted;
    for (const auto& e : fs::directory_iterator(results, ec)) {
      const std::string entry = e.path().filename().string();
      if (entry.rfind(".tmp-", 0) == 0) {
        const std::string pid = entry.substr(entry.rfind('-') + 1);
        const long p = std::strtol(pid.c_str(), nullptr, 10);
        if (p <= 0 || (::kill(static_cast<pid_t>(p), 0) != 0 && errno == ESRCH)) out.temporaries.push_back(e.path());
      } else if (e.is_regular_file() && !listed.count(entry) && fs::last_write_time(e.path(), ec) < started && !ec) {
        unlisted.push_back(e.path());
      }
    }
    std::sort(unlisted.begin(), unlisted.end());
    for (const auto& f : unlisted) out.results.push_back(f);
    if (!dry_run)
      for (const auto& f : out.temporaries)
        if (f.parent_path() == results) fs::remove(f, ec);
    if (!dry_run)
      for (const auto& f : out.results) {
        fs::remove(f, ec);
        if (ec) throw IoError("cannot remove " + f.string() + ": " + ec.message());
      }
  }
  return out;
}

fs::path BundleStore::publish(const std::string& job, const std::string& hash12, nlohmann::json manifest,
                              const std::vector<OutputFile>& files) const {
  const fs::path dir = job_dir(job);
  make_dirs(dir);
  const std::string pid = std::to_string(::getpid());
  const fs::path tmp = dir / (".tmp-" + hash12 + "-" + pid);
  std::error_code ec;
  fs::remove_all(tmp, ec);
  make_dirs(tmp);
  try {
    // The files are written (and synced) and hashed on the hardware threads, one file each; the
    // list keeps the jobs' order.
    for (const auto& f : files) make_dirs((tmp / f.path).parent_path());
    std::vector<std::string> sha(files.size());
    parallel_for(static_cast<long long>(files.size()), [&](long long i) {
      const OutputFile& f = files[static_cast<std::size_t>(i)];
      write_file_synced(tmp / f.path, f.bytes);
      sha[static_cast<std::size_t>(i)] = sha256_hex(f.bytes);
    });
    nlohmann::json list = nlohmann::json::array();
    for (std::size_t i = 0; i < files.size(); ++i) {
      const OutputFile& f = files[i];
      nlohmann::json entry = {{"path", f.path}, {"sha256", sha[i]}, {"bytes", f.bytes.size()}};
      if (!f.dtype.empty()) entry["dtype"] = f.dtype;
      if (!f.shape.empty()) entry["shape"] = f.shape;
      if (!f.layout.empty()) entry["layout"] = f.layout;
      if (!f.units.empty()) entry["units"] = f.units;
      if (!f.description.empty()) entry["description"] = f.description;
      list.push_back(entry);
    }
    manifest["files"] = list;
    write_file_synced(tmp / "manifest.json", manifest.dump(2) + "\n");
    sync_dir(tmp);

    const fs::path final_dir = bundle_dir(job, hash12);
    if (fs::exists(final_dir, ec)) {
      // Rebuild (--force): swap atomically so a reader always sees one complete bundle.
      if (::renameat2(AT_FDCWD, tmp.c_str(), AT_FDCWD, final_dir.c_str(), RENAME_EXCHANGE) != 0)
        io_fail("cannot replace", final_dir);
      fs::remove_all(tmp, ec);  // now holds the previous bundle
    } else if (::rename(tmp.c_str(), final_dir.c_str()) != 0) {
      io_fail("cannot publish", final_dir);
    }
    sync_dir(dir);
    set_latest(job, hash12);
    return final_dir;
  } catch (...) {
    fs::remove_all(tmp, ec);
    throw;
  }
}

}  // namespace specbake
