#pragma once
// SHA-256 (OpenSSL EVP), hex encoded.
#include <filesystem>
#include <string>
#include <string_view>

namespace specbake {

class Sha256 {
 public:
  Sha256();
  ~Sha256();
  Sha256(const Sha256&) = delete;
  Sha256& operator=(const Sha256&) = delete;
  Sha256& update(std::string_view bytes);
  Sha256& update(const void* data, std::size_t size);
  std::string hex();  // finalises
 private:
  void* ctx_;
};

std::string sha256_hex(std::string_view bytes);
std::string sha256_file(const std::filesystem::path& path);  // throws IoError

}  // namespace specbake
