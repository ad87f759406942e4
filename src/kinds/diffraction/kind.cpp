// The diffraction kind's entry in the kind table.
#include "kinds/diffraction/kind.hpp"

#include <algorithm>
#include <cmath>

#include "kinds/diffraction/diffraction_job.hpp"
#include "kinds/diffraction/table.hpp"
#include "kinds/diffraction/terms.hpp"

namespace specbake::diffraction {

Kind kind() {
  Kind k = Kind::of<DiffractionSpec>("diffraction", "Taylor / Chebyshev FFT terms of a surface heightfield for a real-time diffraction BRDF", parse_spec, plan, bake);
  // Full bins, measured on PoCL (2 cores): 0.3-1 s for the bundled 256²-1024² fields; grows with
  // M² log M. With a table (docs/diffraction.md, the 8192² rows): previews ≈ 2.8 s, field, plan
  // and the direct sums of the error ≈ 1.5e-7 s per sample, the NUFFT ≈ 3.4e-8 s per term, kept
  // row and padded point (T = 16 when terms: auto).
  k.cost_s = [](const JobSpec& j) {
    const auto& s = j.as<DiffractionSpec>();
    const int w = s.procedural ? s.procedural->size : (s.field ? s.field->width : 0);
    const int h = s.procedural ? s.procedural->size : (s.field ? s.field->height : 0);
    if (!s.table) return 0.3 + 2e-6 * w * h;
    const double dx = s.procedural ? s.procedural->dx_um : s.field->dx_um;
    const double sigma = coherence_length_um(s) / std::sqrt(2.0);
    const AxisExtent ex = fft_extent(w, dx, sigma), ey = fft_extent(h, dx, sigma);
    const double terms = s.terms ? *s.terms : 16;
    return 2.8 + 1.5e-7 * w * h + 3.4e-8 * terms * (static_cast<double>(ex.n) * ey.kept + static_cast<double>(ey.n) * 1024);
  };
  k.memory = [](const JobSpec& j) {
    const auto& s = j.as<DiffractionSpec>();
    const std::uint64_t w = s.procedural ? s.procedural->size : (s.field ? s.field->width : 0);
    const std::uint64_t h = s.procedural ? s.procedural->size : (s.field ? s.field->height : 0);
    if (s.table) {
      // Host: the heightfield in double; the row-stage results of a group of terms (float pairs,
      // at most 768 MiB); the batches of rows and columns being transformed (at most 128 MiB
      // each); every candidate table of a phase in double (T·ΣN²·16 bytes, ΣN² ≤ 768²). Device:
      // one batch of rows. T = 16 when terms: auto.
      const double dx = s.procedural ? s.procedural->dx_um : s.field->dx_um;
      const double sigma = coherence_length_um(s) / std::sqrt(2.0);
      const AxisExtent ex = fft_extent(static_cast<int>(w), dx, sigma), ey = fft_extent(static_cast<int>(h), dx, sigma);
      const std::uint64_t terms = s.terms ? *s.terms : 16, mib = std::uint64_t{1} << 20;
      const std::uint64_t rows = std::min<std::uint64_t>(768 * mib, terms * ey.kept * 1024 * 8);
      const std::uint64_t batch = std::min<std::uint64_t>(128 * mib, terms * ey.kept * ex.n * 8);
      const std::uint64_t tables = terms * 768 * 768 * 16;
      return MemoryEstimate{batch, batch, w * h * 8 + rows + 2 * batch + tables};
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
    if (p.contains("bins") && p["bins"].contains("ku"))
      s += ", bins " + p["bins"]["ku"].dump() + " x " + p["bins"]["kv"].dump();
    return s;
  };
  return k;
}

}  // namespace specbake::diffraction
