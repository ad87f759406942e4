#include "io/result_store.hpp"

#include <fcntl.h>
#include <unistd.h>
#include <zstd.h>

#include <cstdint>
#include <fstream>
#include <memory>
#include <vector>

#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include "core/hash.hpp"

namespace specbake {

namespace {

using json = nlohmann::json;

// Compression level: the entries are small (a scene's truth: ~0.1–2 MB of doubles); speed over ratio.
constexpr int kLevel = 3;
// What a read accepts: no entry is near 1 GiB, and doubles do not compress 4096-fold.
constexpr std::uintmax_t kMaxBytes = std::uintmax_t{1} << 30;
constexpr unsigned long long kMaxRatio = 4096;

}  // namespace

std::string ResultStore::name_of(std::string_view key) { return sha256_hex(key).substr(0, 32) + ".zst"; }

bool ResultStore::has(std::string_view key) const {
  std::error_code ec;
  return fs::is_regular_file(dir_ / name_of(key), ec);
}

std::optional<std::string> ResultStore::get(std::string_view key) const {
  const fs::path file = dir_ / name_of(key);
  std::error_code ec;
  if (!fs::is_regular_file(file, ec)) return std::nullopt;
  auto miss = [&](const std::string& why) -> std::optional<std::string> {
    spdlog::warn("{}: not used ({}); computing it again", file.string(), why);
    return std::nullopt;
  };
  try {
    const std::uintmax_t packed_size = fs::file_size(file);
    if (packed_size > kMaxBytes) return miss("larger than any kept result");
    std::string packed(packed_size, '\0');
    std::ifstream in(file, std::ios::binary);
    in.read(packed.data(), static_cast<std::streamsize>(packed.size()));
    if (!in || static_cast<std::uintmax_t>(in.gcount()) != packed_size) return miss("unreadable");
    // The frame's header says how large the content is; a damaged header is refused before
    // anything that large is allocated (the checksum is only checked while decompressing).
    const unsigned long long size = ZSTD_getFrameContentSize(packed.data(), packed.size());
    if (size == ZSTD_CONTENTSIZE_ERROR || size == ZSTD_CONTENTSIZE_UNKNOWN) return miss("not a Zstandard frame of known size");
    if (size > kMaxBytes || size > kMaxRatio * packed_size + 65536) return miss("damaged: implausible content size");
    std::vector<std::uint8_t> raw(size);
    const std::size_t n = ZSTD_decompress(raw.data(), raw.size(), packed.data(), packed.size());
    if (ZSTD_isError(n) || n != size) return miss(std::string("damaged: ") + (ZSTD_isError(n) ? ZSTD_getErrorName(n) : "short"));
    const json entry = json::from_cbor(raw);
    if (entry.at("key").get<std::string>() != key) return miss("kept for another key");
    const auto& bytes = entry.at("value").get_binary();
    spdlog::debug("{}: reused", file.string());
    return std::string(bytes.begin(), bytes.end());
  } catch (const std::exception& e) {
    return miss(std::string("damaged: ") + e.what());
  }
}

bool ResultStore::put(std::string_view key, std::string_view bytes) const {
  if (!writable_) return false;
  const fs::path file = dir_ / name_of(key);
  const fs::path tmp = dir_ / (".tmp-" + file.filename().string() + "-" + std::to_string(::getpid()));
  try {
    json entry = {{"key", key}, {"value", json::binary(std::vector<std::uint8_t>(bytes.begin(), bytes.end()))}};
    const std::vector<std::uint8_t> raw = json::to_cbor(entry);
    std::unique_ptr<ZSTD_CCtx, decltype(&ZSTD_freeCCtx)> cctx(ZSTD_createCCtx(), &ZSTD_freeCCtx);
    if (!cctx) throw std::runtime_error("out of memory");
    ZSTD_CCtx_setParameter(cctx.get(), ZSTD_c_compressionLevel, kLevel);
    ZSTD_CCtx_setParameter(cctx.get(), ZSTD_c_checksumFlag, 1);  // a damaged file is detected on read
    std::string packed(ZSTD_compressBound(raw.size()), '\0');
    const std::size_t n = ZSTD_compress2(cctx.get(), packed.data(), packed.size(), raw.data(), raw.size());
    if (ZSTD_isError(n)) throw std::runtime_error(ZSTD_getErrorName(n));
    packed.resize(n);
    fs::create_directories(dir_);
    {
      std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
      out.write(packed.data(), static_cast<std::streamsize>(packed.size()));
      out.close();
      if (!out) throw std::runtime_error("cannot write " + tmp.string());
    }
    // on disk before it is renamed into place: after a crash the name holds a whole entry or none
    const int fd = ::open(tmp.c_str(), O_RDONLY | O_CLOEXEC);
    const bool synced = fd >= 0 && ::fsync(fd) == 0;
    if (fd >= 0) ::close(fd);
    if (!synced) throw std::runtime_error("cannot sync " + tmp.string());
    fs::rename(tmp, file);
    return true;
  } catch (const std::exception& e) {
    std::error_code ec;
    fs::remove(tmp, ec);
    spdlog::warn("{}: not kept for later runs: {}", file.string(), e.what());
    return false;
  }
}

}  // namespace specbake
