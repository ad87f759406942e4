#pragma once
// Results kept on disk between runs, for work a bake can reuse when nothing it depends on has
// changed (the atmosphere's path-traced scene does not depend on texture sizes or on a --force):
//   <output>/.results/<name>.zst     one result: Zstandard (with its content checksum) of CBOR
//                                    {"key": the full key, "value": the bytes}
// <name> is the first 32 hex digits of SHA-256(key). The caller's key names everything the
// bytes depend on (inputs, the programs' sources, the device, the tool's version); a read
// compares the stored key with it, so a colliding name or a damaged file is a miss (logged),
// never a wrong result. Writes go to a temporary file, synced and renamed into place, so a
// reader sees a whole entry or none. The store knows nothing of what the bytes mean.
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>

namespace specbake {

namespace fs = std::filesystem;

class ResultStore {
 public:
  // writable = false: get() only; put() does nothing (`plan` reads what earlier runs kept).
  explicit ResultStore(fs::path dir, bool writable = true) : dir_(std::move(dir)), writable_(writable) {}
  const fs::path& dir() const { return dir_; }
  // The entry's file name for a key ("<32 hex>.zst").
  static std::string name_of(std::string_view key);
  // The bytes kept under `key`, or nothing (absent, unreadable, damaged, or another key).
  std::optional<std::string> get(std::string_view key) const;
  // Whether an entry for `key` is there (it may still turn out unreadable: get() says).
  bool has(std::string_view key) const;
  // Keeps `bytes` under `key`. A failure to write is logged and returns false: the result is
  // only not kept for later runs.
  bool put(std::string_view key, std::string_view bytes) const;

 private:
  fs::path dir_;
  bool writable_;
};

// The output root's store.
inline fs::path results_dir(const fs::path& output_root) { return output_root / ".results"; }

}  // namespace specbake
