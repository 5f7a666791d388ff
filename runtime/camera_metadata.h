// The camera a pack was farmed with (its metadata's scene → camera) and the --camera override:
// what prt-view, its window and the glossy renderer start a frame from.
#pragma once

#include <functional>
#include <string>

#include "vocabulary/scene.h"

namespace prt {

// The scene's camera from a pack's metadata JSON: "scene" → "camera" (eye, target, up, fov,
// width, height; missing keys keep Camera{}'s defaults). Returns false (camera untouched) when
// there is none; throws prt::InputError(name, ...) on a camera whose values have the wrong type.
// A pack whose metadata kept scene.toml as text instead (run_folder_pack.cpp's fallback) needs a
// TOML parser, which the runtime does not link: `scene_toml_camera` (the viewer's
// SceneTomlCamera) reads the camera from that text, returning false when it cannot; without
// one such a pack has no camera here.
using SceneTomlCameraFn =
    std::function<bool(const std::string& toml, const std::string& name, Camera& camera)>;
bool CameraFromMetadata(const std::string& metadata_json, const std::string& name, Camera& camera,
                        const SceneTomlCameraFn& scene_toml_camera = {});

// "ex,ey,ez,tx,ty,tz" with optionally ",ux,uy,uz" and then ",fov": overrides those fields of
// `base`. Throws std::invalid_argument on any other count or a non-finite number.
Camera ParseCameraSpec(const std::string& spec, const Camera& base);

}  // namespace prt
