// The truth's inputs and outputs: POINTS.csv and RESULT.csv, the scene point sets, the
// conversion to the bundle's units, and GetSkyRadiance from a bundle's textures.
#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include <spdlog/spdlog.h>

#include "io/bundle_texture.hpp"
#include "kinds/atmosphere/model/model.hpp"
#include "kinds/atmosphere/truth/truth.hpp"

namespace specbake::atmosphere {

namespace {

const char* const kColumns[4] = {"altitude_km", "view_zenith_deg", "sun_zenith_deg", "view_sun_azimuth_deg"};

std::string read_all(const fs::path& file) {
  std::ifstream in(file, std::ios::binary);
  if (!in) throw IoError("cannot read " + file.string() + ": " + std::strerror(errno));
  std::ostringstream s;
  s << in.rdbuf();
  if (in.bad()) throw IoError("cannot read " + file.string());
  return s.str();
}

std::string fmt(double v) {
  char b[40];
  std::snprintf(b, sizeof b, "%.10g", v);
  return b;
}

}  // namespace

std::vector<TruthPoint> parse_truth_points(const std::string& text, const fs::path& file) {
  std::vector<std::string> lines;
  std::size_t start = 0;
  while (start <= text.size()) {
    const std::size_t end = text.find('\n', start);
    std::string line = text.substr(start, end == std::string::npos ? std::string::npos : end - start);
    if (!line.empty() && line.back() == '\r') line.pop_back();
    lines.push_back(line);
    if (end == std::string::npos) break;
    start = end + 1;
  }
  while (!lines.empty() && lines.back().empty()) lines.pop_back();  // trailing blank lines
  if (lines.empty())
    throw InputError(Location{file, 1, 1, ""}, std::string("the header '") + kTruthPointsHeader + "'");
  const std::string header = lines[0].rfind("\xEF\xBB\xBF", 0) == 0 ? lines[0].substr(3) : lines[0];
  if (header != kTruthPointsHeader) {
    std::size_t col = 0;
    while (col < header.size() && col < std::strlen(kTruthPointsHeader) && header[col] == kTruthPointsHeader[col]) ++col;
    throw InputError(Location{file, 1, static_cast<int>(col) + 1, ""},
                     std::string("the header exactly '") + kTruthPointsHeader + "'");
  }
  std::vector<TruthPoint> points;
  for (std::size_t i = 1; i < lines.size(); ++i) {
    const std::string& line = lines[i];
    const int lineno = static_cast<int>(i) + 1;
    if (line.empty()) throw InputError(Location{file, lineno, 1, ""}, "4 numbers (blank lines only at the end)");
    double v[4];
    std::size_t pos = 0;
    for (int f = 0; f < 4; ++f) {
      const std::size_t comma = line.find(',', pos);
      const bool last = f == 3;
      if (!last && comma == std::string::npos)
        throw InputError(Location{file, lineno, static_cast<int>(line.size()) + 1, kColumns[f + 1]},
                         "4 comma-separated numbers, found " + std::to_string(f + 1));
      const std::size_t end = last ? line.size() : comma;
      if (last && comma != std::string::npos)
        throw InputError(Location{file, lineno, static_cast<int>(comma) + 1, ""},
                         "4 comma-separated numbers, found more");
      const std::string field = line.substr(pos, end - pos);
      const Location at{file, lineno, static_cast<int>(pos) + 1, kColumns[f]};
      std::size_t b = 0, e = field.size();
      while (b < e && (field[b] == ' ' || field[b] == '\t')) ++b;
      while (e > b && (field[e - 1] == ' ' || field[e - 1] == '\t')) --e;
      const std::string num = field.substr(b, e - b);
      char* stop = nullptr;
      errno = 0;
      const double x = num.empty() ? 0.0 : std::strtod(num.c_str(), &stop);
      if (num.empty() || stop != num.c_str() + num.size() || errno == ERANGE || !std::isfinite(x))
        throw InputError(at, "a finite number, got '" + field + "'");
      v[f] = x;
      pos = end + 1;
    }
    const TruthPoint p{v[0], v[1], v[2], v[3]};
    auto range = [&](int f, bool ok, const char* what) {
      if (!ok) {
        std::size_t col = 0;
        for (int k = 0; k < f; ++k) col = line.find(',', col) + 1;
        throw InputError(Location{file, lineno, static_cast<int>(col) + 1, kColumns[f]}, what);
      }
    };
    range(0, p.altitude_km >= 0.0, "an altitude >= 0 km");
    range(1, p.view_zenith_deg >= 0.0 && p.view_zenith_deg <= 180.0, "a view zenith angle in [0, 180] degrees");
    range(2, p.sun_zenith_deg >= 0.0 && p.sun_zenith_deg <= 180.0, "a sun zenith angle in [0, 180] degrees");
    range(3, std::fabs(p.view_sun_azimuth_deg) <= 360.0, "an azimuth in [-360, 360] degrees");
    points.push_back(p);
  }
  if (points.empty()) throw InputError(Location{file, 2, 1, ""}, "at least one point after the header");
  return points;
}

std::vector<TruthPoint> read_truth_points(const fs::path& file) { return parse_truth_points(read_all(file), file); }

std::string truth_result_bytes(const TruthResult& r) {
  const nlohmann::json j = {{"lambda_nm", r.lambda_nm},
                            {"channel_names", r.channel_names},
                            {"points", r.points},
                            {"channels", r.channels},
                            {"radiance", r.radiance},
                            {"standard_error", r.standard_error},
                            {"paths", r.paths},
                            {"channel_paths", r.channel_paths},
                            {"at_cap", r.at_cap},
                            {"split_orders", r.split_orders},
                            {"radiance_low", r.radiance_low},
                            {"standard_error_low", r.standard_error_low},
                            {"radiance_high", r.radiance_high},
                            {"standard_error_high", r.standard_error_high},
                            {"orders", r.orders},
                            {"seed", r.seed},
                            {"mean_events", r.mean_events},
                            {"truncated", r.truncated},
                            {"precision", r.precision},
                            {"device", r.device},
                            {"order1", r.order1}};  // not its seconds: the bytes are the same every run
  const std::vector<std::uint8_t> cbor = nlohmann::json::to_cbor(j);
  return std::string(cbor.begin(), cbor.end());
}

TruthResult truth_result_from_bytes(const std::string& bytes) {
  const nlohmann::json j = nlohmann::json::from_cbor(bytes);
  TruthResult r;
  j.at("lambda_nm").get_to(r.lambda_nm);
  j.at("channel_names").get_to(r.channel_names);
  j.at("points").get_to(r.points);
  j.at("channels").get_to(r.channels);
  j.at("radiance").get_to(r.radiance);
  j.at("standard_error").get_to(r.standard_error);
  j.at("paths").get_to(r.paths);
  if (j.contains("channel_paths")) {
    j.at("channel_paths").get_to(r.channel_paths);
  } else {  // kept before channels walked their own shares: every channel walked the point's walks
    for (long long n : r.paths) r.channel_paths.insert(r.channel_paths.end(), r.channels, n);
  }
  j.at("at_cap").get_to(r.at_cap);
  j.at("split_orders").get_to(r.split_orders);
  j.at("radiance_low").get_to(r.radiance_low);
  j.at("standard_error_low").get_to(r.standard_error_low);
  j.at("radiance_high").get_to(r.radiance_high);
  j.at("standard_error_high").get_to(r.standard_error_high);
  j.at("orders").get_to(r.orders);
  j.at("seed").get_to(r.seed);
  j.at("mean_events").get_to(r.mean_events);
  j.at("truncated").get_to(r.truncated);
  j.at("precision").get_to(r.precision);
  j.at("device").get_to(r.device);
  r.order1 = j.value("order1", std::string("walked"));  // kept before order 1 had a quadrature: walked
  const std::size_t cells = r.points * r.channels;
  const std::size_t split = r.split_orders > 0 ? cells : 0;
  if (r.channels != r.lambda_nm.size() || r.channels != r.channel_names.size() || r.radiance.size() != cells ||
      r.standard_error.size() != cells || r.paths.size() != r.points || r.channel_paths.size() != cells ||
      r.at_cap.size() != r.points ||
      r.radiance_low.size() != split ||
      r.standard_error_low.size() != split || r.radiance_high.size() != split || r.standard_error_high.size() != split)
    throw std::runtime_error("a path-traced result whose arrays do not match its points and channels");
  return r;
}

std::string truth_points_csv(const std::vector<TruthPoint>& points) {
  std::string s = std::string(kTruthPointsHeader) + "\n";
  char b[160];
  for (const TruthPoint& p : points) {
    std::snprintf(b, sizeof b, "%.17g,%.17g,%.17g,%.17g\n", p.altitude_km, p.view_zenith_deg, p.sun_zenith_deg,
                  p.view_sun_azimuth_deg);
    s += b;
  }
  return s;
}

TruthBundleValues to_bundle_units(const AtmosphereSpec& spec, const TruthResult& r) {
  TruthBundleValues v;
  if (!spec.spectral) {
    if (r.channels != 3) throw JobError("truth: an rgb result needs 3 channels");
    v.radiance = r.radiance;
    v.standard_error = r.standard_error;
    v.units = "W m^-2 sr^-1 nm^-1 at 680/550/440 nm";
    return v;
  }
  const Spectrum sp = spectrum_of(spec);
  if (sp.lambda_nm.size() != r.channels) throw JobError("truth: the result's wavelengths are not the spec's");
  v = weighted_sums(r, sp.to_rgb);
  v.units = "linear sRGB luminance / 683 (the bundle's precomputed-luminance values)";
  return v;
}

TruthBundleValues weighted_sums(const TruthResult& r, const std::vector<double>& weights) {
  const std::size_t n = r.channels;
  if (weights.size() != 3 * n) throw JobError("truth: 3 rows of weights over the result's channels expected");
  TruthBundleValues v;
  v.radiance.assign(r.points * 3, 0.0);
  v.standard_error.assign(r.points * 3, 0.0);
  for (std::size_t p = 0; p < r.points; ++p)
    for (int c = 0; c < 3; ++c) {
      double l = 0.0, var = 0.0;
      for (std::size_t i = 0; i < n; ++i) {
        const double k = weights[c * n + i];
        l += k * r.L(p, i);
        var += k * k * r.se(p, i) * r.se(p, i);
      }
      v.radiance[p * 3 + c] = l;
      v.standard_error[p * 3 + c] = std::sqrt(var);
    }
  return v;
}

std::string truth_result_csv(const AtmosphereSpec& spec, const std::vector<TruthPoint>& points, const TruthResult& r,
                             const std::vector<Vec3>* lut) {
  if (points.size() != r.points) throw JobError("truth: points and result differ in length");
  if (lut && lut->size() != r.points) throw JobError("truth: points and LUT values differ in length");
  const TruthBundleValues bundle = to_bundle_units(spec, r);
  const char* rgb[3] = {"R", "G", "B"};
  std::string s = kTruthPointsHeader;
  for (const std::string& c : r.channel_names) s += ",L_" + c + ",se_" + c;
  if (spec.spectral)
    for (const char* c : rgb) s += std::string(",L_") + c + ",se_" + c;
  if (lut)
    for (const char* c : rgb) s += std::string(",lut_") + c;
  s += "\n";
  auto cell = [&](double v) {
    s += ',';
    s += fmt(v);
  };
  for (std::size_t p = 0; p < r.points; ++p) {
    const TruthPoint& q = points[p];
    s += fmt(q.altitude_km);
    cell(q.view_zenith_deg);
    cell(q.sun_zenith_deg);
    cell(q.view_sun_azimuth_deg);
    for (std::size_t c = 0; c < r.channels; ++c) {
      cell(r.L(p, c));
      cell(r.se(p, c));
    }
    if (spec.spectral)
      for (int c = 0; c < 3; ++c) {
        cell(bundle.radiance[p * 3 + c]);
        cell(bundle.standard_error[p * 3 + c]);
      }
    if (lut)
      for (int c = 0; c < 3; ++c) cell((*lut)[p][c]);
    s += '\n';
  }
  return s;
}

void write_text_file(const fs::path& file, const std::string& text) {
  std::ofstream out(file, std::ios::binary | std::ios::trunc);
  if (!out) throw IoError("cannot write " + file.string() + ": " + std::strerror(errno));
  out << text;
  out.flush();
  if (!out) throw IoError("cannot write " + file.string());
}

Luts load_bundle_luts(const fs::path& dir) {
  const fs::path manifest_path = dir / "manifest.json";
  nlohmann::json m;
  try {
    m = nlohmann::json::parse(read_all(manifest_path));
  } catch (const nlohmann::json::exception& e) {
    throw InputError(Location{manifest_path, 0, 0, ""}, std::string("a JSON manifest (") + e.what() + ")");
  }
  const Location at{manifest_path, 0, 0, ""};
  Luts luts;
  try {
    if (m.at("job").at("kind").get<std::string>() != "atmosphere") throw InputError(at, "an atmosphere bundle");
    const auto& atm = m.at("parameters").at("atmosphere");
    luts.model.bottom_radius_km = atm.at("bottom_radius_km").get<double>();
    luts.model.top_radius_km = atm.at("top_radius_km").get<double>();
    luts.model.sun_angular_radius_rad = atm.at("sun_angular_radius_rad").get<double>();
    luts.model.mu_s_min = atm.at("mu_s_min").get<double>();
    luts.model.mie_g = atm.at("mie").is_object() ? atm.at("mie").at("phase_g").get<double>() : 0.0;
    const auto& sz = m.at("parameters").at("sizes");
    Sizes& s = luts.model.sizes;
    s.transmittance_w = sz.at("transmittance").at("mu").get<int>();
    s.transmittance_h = sz.at("transmittance").at("r").get<int>();
    s.irradiance_w = sz.at("irradiance").at("mu_s").get<int>();
    s.irradiance_h = sz.at("irradiance").at("r").get<int>();
    s.r = sz.at("scattering").at("r").get<int>();
    s.mu = sz.at("scattering").at("mu").get<int>();
    s.mu_s = sz.at("scattering").at("mu_s").get<int>();
    s.nu = sz.at("scattering").at("nu").get<int>();
    // bundles from before `quadrature` blended μ_s linearly (their shader did)
    const auto q = m.at("parameters").find("quadrature");
    luts.model.mu_s_geometric = q != m.at("parameters").end() && q->value("mu_s_blend", "linear") == "geometric";
    // the sky-view table, where the bundle has one (bundles from before it: none)
    const auto sv = m.at("parameters").find("sky_view");
    if (sv != m.at("parameters").end() && sv->is_object()) {
      SkyView& v = luts.model.sky_view;
      v.altitude_min_km = sv->at("altitude_km").at(0).get<double>();
      v.altitude_max_km = sv->at("altitude_km").at(1).get<double>();
      v.sun_min_deg = sv->at("sun_elevation_deg").at(0).get<double>();
      v.sun_max_deg = sv->at("sun_elevation_deg").at(1).get<double>();
      v.altitude = sv->at("nodes").at("altitude").get<int>();
      v.sun = sv->at("nodes").at("sun").get<int>();
      v.view = sv->at("nodes").at("view").get<int>();
      v.azimuth = sv->at("nodes").at("azimuth").get<int>();
    }
  } catch (const nlohmann::json::exception& e) {
    throw InputError(at, std::string("an atmosphere bundle manifest (") + e.what() + ")");
  }
  const Sizes& s = luts.model.sizes;
  // from whichever copy the bundle holds (`formats:`): .bin, EXR or KTX2 (half copies: rounded)
  auto load = [&](const char* name, std::size_t count, bool required) {
    std::vector<double> v;
    if (!has_bundle_texture(dir, name)) {
      if (required)
        throw InputError(at, std::string("a bundle with ") + name + " (.bin, .exr or .ktx2: outputs and layout 3d)");
      v.assign(count, 0.0);
      return v;
    }
    const BundleTexture t = read_bundle_texture(dir, name, 3, count / 3);
    if (t.half) spdlog::info("truth: {} read from its half-precision copy {}", name, t.file);
    return std::vector<double>(t.values.begin(), t.values.end());
  };
  const std::size_t n_s = 3 * static_cast<std::size_t>(s.scattering_texels());
  luts.scattering = load("scattering", n_s, true);
  luts.single_mie = load("single_mie_scattering", n_s, true);
  luts.transmittance = load("transmittance", 3ULL * s.transmittance_w * s.transmittance_h, false);
  luts.irradiance = load("irradiance", 3ULL * s.irradiance_w * s.irradiance_h, false);
  if (luts.model.sky_view.on()) {
    const std::size_t n_v = 3 * static_cast<std::size_t>(luts.model.sky_view.texels());
    luts.sky_view = load("sky_view", n_v, true);
    luts.sky_view_mie = load("sky_view_single_mie", n_v, true);
  }
  return luts;
}

std::vector<Vec3> lut_sky_radiance(const Luts& luts, const std::vector<TruthPoint>& points) {
  const Renderer render(luts);
  std::vector<Vec3> out;
  out.reserve(points.size());
  for (const TruthPoint& p : points) {
    const double tv = p.view_zenith_deg * M_PI / 180.0, ts = p.sun_zenith_deg * M_PI / 180.0,
                 az = p.view_sun_azimuth_deg * M_PI / 180.0;
    const Vec3 camera{0.0, 0.0, luts.model.bottom_radius_km + p.altitude_km};
    const Vec3 view{std::sin(tv), 0.0, std::cos(tv)};
    const Vec3 sun{std::sin(ts) * std::cos(az), std::sin(ts) * std::sin(az), std::cos(ts)};
    Vec3 t{};
    out.push_back(render.sky_radiance(camera, view, sun, &t));
  }
  return out;
}

}  // namespace specbake::atmosphere
