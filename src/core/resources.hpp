#pragma once
// Files compiled into the binary (kernels/ and data/), looked up by their path
// relative to the repository root, so specbake runs from any directory.
#include <cstddef>
#include <string>
#include <string_view>
#include <vector>

namespace specbake {

namespace resources_detail {
struct Entry {
  const char* path;
  std::string_view bytes;
};
extern const Entry kEntries[];
extern const std::size_t kEntryCount;
}  // namespace resources_detail

// The embedded file's bytes; throws std::out_of_range naming the path if absent.
std::string_view resource(std::string_view path);
bool has_resource(std::string_view path);
std::vector<std::string> resource_paths(std::string_view prefix);

// An OpenCL program source with every `#include "path"` (relative to kernels/)
// replaced by the embedded file, each wrapped in #line directives so that build
// logs name the original file and line. Each file is included once.
std::string kernel_source(std::string_view path);

}  // namespace specbake
