#include "job/formats.hpp"

namespace specbake {

std::set<std::string> parse_formats(const yaml::At& job, const std::vector<std::string>& allowed,
                                    const std::vector<std::string>& by_default, nlohmann::json& norm) {
  std::set<std::string> chosen(by_default.begin(), by_default.end());
  if (!job.has("formats")) return chosen;
  std::string list;
  for (const auto& a : allowed) list += (list.empty() ? "" : ", ") + a;
  const yaml::At f = job.child("formats");
  chosen.clear();
  f.each_item("formats (" + list + ")", [&](const yaml::At& it) {
    const std::string name = it.node.IsScalar() ? it.node.Scalar() : "";
    bool known = false;
    for (const auto& a : allowed) known = known || a == name;
    if (!known) {
      const std::string near = closest_word(name, allowed);
      it.fail("expected a format of this kind (" + list + "), got " + it.shown() +
              (near.empty() ? "" : " (did you mean '" + near + "'?)"));
    }
    if (!chosen.insert(name).second) it.fail("format '" + name + "' is listed twice");
  });
  if (chosen != std::set<std::string>(by_default.begin(), by_default.end())) {
    norm["formats"] = nlohmann::json::array();
    for (const auto& a : allowed)
      if (chosen.count(a)) norm["formats"].push_back(a);
  }
  return chosen;
}

}  // namespace specbake
