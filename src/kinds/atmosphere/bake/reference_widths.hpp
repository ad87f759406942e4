#pragma once
// The double reference at every pass width (kPassWidths): atmosphere.cl and host_pass.inc
// compiled once per channel count, and with_width(), which hands a width's entry points
// (host_pass.inc's `Width`) to a generic callable. Only the pass driver needs this; the
// renderer and most tests use ref3 from reference.hpp.
#include <string>

#include "kinds/atmosphere/bake/reference.hpp"

namespace specbake::atmosphere {

namespace ref4 {
SPECBAKE_ATMOSPHERE_REF_PROLOGUE
#define NCH 4
#include "atmosphere/atmosphere.cl"
#include "kinds/atmosphere/bake/host_pass.inc"
#undef NCH
}  // namespace ref4

namespace ref8 {
SPECBAKE_ATMOSPHERE_REF_PROLOGUE
#define NCH 8
#include "atmosphere/atmosphere.cl"
#include "kinds/atmosphere/bake/host_pass.inc"
#undef NCH
}  // namespace ref8

namespace ref16 {
SPECBAKE_ATMOSPHERE_REF_PROLOGUE
#define NCH 16
#include "atmosphere/atmosphere.cl"
#include "kinds/atmosphere/bake/host_pass.inc"
#undef NCH
}  // namespace ref16

static_assert(std::size(kPassWidths) == 4 && kPassWidths[0] == 3 && kPassWidths[1] == 4 && kPassWidths[2] == 8 &&
                  kPassWidths[3] == 16,
              "with_width() must list every pass width");

// f(refN::Width{}) for the pass width `width`; throws for a width without a reference.
template <class F>
decltype(auto) with_width(int width, F&& f) {
  switch (width) {
    case 3: return f(ref3::Width{});
    case 4: return f(ref4::Width{});
    case 8: return f(ref8::Width{});
    case 16: return f(ref16::Width{});
  }
  throw JobError("atmosphere: no pass of width " + std::to_string(width));
}

}  // namespace specbake::atmosphere
