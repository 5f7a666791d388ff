// The scene's camera from a pack's metadata, and the --camera override (see camera_metadata.h).
#include "runtime/camera_metadata.h"

#include <cmath>
#include <cstdlib>
#include <nlohmann/json.hpp>
#include <sstream>
#include <stdexcept>
#include <vector>

#include "vocabulary/errors.h"
#include "vocabulary/scene.h"

namespace prt {

namespace {

Vec3 JsonVec3(const nlohmann::json& j, const std::string& name, const char* key) {
  if (!j.is_array() || j.size() != 3)
    throw InputError(name,
                     std::string("metadata scene.camera.") + key + " is not an array of 3 numbers");
  Vec3 v;
  for (int i = 0; i < 3; ++i) {
    if (!j[static_cast<std::size_t>(i)].is_number())
      throw InputError(name, std::string("metadata scene.camera.") + key + " is not numeric");
    const double x = j[static_cast<std::size_t>(i)].get<double>();
    if (!std::isfinite(x))
      throw InputError(name, std::string("metadata scene.camera.") + key + " is not finite");
    (i == 0 ? v.x : (i == 1 ? v.y : v.z)) = x;
  }
  return v;
}

}  // namespace

bool CameraFromMetadata(const std::string& metadata_json, const std::string& name, Camera& camera,
                        const SceneTomlCameraFn& scene_toml_camera) {
  const nlohmann::json meta = nlohmann::json::parse(metadata_json, nullptr, false);
  if (meta.is_discarded() || !meta.is_object() || !meta.contains("scene")) return false;
  const nlohmann::json& scene = meta["scene"];
  if (!scene.is_object()) return false;
  nlohmann::json cam;
  if (scene.contains("camera") && scene["camera"].is_object()) {
    cam = scene["camera"];
  } else if (scene.contains("toml") && scene["toml"].is_string()) {
    // scene.toml kept as text (run_folder_pack.cpp's fallback): the caller's scene parser.
    return scene_toml_camera && scene_toml_camera(scene["toml"].get<std::string>(), name, camera);
  } else {
    return false;
  }
  Camera c = camera;
  if (cam.contains("eye")) c.eye = JsonVec3(cam["eye"], name, "eye");
  if (cam.contains("target")) c.target = JsonVec3(cam["target"], name, "target");
  if (cam.contains("up")) c.up = JsonVec3(cam["up"], name, "up");
  if (cam.contains("fov")) {
    if (!cam["fov"].is_number()) throw InputError(name, "metadata scene.camera.fov is not numeric");
    c.fov_deg = cam["fov"].get<double>();
  }
  for (const char* key : {"width", "height"}) {
    if (!cam.contains(key)) continue;
    if (!cam[key].is_number_integer() || cam[key].get<int64_t>() < 1 ||
        cam[key].get<int64_t>() > 16384)
      throw InputError(
          name, std::string("metadata scene.camera.") + key + " is not an integer in 1..16384");
    (std::string(key) == "width" ? c.width : c.height) = cam[key].get<int>();
  }
  camera = c;
  return true;
}

Camera ParseCameraSpec(const std::string& spec, const Camera& base) {
  std::vector<double> v;
  std::stringstream ss(spec);
  std::string item;
  while (std::getline(ss, item, ',')) {
    char* end = nullptr;
    const double x = std::strtod(item.c_str(), &end);
    if (item.empty() || end == item.c_str() || *end != '\0' || !std::isfinite(x))
      throw std::invalid_argument("--camera: '" + item + "' is not a finite number");
    v.push_back(x);
  }
  if (v.size() != 6 && v.size() != 9 && v.size() != 10)
    throw std::invalid_argument(
        "--camera takes eye_x,eye_y,eye_z,target_x,target_y,target_z[,up_x,up_y,up_z[,fov]] "
        "(6, 9 or 10 numbers), got " +
        std::to_string(v.size()));
  Camera c = base;
  c.eye = {v[0], v[1], v[2]};
  c.target = {v[3], v[4], v[5]};
  if (v.size() >= 9) c.up = {v[6], v[7], v[8]};
  if (v.size() == 10) c.fov_deg = v[9];
  return c;
}

}  // namespace prt
