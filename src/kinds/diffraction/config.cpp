// Config of the diffraction job: a heightfield (file or procedural), the scene's
// wavelength range and w_max, the expansion, its term count and tolerance, centring, crop and
// EXR storage. Heightfield files are read and checked here, so a bad file stops the run
// before any job bakes; their sha256 enters the bundle hash.
#include <cerrno>
#include <cstring>
#include <fstream>
#include <sstream>

#include "core/hash.hpp"
#include "core/resources.hpp"
#include "core/spectral_data.hpp"
#include "core/text.hpp"
#include "io/heightfield.hpp"
#include "kinds/diffraction/spec.hpp"
#include "kinds/diffraction/table.hpp"

namespace specbake::diffraction {

using yaml::At;

namespace {

constexpr int kMaxProceduralSize = 8192;

const char* to_string(ProceduralField::Type t) {
  switch (t) {
    case ProceduralField::Type::sine_grating: return "sine-grating";
    case ProceduralField::Type::binary_grating: return "binary-grating";
    case ProceduralField::Type::blazed_grating: return "blazed-grating";
    case ProceduralField::Type::eggcrate: return "eggcrate";
  }
  return "?";
}

// The file's bytes; an InputError at the config's `file` key saying why it cannot be read.
std::string read_bytes(const fs::path& p, const At& file_at) {
  std::error_code ec;
  if (fs::is_directory(p, ec)) file_at.fail("heightfield " + p.string() + " is a folder; expected a file");
  errno = 0;
  std::ifstream in(p, std::ios::binary);
  if (!in) file_at.fail("cannot read heightfield " + p.string() + ": " + std::strerror(errno ? errno : EIO));
  std::ostringstream s;
  s << in.rdbuf();
  if (!in && !in.eof()) file_at.fail("cannot read heightfield " + p.string() + ": read error");
  return s.str();
}

ProceduralField parse_procedural(const At& at, nlohmann::json& norm) {
  at.expect_map("a procedural heightfield {type, size, dx_um, period_um, ...}");
  if (!at.has("type")) at.fail("expected a 'type' key (sine-grating | binary-grating | blazed-grating | eggcrate)");
  ProceduralField p;
  p.type = at.child("type").choice<ProceduralField::Type>({{"sine-grating", ProceduralField::Type::sine_grating},
                                                           {"binary-grating", ProceduralField::Type::binary_grating},
                                                           {"blazed-grating", ProceduralField::Type::blazed_grating},
                                                           {"eggcrate", ProceduralField::Type::eggcrate}});
  const char* height_key = p.type == ProceduralField::Type::sine_grating ? "amplitude_um"
                           : p.type == ProceduralField::Type::eggcrate   ? "peak_to_valley_um"
                                                                         : "depth_um";
  at.allow_keys({"type", "size", "dx_um", "period_um", height_key});
  for (const char* k : {"size", "dx_um", "period_um", height_key})
    if (!at.has(k)) at.fail(std::string("expected a '") + k + "' key for a " + to_string(p.type));
  const At size = at.child("size");
  const long long m = size.integer();
  if (m < 2 || m > kMaxProceduralSize)
    size.fail("expected an integer in [2, " + std::to_string(kMaxProceduralSize) + "], got " + size.shown());
  p.size = static_cast<int>(m);
  p.dx_um = at.child("dx_um").positive();
  p.period_um = at.child("period_um").positive();
  if (p.period_um < 2.0 * p.dx_um) at.child("period_um").fail("expected period_um >= 2·dx_um (at least 2 samples)");
  p.amplitude_um = at.child(height_key).number();
  if (p.amplitude_um < 0) at.child(height_key).fail("expected a height >= 0 (µm)");
  norm = {{"type", to_string(p.type)}, {"size", p.size}, {"dx_um", p.dx_um}, {"period_um", p.period_um},
          {height_key, p.amplitude_um}};
  return p;
}

std::shared_ptr<const Heightfield> parse_file_field(const At& at, nlohmann::json& norm, Inputs& inputs,
                                                    std::string& source) {
  at.expect_map("a heightfield {file, dx_um, height_um | size}");
  at.allow_keys({"file", "dx_um", "height_um", "size"});
  if (!at.has("file")) at.fail("expected a 'file' key (PNG, BMP, EXR or raw float32, relative to the config)");
  if (!at.has("dx_um")) at.fail("expected a 'dx_um' key (sample spacing in µm)");
  const At file_at = at.child("file");
  const std::string given = file_at.string();
  const fs::path path = at.file->parent_path() / given;
  HeightfieldRead how;
  how.file = path;
  try {
    how.format = heightfield_format(path);
  } catch (const InputError&) {
    file_at.fail("expected a heightfield file ending in .png, .bmp, .exr, .raw or .f32, got '" + given + "'");
  }
  how.dx_um = at.child("dx_um").positive();
  norm = {{"file", given}, {"format", to_string(how.format)}, {"dx_um", how.dx_um}};
  if (holds_grey_levels(how.format)) {
    if (!at.has("height_um")) at.fail("expected 'height_um' (height of the largest grey level) for a grey image");
    if (at.has("size")) at.child("size").fail("'size' applies to raw float32 files only");
    how.height_um = at.child("height_um").positive();
    norm["height_um"] = how.height_um;
  } else {
    if (at.has("height_um"))
      at.child("height_um").fail("'height_um' applies to grey images only; EXR and raw files hold heights in µm");
    if (how.format == HeightfieldFormat::raw) {
      if (!at.has("size")) at.fail("expected 'size: [W, H]' for a raw float32 heightfield");
      const At s = at.child("size");
      const auto v = s.numbers(2, 2);
      for (int i = 0; i < 2; ++i)
        if (v[i] != static_cast<double>(static_cast<long long>(v[i])) || v[i] < 2 || v[i] > 16384)
          s.item(i).fail("expected an integer in [2, 16384]");
      how.raw_size = std::make_pair(static_cast<int>(v[0]), static_cast<int>(v[1]));
      norm["size"] = {how.raw_size->first, how.raw_size->second};
    } else if (at.has("size")) {
      at.child("size").fail("'size' applies to raw float32 files only");
    }
  }
  std::error_code ec;
  if (!fs::exists(path, ec)) file_at.fail("heightfield file not found: " + path.string());
  const std::string bytes = read_bytes(path, file_at);
  inputs.emplace_back("heightfield:" + given, sha256_hex(bytes));
  source = given;
  return std::make_shared<const Heightfield>(decode_heightfield(bytes, how));
}

// `table: none | {size, mapping, power, f_max_per_um, tolerance}`, `coherence: {length_um} |
// {source_angular_diameter_deg}` (with a table only) and `max_bundle_mb`.
void parse_table_keys(const At& job, DiffractionSpec& d) {
  d.budget_at = job.loc();
  if (job.has("max_bundle_mb")) {
    d.max_bundle_mb = job.child("max_bundle_mb").number_in(1e-3, 1e7, "in [0.001, 1e7] (MB)");
    d.budget_at = job.child("max_bundle_mb").loc();
  }
  if (job.has("table")) {
    const At t = job.child("table");
    if (t.node.IsScalar() && t.node.Scalar() == "none") {
      // today's full-bin output
    } else {
      t.expect_map("'none' or a table {size, mapping, power, f_max_per_um, tolerance}");
      t.allow_keys({"size", "mapping", "power", "f_max_per_um", "tolerance"});
      TableSpec ts;
      if (t.has("size")) {
        ts.size = t.child("size").count_or_auto(kMinTableSize, kMaxTableSize);
        if (ts.size && *ts.size % 2) t.child("size").fail("expected an even size (the centre falls between texels), got " +
                                                          t.child("size").shown());
      }
      // The power mapping is the default: it puts texels across the specular peak (docs/diffraction.md).
      ts.power_mapping = true;
      if (t.has("mapping")) ts.power_mapping = t.child("mapping").choice<bool>({{"linear", false}, {"power", true}});
      if (t.has("power")) {
        if (!ts.power_mapping) t.child("power").fail("'power' applies to mapping: power only");
        ts.power = t.child("power").number_in(1.0, 8.0, "in [1, 8]");
      } else if (ts.power_mapping) {
        ts.power = 3.0;
      }
      if (t.has("f_max_per_um")) ts.f_max_per_um = t.child("f_max_per_um").positive();
      if (t.has("tolerance")) ts.tolerance = t.child("tolerance").number_in(1e-9, 1.0, "in [1e-9, 1]");
      d.table = ts;
      if (!job.has("max_bundle_mb")) d.budget_at = t.loc();
    }
  }
  if (job.has("coherence")) {
    const At c = job.child("coherence");
    if (!d.table) c.fail("'coherence' applies with a table (table: {size, ...}); table: none keeps the unwindowed field");
    c.expect_map("{length_um: L} or {source_angular_diameter_deg: theta}");
    c.allow_keys({"length_um", "source_angular_diameter_deg"});
    if (c.has("length_um") == c.has("source_angular_diameter_deg"))
      c.fail("expected exactly one of 'length_um' or 'source_angular_diameter_deg'");
    if (c.has("length_um")) d.coherence.length_um = c.child("length_um").positive();
    else
      d.coherence.source_angular_diameter_deg =
          c.child("source_angular_diameter_deg").number_in(1e-6, 90.0, "in (0, 90] (degrees)");
  }
}

}  // namespace

DiffractionSpec parse_spec(const At& job, nlohmann::json& norm, Inputs& inputs) {
  allow_job_keys(job, {"heightfield", "procedural", "range_nm", "w_max", "expansion", "terms", "tolerance",
                  "center", "crop", "storage", "coherence", "table", "max_bundle_mb", "formats", "ktx2", "previews"});
  DiffractionSpec d;
  nlohmann::json field_norm;
  if (job.has("heightfield") == job.has("procedural"))
    job.fail("expected exactly one of 'heightfield' (a file) or 'procedural'");
  if (job.has("heightfield")) {
    d.field = parse_file_field(job.child("heightfield"), field_norm, inputs, d.source);
    field_norm = {{"heightfield", field_norm}};
  } else {
    d.procedural = parse_procedural(job.child("procedural"), field_norm);
    d.source = "procedural " + field_norm["type"].get<std::string>();
    field_norm = {{"procedural", field_norm}};
  }
  const CmfTable& cmf = cmf_table(CmfSet::cie1931_2deg);
  inputs.emplace_back(cmf.resource, sha256_hex(resource(cmf.resource)));
  inputs.emplace_back("data/cie/d65_1nm.csv", sha256_hex(resource("data/cie/d65_1nm.csv")));
  if (job.has("range_nm")) {
    const At r = job.child("range_nm");
    const auto v = r.numbers(2, 2);
    if (!(v[0] < v[1])) r.fail("expected [lo, hi] with lo < hi (nm)");
    if (v[0] < cmf.first_nm || v[1] > cmf.last_nm)
      r.fail("expected a range inside the CIE 1931 table's [" + std::to_string(static_cast<int>(cmf.first_nm)) + ", " +
             std::to_string(static_cast<int>(cmf.last_nm)) + "] nm");
    d.range_nm = {v[0], v[1]};
  }
  if (job.has("w_max")) d.w_max = job.child("w_max").number_in(1e-6, 2.0, "in (0, 2]");
  if (job.has("expansion"))
    d.expansion = job.child("expansion").choice<Expansion>({{"taylor", Expansion::taylor},
                                                           {"chebyshev", Expansion::chebyshev}});
  if (job.has("terms")) d.terms = job.child("terms").count_or_auto(1, kMaxDiffractionTerms);
  if (job.has("tolerance")) d.tolerance = job.child("tolerance").number_in(1e-12, 1.0, "in [1e-12, 1]");
  if (job.has("center"))
    d.center = job.child("center").choice<Centre>({{"mid-range", Centre::mid_range}, {"mean", Centre::mean},
                                                  {"none", Centre::none}});
  if (job.has("crop")) d.crop = job.child("crop").choice<bool>({{"auto", true}, {"none", false}});
  if (job.has("storage"))
    d.storage = job.child("storage").choice<Storage>({{"float32", Storage::float32}, {"half", Storage::half}});

  parse_table_keys(job, d);
  if (d.table) {
    // The window must span samples: σ = L/√2 below the spacing leaves about one sample.
    const double dx = d.procedural ? d.procedural->dx_um : d.field->dx_um;
    const double length = coherence_length_um(d);
    if (length / std::sqrt(2.0) < dx) {
      const At at = !job.has("coherence")                 ? job
                    : job.child("coherence").has("length_um") ? job.child("coherence").child("length_um")
                                                              : job.child("coherence").child("source_angular_diameter_deg");
      at.fail("the coherence length " + format_g(length) + " um gives a window sigma = L/sqrt(2) below the sample "
              "spacing dx_um = " + format_g(dx) + ": the table would hold the transform of about one sample; "
              "expected L >= " + format_g(dx * std::sqrt(2.0)) + " um");
    }
  }

  norm = {{"kind", "diffraction"},
          {"field", field_norm},
          {"range_nm", {d.range_nm.lo, d.range_nm.hi}},
          {"w_max", d.w_max},
          {"expansion", d.expansion == Expansion::taylor ? "taylor" : "chebyshev"},
          {"terms", d.terms ? nlohmann::json(*d.terms) : nlohmann::json("auto")},
          {"tolerance", d.tolerance},
          {"center", d.center == Centre::mid_range ? "mid-range" : d.center == Centre::mean ? "mean" : "none"},
          {"crop", d.crop ? "auto" : "none"},
          {"storage", d.storage == Storage::float32 ? "float32" : "half"},
          {"cmf", "cie1931-2deg"},
          {"illuminant", "D65"}};
  // Table keys enter the normalised config (and so the bundle hash) only when set, so the
  // hashes of jobs without them stay what they were.
  if (d.table) {
    norm["table"] = {{"size", d.table->size ? nlohmann::json(*d.table->size) : nlohmann::json("auto")},
                     {"mapping", d.table->power_mapping ? "power" : "linear"},
                     {"power", d.table->power},
                     {"f_max_per_um", d.table->f_max_per_um ? nlohmann::json(*d.table->f_max_per_um) : nlohmann::json("auto")},
                     {"tolerance", d.table->tolerance}};
    norm["coherence"] = d.coherence.length_um
                            ? nlohmann::json{{"length_um", *d.coherence.length_um}}
                            : nlohmann::json{{"source_angular_diameter_deg", d.coherence.source_angular_diameter_deg}};
  }
  if (job.has("max_bundle_mb")) norm["max_bundle_mb"] = d.max_bundle_mb;
  if (job.has("previews")) {  // in the hash only when given
    const At pv = job.child("previews");
    if (pv.node.IsScalar() && pv.node.Scalar() == "none") {
      d.previews = false;
      norm["previews"] = "none";
    } else {
      pv.expect_map("previews: none, or {size: N} (pixels per picture side, an even number in [32, 2048])");
      pv.allow_keys({"size"});
      if (pv.has("size")) {
        const At n = pv.child("size");
        const long long v = n.integer();
        if (v < 32 || v > 2048 || v % 2) n.fail("expected an even number of pixels in [32, 2048], got " + n.shown());
        d.preview_size = static_cast<int>(v);
        norm["previews"] = {{"size", d.preview_size}};
      }
    }
  }
  const TextureFormats f = parse_texture_formats(job, norm);
  d.ktx2 = f.ktx2;
  d.write_bin = f.bin;
  d.write_exr = f.exr;
  return d;
}

}  // namespace specbake::diffraction
