// run/geometry.prtg (docs/transport-format.md, "geometry.prtg"): the SceneGeometry the samples
// were taken from (names, albedo, positions, normals, triangles, ground grid resolution), in double
// precision so that any row can be recomputed bit-exactly from it. Little-endian, XXH64 at the end.
// The parser is safe on untrusted input: every count is checked against the bytes left.
#pragma once

#include <string>
#include <string_view>

#include "vocabulary/scene_geometry.h"

namespace prt {

std::string SerializeSceneGeometry(const SceneGeometry& geometry);
// `name` is used in error messages. Throws InputError on any inconsistency.
SceneGeometry ParseSceneGeometry(std::string_view bytes, const std::string& name);
void WriteSceneGeometryFile(const std::string& path, const SceneGeometry& geometry);
SceneGeometry ReadSceneGeometryFile(const std::string& path);

}  // namespace prt
