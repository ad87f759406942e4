// The diffraction kind's entry in the kind table.
#include "kinds/diffraction/kind.hpp"

#include "kinds/diffraction/diffraction_job.hpp"
#include "kinds/diffraction/terms.hpp"

namespace specbake::diffraction {

Kind kind() {
  Kind k = Kind::of<DiffractionSpec>("diffraction", "Taylor / Chebyshev FFT terms of a surface heightfield for a real-time diffraction BRDF", parse_spec, plan, bake);
  // Measured on PoCL (2 cores): 0.3-1 s for the bundled 256²-1024² fields; grows with M² log M.
  k.cost_s = [](const JobSpec& j) {
    const auto& s = j.as<DiffractionSpec>();
    const double w = s.procedural ? s.procedural->size : (s.field ? s.field->width : 0);
    const double h = s.procedural ? s.procedural->size : (s.field ? s.field->height : 0);
    return 0.3 + 2e-6 * w * h;
  };
  k.memory = [](const JobSpec& j) {
    const auto& s = j.as<DiffractionSpec>();
    const std::uint64_t w = s.procedural ? s.procedural->size : (s.field ? s.field->width : 0);
    const std::uint64_t h = s.procedural ? s.procedural->size : (s.field ? s.field->height : 0);
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
    if (p.contains("table_size")) s += ", table " + p["table_size"].dump() + "^2";
    if (p.contains("bins") && p["bins"].contains("ku"))
      s += ", bins " + p["bins"]["ku"].dump() + " x " + p["bins"]["kv"].dump();
    return s;
  };
  return k;
}

}  // namespace specbake::diffraction
