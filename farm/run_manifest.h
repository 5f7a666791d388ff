// The manifest that ties a run folder's checkpoints (docs/farm.md, "Run folder") to one set of
// inputs, so that --resume never mixes rows of two different runs. The folder's file names are
// formats/run_folder.h.
#pragma once

#include <cstdint>
#include <string>

#include "formats/run_folder.h"

namespace prt {

// Everything that determines the bytes of transport.prtt. Two runs with equal manifests produce
// bit-identical files, whatever the number of ranks, threads or job sizes.
struct RunManifest {
  int format_version = 1;
  std::string method = "brute";
  int cubemap_n = 32;
  int rays_per_texel = 4;
  uint64_t seed = 1;
  uint64_t rows = 0;
  uint32_t rows_per_block = 256;
  uint64_t scene_checksum = 0;     // XXH64 of the scene text
  uint64_t geometry_checksum = 0;  // XXH64 of geometry.prtg
  // method "visibility" only (written only then): levels of the visibility maps. cubemap_n is
  // then the maps' n and rays_per_texel supersample².
  int visibility_bits = 0;

  std::string ToJsonText() const;
  // Throws InputError naming `file` when the text is not a manifest.
  static RunManifest FromJsonText(const std::string& text, const std::string& file);
  // XXH64 of ToJsonText(): the run key stored in the journal.
  uint64_t Key() const;
  // "rays_per_texel 4 → 16, ..." for the fields that differ ("" when equal).
  std::string DifferencesFrom(const RunManifest& older) const;
};

}  // namespace prt
