// The manifest of a run folder (docs/farm.md, "Stages and re-runs"): for each stage of the run,
// exactly the inputs that determine its output. A re-run (--resume) compares them with the
// inputs given now and recomputes the first stage whose inputs changed and every stage after it;
// the others are re-used. The folder's file names are formats/run_folder.h.
//
// Stages, in pipeline order (each depends on those before it):
//   rows         transport.prtt (or the visibility job's visibility.prtv) and the per-texel
//                variance sums: geometry as traced (positions, normals, triangles, ground; not
//                names or albedos), samples, n, rays per texel, seed, method and its settings,
//                rows per block
//   indirect     indirect/bounce-<k>.prtt (runs with [sampling] bounces > 0 only): the estimator,
//                bounces, the indirect grid's n, paths per vertex and the albedos
//   compression  transport.prtc: the compressed-transport header it is written with (scheme,
//                wavelets, bits, keep fraction, budget, dither seed, the samples' spatial order)
//   estimate     accuracy.json (the Monte-Carlo error of T and of B under the scene's
//                environments): the environments (paths and bytes) and the albedos
//   assets       scene.toml and geometry.prtg as prt-pack reads them (names, albedos,
//                materials, camera, comments): always rewritten, no computation
#pragma once

#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>
#include <utility>
#include <vector>

#include "formats/run_folder.h"

namespace prt {

inline constexpr const char* kStageRows = "rows";
inline constexpr const char* kStageIndirect = "indirect";
inline constexpr const char* kStageCompression = "compression";
inline constexpr const char* kStageEstimate = "estimate";
inline constexpr const char* kStageAssets = "assets";

inline constexpr int kManifestFormatVersion = 2;

struct RunManifest {
  int format_version = kManifestFormatVersion;
  // Stage name → its inputs (a JSON object), in pipeline order.
  std::vector<std::pair<std::string, nlohmann::ordered_json>> stages;

  // The stage's inputs (nullptr when the manifest has no such stage).
  const nlohmann::ordered_json* Stage(const std::string& name) const;
  void SetStage(const std::string& name, nlohmann::ordered_json inputs);
  // XXH64 of the stage's inputs and, for the stages computed from the rows (compression,
  // estimate), of the rows stage's key: equal keys, equal outputs.
  uint64_t StageKey(const std::string& name) const;
  std::string StageKeyHex(const std::string& name) const;  // 16 hex digits
  // The rows stage's key: the key of the checkpoint journal (its lines stay valid whatever
  // changes after the rows).
  uint64_t Key() const { return StageKey(kStageRows); }

  std::string ToJsonText() const;
  // Throws InputError naming `file` when the text is not a manifest. A manifest of an older
  // prt-farm (format 1, one key for the whole scene text) is read with no stages.
  static RunManifest FromJsonText(const std::string& text, const std::string& file);
  // "rays_per_texel 4 -> 9, sparse.window 7 -> 9" for the inputs of `stage` that differ from
  // `older`'s ("" when equal; "not recorded" when `older` lacks the stage).
  std::string StageDifferences(const std::string& stage, const RunManifest& older) const;
};

}  // namespace prt
