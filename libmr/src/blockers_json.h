// Private to libmr: the "blockers" object of the scene document (docs/scene.md), shared with the
// annotations document (docs/annotations.md), which carries the same schema so that a user who
// annotates a photo can also state what the photo does not show. Defined in scene_json.cpp.
#pragma once

#include <string>

#include "json_reading.h"
#include "mr/scene.h"

namespace mr::detail {

/// Reads a "blockers" object at JSON pointer `pointer` (errors name it). Values are not
/// range-checked here: validate_scene does that (scene_validate.cpp).
Blockers read_blockers_json(const json::Json& j, const std::string& pointer,
                            const json::JsonReader& reader);

/// Every field of `blockers`, as the scene document writes them.
json::Json blockers_json(const Blockers& blockers);

}  // namespace mr::detail
