#include "core/errors.hpp"

#include <sstream>

namespace specbake {

std::string Location::str() const {
  std::ostringstream s;
  s << file.string();
  if (line > 0) {
    s << ':' << line;
    if (column > 0) s << ':' << column;
  }
  if (!key.empty()) s << (file.empty() && line == 0 ? "" : ": ") << key;
  return s.str();
}

InputError::InputError(Location where, const std::string& what_expected)
    : Error(where.str() + ": " + what_expected), where_(std::move(where)) {}

}  // namespace specbake
