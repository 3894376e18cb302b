#pragma once
// Shared by the two layouts of the objects file (object_config.cpp: ours; dope_config.cpp: DOPE's config_pose.yaml).
#include <set>
#include <string>
#include <vector>

#include <yaml-cpp/yaml.h>

#include "diffdope/object_config.hpp"

namespace diffdope::detail {

/// The checks every object passes, whichever layout it came from; resolves its mesh path.
void check_object(ObjectConfig& o, const std::string& entry, const std::string& origin, const std::string& base_dir,
                  const PackageResolver& resolve_package, std::set<std::string>& names);

/// The names with ", " between them ("" for none).
std::string joined(const std::vector<std::string>& names);

/// Whether the file is DOPE's config_pose.yaml (any of its own keys, and none of ours).
bool is_dope_config(const YAML::Node& root);

/// DOPE's config_pose.yaml (object_config.hpp).
ObjectsConfig parse_dope_config(const YAML::Node& root, const std::string& origin, const std::string& base_dir,
                                const PackageResolver& resolve_package, const RefinerOptions& base);

}  // namespace diffdope::detail
