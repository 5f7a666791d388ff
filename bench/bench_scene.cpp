#include "bench/bench_scene.h"

#include <cstdlib>

#include "vocabulary/errors.h"

namespace prt::bench {

#ifndef PRT_SHARED_DATA_DIR
#define PRT_SHARED_DATA_DIR "../shared/data"
#endif

std::string DataDir() {
  if (const char* d = std::getenv("PRT_DATA_DIR"); d != nullptr && *d != '\0') return d;
  return PRT_DATA_DIR;
}

SceneDescription BenchScene(const std::string& name, int n) {
  std::string text = DefaultSceneText();
  auto replace = [&](const std::string& from, const std::string& to) {
    const auto pos = text.find(from);
    if (pos == std::string::npos) throw InputError("<bench scene>", "default scene lacks " + from);
    text.replace(pos, from.size(), to);
  };
  if (name == "armadillo") {
    replace("name = \"bunny\"\n", "name = \"armadillo\"\n");
    replace("meshes/bunny00.off", "meshes/armadillo.off");
  } else if (name == "dragon") {
    replace("name = \"bunny\"\n", "name = \"dragon\"\n");
    replace("meshes/bunny00.off", "meshes/ChineseDragon-10kv.off");
  } else if (name == "camel") {
    replace("name = \"bunny\"\n", "name = \"camel\"\n");
    replace("meshes/bunny00.off", "meshes/camel.off");
  } else if (name == "lion") {
    replace("name = \"bunny\"\n", "name = \"lion\"\n");
    replace("meshes/bunny00.off", "meshes/lion-head.off");
  } else if (name == "horse") {  // ../shared/data only; Z up, wound inward (mesh-import.md)
    replace("name = \"bunny\"\n", "name = \"horse\"\n");
    replace("meshes/bunny00.off", "meshes/horse_cyberware.ply");
    replace("up = \"+y\" }", "up = \"+z\" }\nflip_winding = true");
  } else if (name == "teapot") {  // ../shared/data only; Z up
    replace("name = \"bunny\"\n", "name = \"teapot\"\n");
    replace("meshes/bunny00.off", "meshes/utah_teapot_24x24.obj");
    replace("up = \"+y\" }", "up = \"+z\" }");
  } else if (name != "default" && name != "bunny") {
    throw InputError("<bench scene>",
                     "unknown benchmark scene '" + name +
                         "' (default, armadillo, dragon, camel, lion, horse, teapot)");
  }
  SceneDescription scene =
      ParseScene(text, "<bench scene " + name + ">", "", {DataDir(), PRT_SHARED_DATA_DIR});
  if (n > 0) scene.cubemap_n = n;
  return scene;
}

}  // namespace prt::bench
