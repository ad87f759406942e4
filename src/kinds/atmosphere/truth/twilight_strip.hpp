#pragma once
// The twilight strip (preview/twilight_strip.png): how the bake holds up as the sun sets, beside
// the truth. The sky towards the sun's azimuth from the scene's lowest camera, the sun from
// −12° (or the lowest the textures hold) to +10° across in 1° columns, the view from the horizon
// to 40° up (rows packed towards the horizon), in three labelled panels: the bake
// (GetSkyRadiance from the textures), the path-traced truth at the same views (its walks as the
// scene check's, to a 3 % target at an eighth of its walk cap), and the CIEDE2000 between them.
// Each sun column is exposed at the truth's mean luminance over that column (a renderer's auto
// exposure: the sky dims ~10⁵× across the strip), and the colour difference is taken at that
// exposure. Columns beyond the scene's suns are hatched (the bake holds them with its 4D textures
// alone: no sky-view table there), and each band's record has its figures inside the scene apart.
// Made for scenes that reach deep twilight (sun below −6°), with previews on.
// docs/atmosphere.md, "Previews".
#include <nlohmann/json.hpp>

#include "cl/device.hpp"
#include "io/bundle.hpp"
#include "job/kind.hpp"
#include "kinds/atmosphere/model/spec.hpp"
#include "kinds/atmosphere/shader/render.hpp"

namespace specbake::atmosphere {

struct TwilightStrip {
  OutputFile png;
  nlohmann::json record;  // the strip's geometry, walks, and the CIEDE2000 per sun band
};

bool wants_twilight_strip(const AtmosphereSpec& spec);
// What its truth costs on the 2-core CPU (truth_seconds' model); 0 when the spec wants none.
double twilight_strip_seconds(const AtmosphereSpec& spec);
// The strip's truth is kept in `keep` (its store) as the scene's is.
TwilightStrip twilight_strip(const AtmosphereSpec& spec, const Luts& luts, cl_util::Device& dev, Memo& keep,
                             const Progress& progress);

}  // namespace specbake::atmosphere
