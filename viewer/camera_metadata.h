// The camera a pack was farmed with (its metadata's scene → camera) and the --camera override:
// what prt-view, its window and the glossy renderer start a frame from.
#pragma once

#include <string>

#include "vocabulary/scene.h"

namespace prt {

// The scene's camera from a pack's metadata JSON: "scene" → "camera" (eye, target, up, fov,
// width, height; missing keys keep Camera{}'s defaults). Returns false (camera untouched) when
// there is none; throws prt::InputError(name, ...) on a camera whose values have the wrong type.
bool CameraFromMetadata(const std::string& metadata_json, const std::string& name, Camera& camera);

// "ex,ey,ez,tx,ty,tz" with optionally ",ux,uy,uz" and then ",fov": overrides those fields of
// `base`. Throws std::invalid_argument on any other count or a non-finite number.
Camera ParseCameraSpec(const std::string& spec, const Camera& base);

}  // namespace prt
