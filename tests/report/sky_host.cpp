// The host's side of the report page's WebGL check (tests/report/browser_test.py): for an
// atmosphere bundle and the float32 inputs the page's live sky used (sun direction, altitude),
// the double evaluation of the shipped GetSkyRadiance (kinds/atmosphere/shader/shader_host.hpp, the same
// source text as the bundle's sampling.glsl) from the bundle's float32 texels at each pixel of the
// page's n x n equidistant fisheye, and the per-pixel bound on |GL − host| of the llvmpipe GL test
// (atmosphere/gl_pixel_bound.hpp: texel-coordinate rounding, float32 geometry and arithmetic).
//   sky_host BUNDLE N SUN_X SUN_Y SUN_Z ALTITUDE_KM  →  JSON {kind, value, bound} on stdout
// Pixels row 0 at the bottom (as readPixels returns them), R, G, B innermost; kind 0 a sky ray,
// −1 outside the fisheye's circle (value and bound 0).
#include <cstdio>
#include <cstdlib>
#include <iostream>

#include <nlohmann/json.hpp>

#include "atmosphere/gl_pixel_bound.hpp"
#include "core/errors.hpp"
#include "kinds/atmosphere/shader/render.hpp"
#include "kinds/atmosphere/truth/truth.hpp"

using namespace specbake;
using namespace specbake::testing::gl_bound;

int main(int argc, char** argv) {
  if (argc != 7) {
    std::fprintf(stderr, "usage: sky_host BUNDLE N SUN_X SUN_Y SUN_Z ALTITUDE_KM\n");
    return 2;
  }
  try {
    const atmosphere::Luts luts = atmosphere::load_bundle_luts(argv[1]);
    const int n = std::atoi(argv[2]);
    const dvec3 sun = f32(dvec3{std::atof(argv[3]), std::atof(argv[4]), std::atof(argv[5])});
    const double h = f32(std::atof(argv[6]));
    const auto& m = luts.model;
    const auto& s = m.sizes;
    const std::vector<double> combined = combined_texture(luts);
    Host host = host_of(luts, combined);
    host.sky_view = atmosphere::glsl::sky_view_samplers(luts);  // the page reads the table where there is one
    const dvec3 up{0, 0, 1};
    nlohmann::json kind = nlohmann::json::array(), value = nlohmann::json::array(), bound = nlohmann::json::array();
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x) {
        Pixel p;
        atmosphere::Vec3 dir{};
        if (atmosphere::fisheye_direction((2.0 * x + 1.0) / n - 1.0, (2.0 * y + 1.0) / n - 1.0, dir)) {
          p.dir = f32(dvec3{dir[0], dir[1], dir[2]});
          p.kind = 0;
        }
        kind.push_back(static_cast<int>(p.kind));
        Out v, b;
        if (p.kind == 0) {
          v = host.eval(up, h, sun, p);
          b = bound_of(host, up, h, sun, p, v);
        }
        for (int c = 0; c < 3; ++c) value.push_back(v.v[0][c]), bound.push_back(b.v[0][c]);
      }
    std::cout << nlohmann::json{{"n", n}, {"kind", kind}, {"value", value}, {"bound", bound}}.dump() << "\n";
    return 0;
  } catch (const Error& e) {
    std::fprintf(stderr, "sky_host: %s\n", e.what());
    return static_cast<int>(e.exit_code());
  }
}
