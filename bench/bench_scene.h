// The benchmark scenes by name, shared by every benchmark program (bench_scenes.h adds what
// needs the viewer: environments, relit radiance, images). No viewer and no worker here, so that
// compression_bench links only the worker.
#pragma once

#include <string>

#include "vocabulary/scene.h"

namespace prt::bench {

// Data folder: $PRT_DATA_DIR if set, else the build tree's data/ (compiled in).
std::string DataDir();

// A benchmark scene by name: "default" (the bunny), "armadillo", "dragon" (the CGAL 10k-vertex
// Chinese dragon), "camel", "lion" (the CGAL lion head), and from ../shared/data
// (PRT_SHARED_DATA_DIR) "horse" (Cyberware, 48k vertices) and "teapot" (Utah, 18.5k), each in
// the default scene's place on its ground plane; `n` overrides the cubemap resolution (0 keeps
// the scene's). Throws InputError for an unknown name.
SceneDescription BenchScene(const std::string& name, int n = 0);

}  // namespace prt::bench
