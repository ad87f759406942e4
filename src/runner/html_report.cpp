#include "runner/html_report.hpp"

#include <unistd.h>

#include <algorithm>
#include <cstring>
#include <fstream>
#include <map>
#include <set>
#include <sstream>

#include <spdlog/spdlog.h>

#include "core/errors.hpp"
#include "core/resources.hpp"
#include "core/text.hpp"
#include "io/bundle_diff.hpp"
#include "io/bundle_texture.hpp"

namespace specbake {

using nlohmann::json;

namespace {

std::string esc(const std::string& s) {
  std::string o;
  o.reserve(s.size());
  for (char c : s) {
    switch (c) {
      case '&': o += "&amp;"; break;
      case '<': o += "&lt;"; break;
      case '>': o += "&gt;"; break;
      case '"': o += "&quot;"; break;
      case '\'': o += "&#39;"; break;
      default: o += c;
    }
  }
  return o;
}

std::string base64(const std::string& in) {
  static const char* t = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string o;
  o.reserve((in.size() + 2) / 3 * 4);
  std::size_t i = 0;
  for (; i + 2 < in.size(); i += 3) {
    const unsigned v = (static_cast<unsigned char>(in[i]) << 16) | (static_cast<unsigned char>(in[i + 1]) << 8) |
                       static_cast<unsigned char>(in[i + 2]);
    o += t[v >> 18], o += t[(v >> 12) & 63], o += t[(v >> 6) & 63], o += t[v & 63];
  }
  if (i < in.size()) {
    unsigned v = static_cast<unsigned char>(in[i]) << 16;
    if (i + 1 < in.size()) v |= static_cast<unsigned char>(in[i + 1]) << 8;
    o += t[v >> 18], o += t[(v >> 12) & 63];
    o += i + 1 < in.size() ? t[(v >> 6) & 63] : '=';
    o += '=';
  }
  return o;
}

// The file's bytes, or false when it cannot be read.
bool read_bytes(const fs::path& p, std::string& out) {
  std::ifstream in(p, std::ios::binary);
  if (!in) return false;
  std::ostringstream ss;
  ss << in.rdbuf();
  out = ss.str();
  return static_cast<bool>(in) || in.eof();
}

std::string num(double v) { return format_g(v, 4); }

std::string scalar_text(const json& v) {
  if (v.is_string()) return v.get<std::string>();
  if (v.is_number_float()) return num(v.get<double>());
  if (v.is_null()) return "–";
  return v.dump();
}

// ---- the accuracy record: every field readable ----------------------------------------------
// A record's details are nested JSON. Objects whose values are all numbers (statistics such as
// {count, max, mean, median, p99}) become rows of a table, one table per set of columns; arrays
// of flat objects become tables; everything else is a "key path: value" row.

bool all_numbers(const json& o) {
  if (!o.is_object() || o.size() < 2) return false;
  for (const auto& [k, v] : o.items())
    if (!v.is_number()) return false;
  return true;
}
bool flat_object(const json& o) {
  if (!o.is_object()) return false;
  for (const auto& [k, v] : o.items())
    if (v.is_structured()) return false;
  return true;
}

struct Flattened {
  std::vector<std::pair<std::string, std::string>> leaves;
  // columns → rows (path, object), in order of appearance
  std::vector<std::pair<std::vector<std::string>, std::vector<std::pair<std::string, json>>>> tables;
  void add_row(const std::vector<std::string>& cols, const std::string& path, const json& row) {
    for (auto& t : tables)
      if (t.first == cols) {
        t.second.emplace_back(path, row);
        return;
      }
    tables.push_back({cols, {{path, row}}});
  }
};

void flatten(const json& j, const std::string& path, Flattened& f) {
  const auto join = [&](const std::string& k) { return path.empty() ? k : path + " › " + k; };
  if (all_numbers(j)) {
    std::vector<std::string> cols;
    for (const auto& [k, v] : j.items()) cols.push_back(k);
    f.add_row(cols, path, j);
  } else if (j.is_object()) {
    for (const auto& [k, v] : j.items()) flatten(v, join(k), f);
  } else if (j.is_array() && !j.empty() && std::all_of(j.begin(), j.end(), flat_object)) {
    std::vector<std::string> cols;
    for (const auto& e : j)
      for (const auto& [k, v] : e.items())
        if (std::find(cols.begin(), cols.end(), k) == cols.end()) cols.push_back(k);
    for (std::size_t i = 0; i < j.size(); ++i) f.add_row(cols, path + " [" + std::to_string(i) + "]", j[i]);
  } else if (j.is_array() && std::any_of(j.begin(), j.end(), [](const json& e) { return e.is_structured(); })) {
    for (std::size_t i = 0; i < j.size(); ++i) flatten(j[i], path + " [" + std::to_string(i) + "]", f);
  } else if (j.is_array()) {
    std::string s;
    for (const auto& e : j) s += (s.empty() ? "" : ", ") + scalar_text(e);
    f.leaves.emplace_back(path, "[" + s + "]");
  } else {
    f.leaves.emplace_back(path, scalar_text(j));
  }
}

std::string details_html(const json& details) {
  Flattened f;
  flatten(details, "", f);
  std::ostringstream o;
  for (const auto& [cols, rows] : f.tables) {
    o << "<table class=\"stats\"><tr><th></th>";
    for (const auto& c : cols) o << "<th>" << esc(c) << "</th>";
    o << "</tr>";
    for (const auto& [path, row] : rows) {
      o << "<tr><th>" << esc(path) << "</th>";
      for (const auto& c : cols) o << "<td>" << (row.contains(c) ? esc(scalar_text(row[c])) : "") << "</td>";
      o << "</tr>";
    }
    o << "</table>";
  }
  // the notes and settings of the record, folded
  if (!f.leaves.empty()) {
    o << "<details><summary>" << f.leaves.size() << " more field(s)</summary><table class=\"kv\">";
    for (const auto& [k, v] : f.leaves) o << "<tr><th>" << esc(k) << "</th><td>" << esc(v) << "</td></tr>";
    o << "</table></details>";
  }
  return o.str();
}

// "pass", "fail" or "info" (no tolerance judged).
std::string verdict(const json& a) {
  if (!a.is_object() || !a.contains("passed") || !a["passed"].is_boolean()) return "info";
  if (!a["passed"].get<bool>()) return "fail";
  return a.contains("tolerance") && a["tolerance"].is_number() ? "pass" : "info";
}

std::string job_verdict(const PageJob& j) {
  if (j.status == "failed" || j.status == "invalid" || j.status == "interrupted") return "fail";
  for (const auto& a : j.accuracy)
    if (verdict(a) == "fail") return "fail";
  return j.warnings.empty() ? "pass" : "warn";
}

std::string record_html(const json& a) {
  std::ostringstream o;
  const std::string v = verdict(a);
  o << "<div class=\"record " << v << "\"><div class=\"rec-head\"><span class=\"badge " << v << "\">"
    << (v == "pass" ? "passed" : v == "fail" ? "FAILED" : "recorded") << "</span> "
    << esc(accuracy_headline(json::array({a}))) << "</div>";
  for (const char* k : {"metric", "reference"})
    if (a.contains(k) && a[k].is_string()) o << "<div class=\"rec-line\"><b>" << k << ":</b> " << esc(a[k].get<std::string>()) << "</div>";
  json rest = json::object();
  for (const auto& [k, val] : a.items())
    if (k != "name" && k != "value" && k != "unit" && k != "tolerance" && k != "passed" && k != "metric" &&
        k != "reference")
      rest[k] = val;
  if (rest.contains("details") && rest.size() == 1) rest = rest["details"];
  if (!rest.empty()) o << details_html(rest);
  o << "</div>";
  return o.str();
}

// ---- previews, sweeps, changes ----------------------------------------------------------------

std::string image_figure(const fs::path& png, const std::string& caption) {
  std::string bytes;
  if (!read_bytes(png, bytes)) return "<p class=\"note\">cannot read " + esc(png.string()) + "</p>";
  return "<figure><img alt=\"" + esc(png.filename().string()) + "\" src=\"data:image/png;base64," + base64(bytes) +
         "\"><figcaption>" + esc(caption) + "</figcaption></figure>";
}

json read_manifest_or_null(const fs::path& bundle) {
  std::string text;
  if (!read_bytes(bundle / "manifest.json", text)) return nullptr;
  return json::parse(text, nullptr, false);
}

std::string previews_html(const PageJob& j, const json& manifest) {
  std::ostringstream o;
  int n = 0;
  for (const auto& f : manifest.value("files", json::array())) {
    const std::string p = f.value("path", "");
    if (p.rfind("preview/", 0) != 0 || p.size() < 4 || p.substr(p.size() - 4) != ".png") continue;
    if (p == "preview/contact_sheet.png") continue;  // every other preview again, at half size
    if (!n++) o << "<div class=\"previews\">";
    o << image_figure(j.bundle / p, p.substr(8) + ": " + f.value("description", ""));
  }
  if (n) o << "</div>";
  return n ? "<h4>Previews</h4>" + o.str() : "";
}

// ---- live views (src/runner/report/live.js and one script per view) ---------------------------
// A bundle's own shipped GLSL in WebGL2, on its data embedded in the page as base64 float32 in a
// JSON block; at most kLiveBytes of data per bundle, so that a page of large bakes stays openable.
// Where a bundle lacks what a view needs, a note says why.
constexpr std::uint64_t kLiveBytes = 48ull << 20;

struct Slider {
  const char* name;
  const char* label;
  double min, max, step, value;
  const char* unit;
};

std::string live_view_html(const char* cls, std::size_t index, int width, int height, const std::vector<Slider>& sliders,
                           const std::string& note, const json& data) {
  std::string text = data.dump();
  for (std::size_t at = 0; (at = text.find("</", at)) != std::string::npos; at += 3) text.replace(at, 2, "<\\/");
  std::ostringstream o;
  o << "<h4>Live view</h4><div class=\"live " << cls << "\" id=\"" << cls << "-" << index << "\"><canvas width=\""
    << width << "\" height=\"" << height << "\"></canvas><div class=\"controls\">";
  for (const Slider& c : sliders)
    o << "<label>" << c.label << " <input type=\"range\" name=\"" << c.name << "\" min=\"" << num(c.min)
      << "\" max=\"" << num(c.max) << "\" step=\"" << num(c.step) << "\" value=\"" << num(c.value)
      << "\"><output></output> " << c.unit << "</label>";
  o << "<p class=\"live-note\">" << esc(note) << "</p><p class=\"live-status\"></p></div>"
    << "<script type=\"application/json\" class=\"live-data\">" << text << "</script></div>\n";
  return o.str();
}

std::string no_live_view(const std::string& why) {
  return "<h4>Live view</h4><p class=\"note\">no live view of this bundle: " + esc(why) + "</p>";
}

// The shipped text at `glsl_path` and the float32 files (name → path) into `data`; "" or the reason not.
// A live view's data: the bundle's shipped GLSL and its textures (name, the file's stem, channels),
// each read from whichever copy the bundle holds (.bin, EXR or KTX2: read_bundle_texture) with
// its shape as the .bin has it ([..., channels]). "" when it could, else why not.
struct LiveTexture {
  std::string name, stem;
  int channels = 3;
};
std::string live_data(const PageJob& j, const json& manifest, const std::string& glsl_path,
                      const std::vector<LiveTexture>& textures, json& data) {
  std::map<std::string, json> files;
  for (const auto& f : manifest.value("files", json::array())) files[f.value("path", "")] = f;
  std::string glsl;
  if (!files.count(glsl_path) || !read_bytes(j.bundle / glsl_path, glsl)) return "it has no " + glsl_path;
  data = {{"job", j.name}, {"glsl", glsl}, {"textures", json::object()}};
  std::uint64_t total = 0;
  for (const auto& t : textures) {
    json shape;
    for (const char* ext : {".bin", ".exr", ".ktx2"})
      if (shape.is_null() && files.count(t.stem + ext)) shape = files[t.stem + ext].value("shape", json::array());
    if (shape.is_null() || shape.empty())
      return "it has no " + t.stem + ".bin, .exr or .ktx2 (the live view reads one)";
    shape.back() = t.channels;  // KTX2 copies hold RGBA: the view gets the channels the .bin has
    std::uint64_t texels = 1;
    for (std::size_t i = 0; i + 1 < shape.size(); ++i) texels *= shape[i].get<std::uint64_t>();
    total += texels * static_cast<std::uint64_t>(t.channels) * 4;
    if (total > kLiveBytes) return "its data exceed the " + human_bytes(kLiveBytes) + " a page embeds per bundle";
    BundleTexture tex;
    try {
      tex = read_bundle_texture(j.bundle, t.stem, t.channels, texels);
    } catch (const Error& e) {
      return std::string("its ") + t.stem + " cannot be read (" + e.what() + ")";
    }
    std::string bytes(tex.values.size() * sizeof(float), '\0');
    std::memcpy(bytes.data(), tex.values.data(), bytes.size());
    data["textures"][t.name] = {{"shape", shape}, {"base64", base64(bytes)}, {"file", tex.file}};
  }
  return "";
}

// Atmosphere (sky.js): sampling.glsl's GetSkyRadiance over a fisheye; RGB bundles with the 3D
// layout and a separate single-Mie texture (what sky.js binds).
std::string live_sky_html(const PageJob& j, const json& manifest, std::size_t index) {
  json data;
  std::vector<LiveTexture> textures = {{"transmittance", "transmittance"}, {"scattering", "scattering"},
                                       {"single_mie_scattering", "single_mie_scattering"}};
  const json params = manifest.value("parameters", json::object());
  const bool table = params.is_object() && params.contains("sky_view") && params["sky_view"].is_object();
  if (table)  // the sky-view table (GetSkyRadianceWithSkyView)
    for (const char* t : {"sky_view", "sky_view_single_mie"}) textures.push_back({t, t});
  const std::string why = live_data(j, manifest, "sampling.glsl", textures, data);
  if (!why.empty()) return no_live_view(why);
  if (data["glsl"].get<std::string>().find("this bundle has no 3D layout") != std::string::npos)
    return no_live_view("the live view binds the 3D scattering layout; this bundle has the tiled 2D one only");
  return live_view_html(
      "live-sky", index, 320, 320,
      {{"sun_elevation_deg", "sun elevation", -10, 90, 0.5, 20, "deg"},
       {"sun_azimuth_deg", "sun azimuth", -180, 180, 1, 0, "deg"},
       {"altitude_km", "altitude", 0, 50, 0.1, 0, "km"},
       {"exposure", "exposure", -4, 10, 0.25, 3, "stops"}},
      std::string("The bundle's own sampling.glsl (") +
          (table ? "GetSkyRadianceWithSkyView: its sky-view table where it holds the camera and the sun" : "GetSkyRadiance") +
          ", as shipped) in WebGL2 on its float32 textures: equidistant "
      "fisheye, zenith at the centre, sun azimuth 0 at the right; the sky's radiance (R, G, B at the bundle's "
      "wavelengths, no sun disc) times 2^exposure, then 1 − exp(−x) and the sRGB curve.",
      data);
}

// Dispersion (prism.js): dispersion.glsl's specbake_dispersion_combine over a white beam.
std::string live_prism_html(const PageJob& j, const json& manifest, std::size_t index) {
  json data;
  const std::string why = live_data(j, manifest, "dispersion.glsl", {}, data);
  if (!why.empty()) return no_live_view(why);
  double spread = 4.0;  // the prism check's spread (beam widths between the range's ends), where recorded
  for (const auto& a : j.accuracy)
    if (a.is_object() && a.contains("details") && a["details"].is_object() && a["details"].contains("spread") &&
        a["details"]["spread"].is_number())
      spread = a["details"]["spread"].get<double>();
  return live_view_html(
      "live-prism", index, 640, 64, {{"spread", "spread", 0, 16, 0.25, spread, "beam widths"}},
      "The bundle's own dispersion.glsl (specbake_dispersion_combine, as shipped) in WebGL2: a white beam one unit "
      "wide through a thin prism, sample n landing at spread · SPECBAKE_IOR_OFFSET[n] (the spread: beam widths "
      "between the range's ends), the per-sample renders summed with K_n; linear sRGB clamped to [0, 1], then the "
      "sRGB curve. The static preview above compares the same sum with the dense spectrum.",
      data);
}

// Diffraction table bundles (lobes.js): diffraction_srgb_fast over the outgoing hemisphere.
std::string live_lobes_html(const PageJob& j, const json& manifest, std::size_t index) {
  json data;
  const std::string why =
      live_data(j, manifest, "shader/diffraction_brdf.glsl", {{"table_terms", "table_terms", 2}}, data);
  if (!why.empty()) return no_live_view(why);
  return live_view_html(
      "live-lobes", index, 320, 320,
      {{"light_angle_deg", "light angle", 0, 85, 1, 30, "deg"}, {"exposure", "exposure", -4, 12, 0.25, 4, "stops"}},
      "The bundle's own shader/diffraction_brdf.glsl (diffraction_srgb_fast, as shipped) in WebGL2 on its table "
      "(table_terms.bin): the outgoing hemisphere seen from above (orthographic, the normal at the centre), lit by "
      "D65 at the light angle from the normal on the left (its mirror direction on the right); the relative BRDF "
      "in linear sRGB times 2^exposure, clamped to [0, 1], then the sRGB curve.",
      data);
}

std::string live_html(const PageJob& j, const json& manifest, std::size_t index) {
  if (j.kind == "atmosphere") return live_sky_html(j, manifest, index);
  if (j.kind == "dispersion") return live_prism_html(j, manifest, index);
  if (j.kind == "diffraction") return live_lobes_html(j, manifest, index);
  return "";
}

std::string changes_html(const PageJob& j, const json& manifest) {
  if (j.previous.empty() || j.bundle.empty()) return "";
  std::ostringstream o;
  const json old = read_manifest_or_null(j.previous);
  o << "<h4>Changes since the earlier bundle <code>" << esc(j.previous.filename().string()) << "</code>";
  if (old.is_object()) o << " (" << esc(old.value("created_utc", "?")) << ")";
  o << "</h4>";
  // Accuracy: each record's value, earlier and now, by name.
  std::map<std::string, json> before;
  if (old.is_object())
    for (const auto& a : old.value("accuracy", json::array()))
      if (a.is_object()) before[a.value("name", "")] = a;
  o << "<table class=\"changes\"><tr><th>accuracy record</th><th>earlier</th><th>now</th><th>change</th></tr>";
  for (const auto& a : manifest.value("accuracy", json::array())) {
    if (!a.is_object()) continue;
    const std::string name = a.value("name", "");
    const json now = a.value("value", json(nullptr));
    const json was = before.count(name) ? before[name].value("value", json(nullptr)) : json(nullptr);
    std::string change = "–";
    if (now.is_number() && was.is_number()) {
      const double d = now.get<double>() - was.get<double>();
      change = d == 0 ? "same" : (d > 0 ? "+" : "") + num(d);
      if (d != 0 && was.get<double>() != 0) change += " (" + num(100.0 * d / std::abs(was.get<double>())) + " %)";
    } else if (!before.count(name)) {
      change = "new";
    }
    o << "<tr><td>" << esc(name) << "</td><td>" << esc(scalar_text(was)) << "</td><td>" << esc(scalar_text(now))
      << "</td><td>" << esc(change) << "</td></tr>";
  }
  o << "</table>";
  try {
    const BundleDiff d = diff_bundles(j.previous, j.bundle, 0.0, 0.0);
    int same = 0;
    std::ostringstream rows;
    for (const auto& f : d.files) {
      if (f.status == "same") {
        ++same;
        continue;
      }
      rows << "<tr><td>" << esc(f.path) << "</td><td>" << esc(f.status) << "</td><td>"
           << (f.numeric && f.status == "differs" ? num(f.max_abs) : "") << "</td><td>"
           << (f.numeric && f.status == "differs" ? num(f.max_rel) : "") << "</td></tr>";
    }
    o << "<table class=\"changes\"><tr><th>file</th><th>status</th><th>max abs</th><th>max rel</th></tr>" << rows.str()
      << "</table><p class=\"note\">" << same << " file(s) the same byte for byte; values compared as "
      << "<code>specbake diff</code> does (float32 data and EXR pixels element by element).</p>";
    if (!d.changed.empty()) {
      o << "<table class=\"changes\"><tr><th>manifest key</th><th>earlier</th><th>now</th></tr>";
      for (auto it = d.changed.begin(); it != d.changed.end(); ++it)
        o << "<tr><td>" << esc(it.key()) << "</td><td>" << esc(scalar_text(it.value()[0])) << "</td><td>"
          << esc(scalar_text(it.value()[1])) << "</td></tr>";
      o << "</table>";
    }
  } catch (const Error& e) {
    o << "<p class=\"note\">cannot compare with the earlier bundle: " << esc(e.what()) << "</p>";
  }
  return o.str();
}

std::string sweeps_html(const std::vector<fs::path>& sweeps) {
  if (sweeps.empty()) return "";
  std::ostringstream o;
  o << "<section class=\"sweeps\"><h2>Sweeps</h2>";
  for (const auto& s : sweeps) {
    std::string text;
    json j = read_bytes(s / "sweep.json", text) ? json::parse(text, nullptr, false) : json(nullptr);
    std::string title = s.filename().string();
    if (j.is_object()) {
      title = j.value("job", title) + " (" + j.value("kind", "?") + ")";
      std::string varies;
      for (const auto& v : j.value("varies", json::array())) varies += (varies.empty() ? "" : ", ") + v.value("key", "");
      title += ": " + std::to_string(j.value("points", json::array()).size()) + " points over " + varies;
    }
    o << "<div class=\"sweep\"><h3>" << esc(title) << "</h3><p class=\"path\">" << esc(s.string()) << "</p>";
    if (fs::exists(s / "sweep.png")) o << image_figure(s / "sweep.png", "speed against error (sweep.png)");
    else o << "<p class=\"note\">no sweep.png (matplotlib was missing when it ran); the numbers are in sweep.csv</p>";
    o << "</div>";
  }
  o << "</section>";
  return o.str();
}

std::string seconds_text(double s) {
  if (s < 0) return "–";
  char b[32];
  if (s < 60) std::snprintf(b, sizeof b, "%.1f s", s);
  else std::snprintf(b, sizeof b, "%d min %02d s", static_cast<int>(s) / 60, static_cast<int>(s) % 60);
  return b;
}

std::string anchor(std::size_t i) { return "job-" + std::to_string(i); }

}  // namespace

// ---- rows from the three sources -----------------------------------------------------------------

PageJob page_job(const OutputJob& j) {
  PageJob p;
  p.name = j.name;
  const json job = j.manifest.value("job", json::object());
  if (job.is_object()) {
    p.kind = job.value("kind", "");
    p.hash = job.value("hash", "");
    p.config = job.value("config_file", "");
  }
  p.status = "published";
  p.bundle = j.bundle;
  p.previous = j.previous;
  p.created_utc = j.manifest.value("created_utc", "");
  p.accuracy = j.manifest.value("accuracy", json::array());
  for (const auto& w : j.manifest.value("warnings", json::array())) p.warnings.push_back(w.is_string() ? w.get<std::string>() : w.dump());
  p.parameters = j.manifest.value("parameters", json::object());
  const json t = j.manifest.value("timings_s", json::object());
  if (t.is_object() && t.contains("bake") && t["bake"].is_number()) p.seconds = t["bake"].get<double>();
  return p;
}

PageJob page_job(const JobReport& r) {
  PageJob p;
  p.name = r.name, p.kind = r.kind, p.status = r.status, p.reason = r.reason, p.config = r.config, p.hash = r.hash;
  p.bundle = r.bundle;
  if (!p.bundle.empty()) p.previous = previous_bundle(p.bundle);
  if (r.accuracy.is_array()) p.accuracy = r.accuracy;
  p.warnings = r.warnings;
  p.parameters = r.parameters;
  if (r.timings.is_object() && r.timings.contains("total_s") && r.timings["total_s"].is_number())
    p.seconds = r.timings["total_s"].get<double>();
  if (!p.bundle.empty())
    if (const json m = read_manifest_or_null(p.bundle); m.is_object()) p.created_utc = m.value("created_utc", "");
  return p;
}

PageJob page_job_from_report_entry(const json& e) {
  PageJob p;
  if (!e.is_object()) return p;
  p.name = e.value("name", ""), p.kind = e.value("kind", ""), p.status = e.value("status", "");
  p.reason = e.value("reason", ""), p.config = e.value("config", ""), p.hash = e.value("hash", "");
  if (e.contains("bundle") && e["bundle"].is_string()) {
    p.bundle = e["bundle"].get<std::string>();
    std::error_code ec;
    if (fs::exists(p.bundle / "manifest.json", ec)) {
      p.previous = previous_bundle(p.bundle);
      if (const json m = read_manifest_or_null(p.bundle); m.is_object()) p.created_utc = m.value("created_utc", "");
    }
  }
  if (e.contains("accuracy") && e["accuracy"].is_array()) p.accuracy = e["accuracy"];
  for (const auto& w : e.value("warnings", json::array())) p.warnings.push_back(w.is_string() ? w.get<std::string>() : w.dump());
  p.parameters = e.value("parameters", json::object());
  const json t = e.value("timings", json::object());
  if (t.is_object() && t.contains("total_s") && t["total_s"].is_number()) p.seconds = t["total_s"].get<double>();
  return p;
}

std::vector<fs::path> find_sweeps(const fs::path& dir) {
  std::vector<fs::path> out;
  std::error_code ec;
  if (fs::exists(dir / "sweep.json", ec)) out.push_back(dir);
  for (const auto& e : fs::directory_iterator(dir, ec))
    if (e.is_directory(ec) && fs::exists(e.path() / "sweep.json", ec)) out.push_back(e.path());
  std::sort(out.begin(), out.end());
  return out;
}

ReportPage report_page_from_output(const std::vector<fs::path>& dirs) {
  ReportPage page;
  for (const auto& d : dirs) {
    page.sources.push_back(fs::absolute(d).lexically_normal().string());
    const auto sweeps = find_sweeps(d);
    page.sweeps.insert(page.sweeps.end(), sweeps.begin(), sweeps.end());
    if (!sweeps.empty() && !is_output_folder(d)) continue;  // a folder of sweeps only
    for (const auto& j : scan_output_folder(d)) page.jobs.push_back(page_job(j));
  }
  return page;
}

// ---- the page -------------------------------------------------------------------------------------

std::string report_html(const ReportPage& page) {
  std::ostringstream o;
  std::map<std::string, int> counts;
  for (const auto& j : page.jobs) ++counts[job_verdict(j)];
  o << "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
    << "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">"
    << "<meta name=\"generator\" content=\"specbake\"><title>" << esc(page.title) << "</title>\n<style>\n"
    << resource("src/runner/report/page.css") << "</style>\n</head>\n<body>\n"
    << "<div id=\"js-errors\" hidden></div>\n<header><h1>" << esc(page.title) << "</h1><p class=\"sources\">";
  for (const auto& s : page.sources) o << "<code>" << esc(s) << "</code> ";
  o << "</p><p class=\"summary\">" << page.jobs.size() << " job(s): <span class=\"badge pass\">" << counts["pass"]
    << " passed</span> <span class=\"badge warn\">" << counts["warn"] << " with warnings</span> <span class=\"badge fail\">"
    << counts["fail"] << " failed</span></p></header>\n";

  // The overview: one row per job, linking to its section.
  o << "<section><h2>Jobs</h2><input id=\"filter\" type=\"search\" placeholder=\"filter jobs (name, kind, status)\">"
    << "<table id=\"jobs\" class=\"jobs\"><thead><tr><th>job</th><th>kind</th><th>status</th><th>time</th>"
    << "<th>bundle size</th><th>headline accuracy</th><th>warnings</th><th>created (UTC)</th></tr></thead><tbody>\n";
  for (std::size_t i = 0; i < page.jobs.size(); ++i) {
    const PageJob& j = page.jobs[i];
    std::string size = "–";
    if (!j.bundle.empty())
      if (const json m = read_manifest_or_null(j.bundle); m.is_object()) size = human_bytes(bundle_bytes(j.bundle, m));
    o << "<tr class=\"" << job_verdict(j) << "\"><td><a href=\"#" << anchor(i) << "\">" << esc(j.name)
      << "</a></td><td>" << esc(j.kind.empty() ? "–" : j.kind) << "</td><td>" << esc(j.status) << "</td><td>"
      << seconds_text(j.seconds) << "</td><td>" << size << "</td><td>" << esc(accuracy_headline(j.accuracy));
    const auto failed = std::count_if(j.accuracy.begin(), j.accuracy.end(), [](const json& a) { return verdict(a) == "fail"; });
    if (failed) o << " <span class=\"badge fail\">" << failed << " record(s) failed</span>";
    o << "</td><td>" << j.warnings.size() << "</td><td>" << esc(j.created_utc.empty() ? "–" : j.created_utc)
      << "</td></tr>\n";
  }
  o << "</tbody></table></section>\n";

  // Per job: the whole record.
  for (std::size_t i = 0; i < page.jobs.size(); ++i) {
    const PageJob& j = page.jobs[i];
    const json manifest = j.bundle.empty() ? json(nullptr) : read_manifest_or_null(j.bundle);
    o << "<section class=\"job " << job_verdict(j) << "\" id=\"" << anchor(i) << "\" data-kind=\""
      << esc(j.kind) << "\"><h2>" << esc(j.name) << " <small>" << esc(j.kind) << " · " << esc(j.status)
      << "</small></h2>\n<table class=\"kv\">";
    const auto row = [&](const char* k, const std::string& v) {
      if (!v.empty()) o << "<tr><th>" << k << "</th><td>" << esc(v) << "</td></tr>";
    };
    if (!j.reason.empty() && j.status != "published") row("reason", j.reason);
    row("config", j.config);
    row("bundle", j.bundle.string());
    row("hash", j.hash.substr(0, 12));
    if (manifest.is_object()) {
      const json dev = manifest.value("device", json::object());
      if (dev.is_object()) row("device", dev.value("name", "") + " (" + dev.value("platform", "") + ")");
      const json tool = manifest.value("tool", json::object());
      if (tool.is_object()) row("tool", "specbake " + tool.value("version", "?"));
    }
    row("bake time", j.seconds < 0 ? "" : seconds_text(j.seconds));
    o << "</table>\n";
    if (!j.warnings.empty()) {
      o << "<div class=\"warnings\"><h4>Warnings</h4><ul>";
      for (const auto& w : j.warnings) o << "<li>" << esc(w) << "</li>";
      o << "</ul></div>\n";
    }
    if (manifest.is_object())
      o << previews_html(j, manifest) << live_html(j, manifest, i);
    if (!j.accuracy.empty()) {
      o << "<h4>Accuracy</h4>";
      for (const auto& a : j.accuracy) o << record_html(a) << "\n";
    }
    if (manifest.is_object()) o << changes_html(j, manifest);
    else if (!j.bundle.empty()) o << "<p class=\"note\">cannot read " << esc((j.bundle / "manifest.json").string()) << "</p>";
    if (j.parameters.is_object() && !j.parameters.empty())
      o << "<details><summary>Parameters</summary>" << details_html(j.parameters) << "</details>\n";
    o << "</section>\n";
  }
  o << sweeps_html(page.sweeps);
  o << "<footer>made by specbake; opens from disk: no server, no network.</footer>\n<script>\n"
    << resource("src/runner/report/page.js") << "</script>\n";
  for (const char* js : {"live.js", "sky.js", "prism.js", "lobes.js"})
    o << "<script>\n" << resource(std::string("src/runner/report/") + js) << "</script>\n";
  o << "</body></html>\n";
  return o.str();
}

fs::path report_html_path(const std::string& file_or_dir) {
  if (file_or_dir.empty()) return "report.html";
  std::error_code ec;
  if (file_or_dir.back() == '/') fs::create_directories(file_or_dir, ec);  // a failure is named by the check
  if (file_or_dir.back() == '/' || fs::is_directory(file_or_dir, ec)) return fs::path(file_or_dir) / "report.html";
  return file_or_dir;
}

void check_report_html_path(const fs::path& file, const std::string& option) {
  std::error_code ec;
  if (fs::is_directory(file, ec)) throw UsageError(option + " " + file.string() + " is a folder; expected a file path");
  const fs::path parent = fs::absolute(file).parent_path();
  if (!fs::is_directory(parent, ec)) throw IoError("cannot write " + file.string() + ": no folder " + parent.string());
  if (::access(parent.c_str(), W_OK) != 0 || (fs::exists(file, ec) && ::access(file.c_str(), W_OK) != 0))
    throw IoError("cannot write " + file.string() + ": permission denied");
}

void write_report_html(const ReportPage& page, const fs::path& file) {
  const std::string html = report_html(page);
  const fs::path tmp = file.string() + ".tmp";
  {
    std::ofstream o(tmp, std::ios::binary);
    o << html;
    if (!o.flush()) {
      std::error_code ec;
      fs::remove(tmp, ec);
      throw IoError("cannot write " + tmp.string());
    }
  }
  std::error_code ec;
  fs::rename(tmp, file, ec);
  if (ec) {
    fs::remove(tmp, ec);
    throw IoError("cannot write " + file.string() + ": " + ec.message());
  }
  spdlog::debug("report: wrote {} ({} jobs, {} bytes)", file.string(), page.jobs.size(), html.size());
}

}  // namespace specbake
