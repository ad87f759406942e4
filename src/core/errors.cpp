#include "core/errors.hpp"

namespace specbake {

std::string Location::str() const {
  std::string s = file.string();
  if (line > 0) {
    s += ":" + std::to_string(line);
    if (column > 0) s += ":" + std::to_string(column);
  }
  if (!key.empty()) s += (s.empty() ? "" : ": ") + key;
  return s;
}

InputError::InputError(Location where, const std::string& what_expected)
    : Error(where.str() + ": " + what_expected), where_(std::move(where)) {}

}  // namespace specbake
