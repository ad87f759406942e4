#pragma once
// A YAML node together with the key path that reached it, so that every error a config parser
// raises names file, line, column and key, and says what was expected. Used by the config
// loader and by each kind's parser.
#include <yaml-cpp/yaml.h>

#include <cmath>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include <filesystem>

#include "core/errors.hpp"

namespace specbake {

// The closest of `candidates` to `word`, or "" (core/config.cpp).
std::string closest_word(const std::string& word, const std::vector<std::string>& candidates);

namespace yaml {

namespace fs = std::filesystem;

// A YAML node with the path used to reach it, so errors name file, line, column and key.
struct At {
  YAML::Node node;
  std::string key;
  const fs::path* file;

  Location loc() const {
    const auto m = node.Mark();
    Location l{*file, 0, 0, key};
    if (m.line >= 0) {
      l.line = m.line + 1;
      l.column = m.column + 1;
    }
    return l;
  }
  [[noreturn]] void fail(const std::string& expected) const { throw InputError(loc(), expected); }

  std::string shown() const {
    if (node.IsScalar()) return "'" + node.Scalar() + "'";
    if (node.IsSequence()) return "a list";
    if (node.IsMap()) return "a mapping";
    return "nothing";
  }

  At child(const std::string& k) const { return {node[k], key.empty() ? k : key + "." + k, file}; }
  At item(std::size_t i) const { return {node[i], key + "[" + std::to_string(i) + "]", file}; }
  bool has(const std::string& k) const { return node.IsMap() && node[k]; }

  // Each item of a non-empty list, in order; fails naming `what` (e.g. "layouts (3d, tiled2d)")
  // when this is not one.
  template <class F>
  void each_item(const std::string& what, F&& on_item) const {
    if (!node.IsSequence() || node.size() == 0) fail("expected a non-empty list of " + what);
    for (std::size_t i = 0; i < node.size(); ++i) on_item(item(i));
  }

  void expect_map(const char* what) const {
    if (!node.IsMap()) fail(std::string("expected ") + what + " (a mapping), got " + shown());
  }
  // Rejects unknown and duplicate keys.
  void allow_keys(std::initializer_list<const char*> allowed) const {
    allow_keys(std::vector<std::string>(allowed.begin(), allowed.end()));
  }
  void allow_keys(const std::vector<std::string>& names) const {
    std::set<std::string> seen;
    for (auto it = node.begin(); it != node.end(); ++it) {
      const std::string k = it->first.Scalar();
      At key_at{it->first, key.empty() ? k : key + "." + k, file};
      if (!seen.insert(k).second) key_at.fail("duplicate key '" + k + "'");
      bool ok = false;
      std::string list;
      for (const std::string& a : names) {
        ok = ok || k == a;
        list += (list.empty() ? "" : ", ") + a;
      }
      if (!ok) {
        const std::string near = closest_word(k, names);
        key_at.fail("unknown key '" + k + "'" + (near.empty() ? "" : " (did you mean '" + near + "'?)") +
                    "; expected one of: " + list);
      }
    }
  }

  double number() const {
    if (!node.IsScalar()) fail("expected a number, got " + shown());
    try {
      const double v = node.as<double>();
      if (!std::isfinite(v)) fail("expected a finite number, got " + shown());
      return v;
    } catch (const YAML::Exception&) {
      fail("expected a number, got " + shown());
    }
  }
  double number_in(double lo, double hi, const char* range_text) const {
    const double v = number();
    if (!(v >= lo && v <= hi)) fail(std::string("expected a number ") + range_text + ", got " + shown());
    return v;
  }
  double positive() const {
    const double v = number();
    if (!(v > 0)) fail("expected a number > 0, got " + shown());
    return v;
  }
  long long integer() const {
    if (!node.IsScalar()) fail("expected an integer, got " + shown());
    try {
      return node.as<long long>();
    } catch (const YAML::Exception&) {
      fail("expected an integer, got " + shown());
    }
  }
  // An integer in [lo, hi], or the word `auto` (then nullopt).
  std::optional<int> count_or_auto(long long lo, long long hi) const {
    const std::string expected = "expected an integer in [" + std::to_string(lo) + ", " + std::to_string(hi) + "] or 'auto', got ";
    if (!node.IsScalar()) fail(expected + shown());
    if (node.Scalar() == "auto") return std::nullopt;
    long long n = 0;
    try {
      n = node.as<long long>();
    } catch (const YAML::Exception&) {
      fail(expected + shown());
    }
    if (n < lo || n > hi) fail(expected + shown());
    return static_cast<int>(n);
  }
  std::string string() const {
    if (!node.IsScalar()) fail("expected a string, got " + shown());
    return node.Scalar();
  }
  template <class E>
  E choice(std::initializer_list<std::pair<const char*, E>> options) const {
    const std::string s = node.IsScalar() ? node.Scalar() : "";
    std::string list;
    std::vector<std::string> names;
    for (auto& [name, value] : options) {
      if (s == name) return value;
      list += std::string(list.empty() ? "" : " | ") + name;
      names.emplace_back(name);
    }
    const std::string near = s.empty() ? "" : closest_word(s, names);
    fail("expected one of " + list + ", got " + shown() + (near.empty() ? "" : " (did you mean '" + near + "'?)"));
  }
  std::vector<double> numbers(std::size_t min_len, std::size_t max_len) const {
    if (!node.IsSequence()) fail("expected a list of numbers, got " + shown());
    if (node.size() < min_len || node.size() > max_len) {
      fail(min_len == max_len ? "expected a list of " + std::to_string(min_len) + " numbers"
                              : "expected a list of " + std::to_string(min_len) + " to " +
                                    std::to_string(max_len) + " numbers");
    }
    std::vector<double> out;
    for (std::size_t i = 0; i < node.size(); ++i) out.push_back(item(i).number());
    return out;
  }
};


}  // namespace yaml
}  // namespace specbake
