// The store of kept results (src/io/result_store.hpp): what is put under a key is what a read
// of that key gives, byte for byte; an entry under another key's name, a truncated, damaged or
// foreign file, and a read-only store's put give nothing, never wrong bytes.
#include <gtest/gtest.h>

#include <string>

#include "io/result_store.hpp"
#include "support/testing.hpp"

using namespace specbake;
namespace t = specbake::testing;

namespace {

std::string some_bytes() {
  std::string b;
  for (int i = 0; i < 100000; ++i) b.push_back(static_cast<char>((i * 7919) % 251));
  b.push_back('\0');  // binary: NUL bytes included
  return b;
}

TEST(ResultStore, WhatIsPutIsWhatIsRead) {
  t::TempDir dir;
  const ResultStore store(dir / "r");
  EXPECT_FALSE(store.get("a").has_value());  // nothing yet (and no folder)
  const std::string bytes = some_bytes();
  ASSERT_TRUE(store.put("a", bytes));
  const auto back = store.get("a");
  ASSERT_TRUE(back.has_value());
  EXPECT_EQ(*back, bytes);
  EXPECT_FALSE(store.get("b").has_value());
  EXPECT_TRUE(std::filesystem::is_regular_file(dir / "r" / ResultStore::name_of("a")));
  EXPECT_EQ(ResultStore::name_of("a").size(), 32u + 4u);  // 32 hex digits and ".zst"
  // a put replaces the entry whole
  ASSERT_TRUE(store.put("a", "short"));
  EXPECT_EQ(store.get("a").value_or(""), "short");
}

TEST(ResultStore, AnythingButAWholeEntryOfTheKeyIsAMiss) {
  t::TempDir dir;
  const ResultStore store(dir / "r");
  ASSERT_TRUE(store.put("a", some_bytes()));
  const auto file_a = dir / "r" / ResultStore::name_of("a"), file_b = dir / "r" / ResultStore::name_of("b");
  const std::string whole = t::read_file(file_a);
  // a's entry under b's name: b's read compares the stored key
  t::write_file(file_b, whole);
  EXPECT_FALSE(store.get("b").has_value());
  // truncated, one byte flipped anywhere in the frame (header, data or checksum), not zstd, empty
  t::write_file(file_a, whole.substr(0, whole.size() / 2));
  EXPECT_FALSE(store.get("a").has_value());
  for (std::size_t at : {std::size_t{5}, whole.size() / 2, whole.size() - 1}) {
    std::string damaged = whole;
    damaged[at] = static_cast<char>(damaged[at] ^ 0x20);
    t::write_file(file_a, damaged);
    EXPECT_FALSE(store.get("a").has_value()) << at;
  }
  t::write_file(file_a, "not an entry");
  EXPECT_FALSE(store.get("a").has_value());
  t::write_file(file_a, "");
  EXPECT_FALSE(store.get("a").has_value());
  // put again: whole once more
  ASSERT_TRUE(store.put("a", "x"));
  EXPECT_EQ(store.get("a").value_or(""), "x");
}

TEST(ResultStore, AReadOnlyStoreWritesNothing) {
  t::TempDir dir;
  const ResultStore store(dir / "r", /*writable=*/false);
  EXPECT_FALSE(store.put("a", "bytes"));
  EXPECT_FALSE(std::filesystem::exists(dir / "r"));
  const ResultStore writer(dir / "r");
  ASSERT_TRUE(writer.put("a", "bytes"));
  EXPECT_EQ(store.get("a").value_or(""), "bytes");  // it reads what others kept
}

}  // namespace
