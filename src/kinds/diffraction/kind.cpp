// The diffraction kind's entry in the kind table.
#include "kinds/diffraction/kind.hpp"

#include <algorithm>
#include <cmath>

#include "kinds/diffraction/diffraction_job.hpp"
#include "kinds/diffraction/table.hpp"
#include "kinds/diffraction/terms.hpp"

namespace specbake::diffraction {

namespace {
// What the estimates need of a job before its field is made: its size, and with a table the
// samples the window keeps and the transform lengths per axis (table.hpp, fft_extent).
struct Shape {
  std::uint64_t w = 0, h = 0;
  AxisExtent x, y;
  double terms = 16;  // terms: auto counts 16
};
Shape shape_of(const DiffractionSpec& s) {
  Shape sh;
  sh.w = s.procedural ? s.procedural->size : (s.field ? s.field->width : 0);
  sh.h = s.procedural ? s.procedural->size : (s.field ? s.field->height : 0);
  if (s.terms) sh.terms = *s.terms;
  if (s.table) {
    const double dx = s.procedural ? s.procedural->dx_um : s.field->dx_um;
    const double sigma = coherence_length_um(s) / std::sqrt(2.0);
    sh.x = fft_extent(static_cast<int>(sh.w), dx, sigma);
    sh.y = fft_extent(static_cast<int>(sh.h), dx, sigma);
  }
  return sh;
}
}  // namespace

Kind kind() {
  Kind k = Kind::of<DiffractionSpec>("diffraction", "Taylor / Chebyshev FFT terms of a surface heightfield for a real-time diffraction BRDF", parse_spec, plan, bake);
  // Full bins, measured on PoCL (2 cores): 0.3-1 s for the bundled 256²-1024² fields; grows with
  // M² log M. With a table (docs/diffraction.md, the 8192² rows): previews ≈ 2.8 s, field, plan
  // and the direct sums of the error ≈ 1.5e-7 s per sample, the NUFFT ≈ 3.4e-8 s per term, kept
  // row and padded point.
  k.cost_s = [](const JobSpec& j) {
    const Shape sh = shape_of(j.as<DiffractionSpec>());
    const double samples = static_cast<double>(sh.w) * static_cast<double>(sh.h);
    if (!j.as<DiffractionSpec>().table) return 0.3 + 2e-6 * samples;
    return 2.8 + 1.5e-7 * samples +
           3.4e-8 * sh.terms * (static_cast<double>(sh.x.n) * sh.y.kept + static_cast<double>(sh.y.n) * 1024);
  };
  k.memory = [](const JobSpec& j) {
    const Shape sh = shape_of(j.as<DiffractionSpec>());
    const std::uint64_t w = sh.w, h = sh.h;
    if (j.as<DiffractionSpec>().table) {
      // Device: the heights (double on fp64 devices), the row-stage results of a group of terms
      // (float pairs, at most 768 MiB), the batches of rows and of columns being transformed (at
      // most 128 MiB each), every candidate table of a phase (float pairs, T·ΣN²·8 bytes, ΣN² ≤
      // 768²), the exact sums' windowed rows (2 × 64 MiB). Host: the heightfield in double, the
      // tables read back, the chosen table's files.
      const auto terms = static_cast<std::uint64_t>(sh.terms), mib = std::uint64_t{1} << 20;
      const std::uint64_t kept = static_cast<std::uint64_t>(sh.y.kept);
      const std::uint64_t rows = std::min<std::uint64_t>(768 * mib, terms * kept * 1024 * 8);
      const std::uint64_t batch = std::min<std::uint64_t>(128 * mib, terms * kept * static_cast<std::uint64_t>(sh.x.n) * 8);
      const std::uint64_t tables = terms * 768 * 768 * 8, heights = w * h * 8;
      return MemoryEstimate{heights + rows + 2 * batch + tables + 128 * mib, std::max({heights, rows, tables}),
                            heights + 2 * tables};
    }
    // Complex float fields of the heightfield's size: the term input, the FFT buffer and the
    // cropped terms (at most the full field per term, counted as two fields), plus a complex
    // double field for the exact transforms of the self-check.
    const std::uint64_t field = w * h * 8;
    // Host: the heightfield and exact-DFT fields in double (complex), the float terms read back
    // (at most a few fields' worth when cropped) and their file encodings.
    return MemoryEstimate{4 * field + 2 * field, 2 * field, w * h * (8 + 2 * 16) + 6 * field + (std::uint64_t{1} << 26)};
  };
  k.programs = {kProgram};
  // with a table, what a shader's filtered fetch reads: the error between texels
  k.truth_records = {"vs_exact_transform", "table_between_texels"};
  k.describe = [](const nlohmann::json& p) {
    std::string s = std::to_string(p.value("terms", 0)) + " " + p.value("expansion", "?") + " terms";
    if (p.contains("field"))
      s += ", field " + std::to_string(p["field"].value("width", 0)) + "x" + std::to_string(p["field"].value("height", 0));
    if (p.contains("table_size"))
      s += p["table_size"].is_string() ? ", table auto" : ", table " + p["table_size"].dump() + "^2";
    else
      s += ", no GLSL (table: none)";  // only a table is a shader's texture (docs/diffraction.md)
    if (p.contains("bins") && p["bins"].contains("ku"))
      s += ", bins " + p["bins"]["ku"].dump() + " x " + p["bins"]["kv"].dump();
    return s;
  };
  return k;
}

}  // namespace specbake::diffraction
