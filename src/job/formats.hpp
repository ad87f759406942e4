#pragma once
// `formats:` of a job: which copies of its data a bundle holds. Every kind takes a non-empty list
// of its own format names (atmosphere and diffraction: bin, exr, ktx2; dispersion: bin, json),
// each at most once; the kinds' docs say what each one writes.
#include <set>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/yaml_at.hpp"

namespace specbake {

// The formats a job asks for: `by_default` without a `formats` key, else the listed ones, failing
// at the key (file, line, column) on an empty list, a name not in `allowed` (with the closest
// one) or a repeat. `norm["formats"]` gets the list, in `allowed`'s order, when it differs from
// the default (the default keeps the bundle hash of configs that do not name it).
std::set<std::string> parse_formats(const yaml::At& job, const std::vector<std::string>& allowed,
                                    const std::vector<std::string>& by_default, nlohmann::json& norm);

}  // namespace specbake
