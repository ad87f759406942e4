#include "core/resources.hpp"

#include <regex>
#include <set>
#include <sstream>
#include <stdexcept>

namespace specbake {

using resources_detail::kEntries;
using resources_detail::kEntryCount;

std::string_view resource(std::string_view path) {
  for (std::size_t i = 0; i < kEntryCount; ++i)
    if (path == kEntries[i].path) return kEntries[i].bytes;
  throw std::out_of_range("no embedded resource '" + std::string(path) + "'");
}

bool has_resource(std::string_view path) {
  for (std::size_t i = 0; i < kEntryCount; ++i)
    if (path == kEntries[i].path) return true;
  return false;
}

std::vector<std::string> resource_paths(std::string_view prefix) {
  std::vector<std::string> out;
  for (std::size_t i = 0; i < kEntryCount; ++i) {
    std::string_view p = kEntries[i].path;
    if (p.substr(0, prefix.size()) == prefix) out.emplace_back(p);
  }
  return out;
}

namespace {
void expand(const std::string& path, std::set<std::string>& seen, std::ostringstream& out) {
  if (!seen.insert(path).second) return;
  static const std::regex include_re(R"re(^\s*#\s*include\s+"([^"]+)"\s*$)re");
  std::istringstream in{std::string(resource(path))};
  std::string line;
  int line_no = 0;
  out << "#line 1 \"" << path << "\"\n";
  while (std::getline(in, line)) {
    ++line_no;
    std::smatch m;
    if (std::regex_match(line, m, include_re)) {
      expand("kernels/" + m[1].str(), seen, out);
      out << "#line " << line_no + 1 << " \"" << path << "\"\n";
    } else {
      out << line << '\n';
    }
  }
}
}  // namespace

std::string kernel_source(std::string_view path) {
  std::set<std::string> seen;
  std::ostringstream out;
  expand(std::string(path), seen, out);
  return out.str();
}

}  // namespace specbake
