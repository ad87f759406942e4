#pragma once
// Minimal reader for NumPy .npy files (format 1.x/2.x): little-endian float64 or float32,
// C order. Enough for the reference data in refdata/atmosphere.
#include <cstdint>
#include <cstring>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace specbake::testing {

struct Npy {
  std::vector<std::int64_t> shape;
  std::vector<double> data;
  std::int64_t size() const {
    std::int64_t n = 1;
    for (auto s : shape) n *= s;
    return n;
  }
};

inline Npy read_npy(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  if (!f) throw std::runtime_error("cannot open " + path);
  std::string bytes((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  if (bytes.size() < 10 || bytes.compare(0, 6, "\x93NUMPY") != 0) throw std::runtime_error(path + ": not a .npy file");
  const int major = static_cast<unsigned char>(bytes[6]);
  std::size_t header_len, offset;
  if (major == 1) {
    header_len = static_cast<unsigned char>(bytes[8]) | (static_cast<unsigned char>(bytes[9]) << 8);
    offset = 10;
  } else {
    std::uint32_t h;
    std::memcpy(&h, bytes.data() + 8, 4);
    header_len = h;
    offset = 12;
  }
  const std::string header = bytes.substr(offset, header_len);
  auto field = [&](const std::string& key) {
    const auto p = header.find("'" + key + "'");
    if (p == std::string::npos) throw std::runtime_error(path + ": header lacks " + key);
    return header.substr(header.find(':', p) + 1);
  };
  const std::string descr = field("descr");
  const bool f8 = descr.find("<f8") != std::string::npos, f4 = descr.find("<f4") != std::string::npos;
  if (!f8 && !f4) throw std::runtime_error(path + ": expected <f8 or <f4, header " + header);
  if (field("fortran_order").find("False") == std::string::npos) throw std::runtime_error(path + ": not C order");
  Npy out;
  const std::string sh = field("shape");
  const std::string inner = sh.substr(sh.find('(') + 1, sh.find(')') - sh.find('(') - 1);
  std::stringstream ss(inner);
  std::string tok;
  while (std::getline(ss, tok, ','))
    if (tok.find_first_of("0123456789") != std::string::npos) out.shape.push_back(std::stoll(tok));
  const std::size_t n = static_cast<std::size_t>(out.size());
  const char* p = bytes.data() + offset + header_len;
  if (bytes.size() < offset + header_len + n * (f8 ? 8 : 4)) throw std::runtime_error(path + ": truncated");
  out.data.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    if (f8) {
      std::memcpy(&out.data[i], p + 8 * i, 8);
    } else {
      float v;
      std::memcpy(&v, p + 4 * i, 4);
      out.data[i] = v;
    }
  }
  return out;
}

// Rows of a reference CSV ('#' comment lines, then a header row), by column name.
struct Csv {
  std::vector<std::string> columns;
  std::vector<std::vector<double>> rows;
  int col(const std::string& name) const {
    for (std::size_t i = 0; i < columns.size(); ++i)
      if (columns[i] == name) return static_cast<int>(i);
    throw std::runtime_error("no column " + name);
  }
};

inline Csv read_csv(const std::string& path) {
  std::ifstream f(path);
  if (!f) throw std::runtime_error("cannot open " + path);
  Csv c;
  std::string line;
  while (std::getline(f, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::vector<std::string> fields;
    std::stringstream ss(line);
    std::string tok;
    while (std::getline(ss, tok, ',')) fields.push_back(tok);
    if (c.columns.empty()) {
      c.columns = fields;
    } else {
      std::vector<double> row;
      for (auto& t : fields) row.push_back(std::stod(t));
      c.rows.push_back(row);
    }
  }
  return c;
}

}  // namespace specbake::testing
