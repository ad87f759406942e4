#pragma once
// Versioned bundles on disk:
//   <output>/<job>/<hash12>/manifest.json + files     one complete bake
//   <output>/<job>/latest -> <hash12>                 the newest complete bundle (symlink)
//   <output>/.results/                                results bakes reuse (io/result_store.hpp)
// A bundle is written into <output>/<job>/.tmp-<hash12>-<pid>, fsynced, and renamed into
// place; `latest` is replaced last by an atomic rename. A killed run leaves at most a
// stale .tmp-* folder, which the next run removes. The writer knows nothing of job kinds.
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace specbake {

namespace fs = std::filesystem;

struct OutputFile {
  std::string path;                // relative to the bundle, e.g. "matrices.bin", "preview/sky.png"
  std::string bytes;
  std::string dtype;               // "float32" for .bin, "" for text/images
  std::vector<std::int64_t> shape; // outermost first
  std::string layout;              // e.g. "[n][row][col], row-major, little-endian"
  std::string units;
  std::string description;
};

// Little-endian float32 bytes of values (rounded to nearest); throws JobError naming
// `what` and the first index if any value is not finite.
std::string float32_le(const std::vector<double>& values, const std::string& what);
std::string float32_le(const std::vector<float>& values, const std::string& what);

// An exclusive advisory lock (flock) on <output>/<job>/.lock, held while a run checks,
// bakes and publishes that job; a second run on the same output waits for it.
class JobLock {
 public:
  // wait = false: returns at once; held() says whether the lock was taken.
  JobLock(const fs::path& job_dir, const std::string& job, bool wait = true);
  bool held() const { return fd_ >= 0; }
  // Whether a live process holds the job's lock (a lock file left by a dead one is free).
  static bool held_by_live_process(const fs::path& job_dir);
  ~JobLock();
  JobLock(const JobLock&) = delete;
  JobLock& operator=(const JobLock&) = delete;

 private:
  int fd_ = -1;
  fs::path path_;
};

struct GcResult {
  std::vector<fs::path> bundles;      // old bundles removed (or that would be)
  std::vector<fs::path> temporaries;  // .tmp-*/.latest-* of interrupted runs, stale .lock files
  std::vector<fs::path> busy;         // job folders a live run holds: left alone
  std::vector<fs::path> results;      // kept results (<output>/.results) no remaining bundle lists
};

class BundleStore {
 public:
  explicit BundleStore(fs::path output_root) : root_(std::move(output_root)) {}
  const fs::path& root() const { return root_; }
  fs::path job_dir(const std::string& job) const { return root_ / job; }
  fs::path bundle_dir(const std::string& job, const std::string& hash12) const { return job_dir(job) / hash12; }

  // True when the bundle's manifest exists and every file it lists has the recorded size.
  bool is_complete(const std::string& job, const std::string& hash12) const;
  // Points `latest` at an existing bundle (atomic).
  void set_latest(const std::string& job, const std::string& hash12) const;
  // Removes .tmp-* folders and .latest-* links left by interrupted runs. Call with the job's
  // lock held: no live run can then be writing them.
  void clean_stale(const std::string& job) const;
  // Prunes bundles of every job under the root, keeping the `keep` newest (by manifest
  // creation time) and always the one `latest` points at, and removes what interrupted runs
  // left (temporary folders, lock files of dead processes). Jobs a live run holds are skipped.
  // Then the kept results (io/result_store.hpp) that no remaining bundle's manifest lists in
  // `results_kept` and that were written before gc began, unless a run holds some job. dry_run: changes nothing, returns what would be removed.
  GcResult gc(int keep, bool dry_run = false) const;
  // Writes files and manifest (the manifest's "files" list is filled in here) and
  // publishes the bundle atomically, then updates `latest`. Returns the bundle path.
  fs::path publish(const std::string& job, const std::string& hash12, nlohmann::json manifest,
                   const std::vector<OutputFile>& files) const;
  // Fails with IoError if the output root cannot be created or written.
  void check_writable() const;

 private:
  fs::path root_;
};

}  // namespace specbake
