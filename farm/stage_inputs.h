// The manifest of stage inputs (farm/run_manifest.h) for a scene and a command line: what each
// stage's output depends on, and nothing else (docs/farm.md, "Stages and re-runs").
#pragma once

#include <cstdint>
#include <string>

#include "farm/farm_options.h"
#include "farm/run_manifest.h"
#include "formats/compressed_transport.h"
#include "vocabulary/scene.h"
#include "worker/transport_compressor.h"

namespace prt {

// What the compression stage is keyed with and the compression phase writes with: the options
// (the scene's [compression], --compression-scheme over it) and the header transport.prtc gets.
// Throws InputError naming the scene file on bad settings.
struct CompressionPlan {
  CompressionOptions options;
  CompressedTransportHeader header;
};
// channels: rows of T per sample (3 with bounces and coloured albedos, docs/interreflection.md);
// terms: the glossy factorisation's (docs/glossy-transport.md), the domain's segments once each.
CompressionPlan PlanCompression(const SceneDescription& scene, const SceneGeometry& geometry,
                                int cubemap_n, const FarmOptions& options, int channels = 1,
                                int terms = 1);

// What setup resolved from the scene and the command line (the overrides applied).
struct ResolvedSampling {
  std::string job = "transport";  // transport | visibility
  std::string method = "brute";   // brute | sparse (transport only)
  int cubemap_n = 32;
  int rays_per_texel = 4;
  uint64_t seed = 1;
  uint64_t rows = 0;
  // Interreflection (docs/interreflection.md); bounces 0: no indirect stage.
  int bounces = 0;
  std::string estimator = "gather";
  int indirect_n = 0;
  int gather_paths = 1024;
  double near_field = 1.0;
  int channels = 1;
  // Glossy vertex transport (docs/glossy-transport.md): the factorisation's terms (rows already
  // counts them) and the XXH64 of run/glossy.prtf's bytes; 1 and 0 when every mesh is diffuse.
  int terms = 1;
  uint64_t glossy_factors = 0;
};

// XXH64 of what the rays see of the geometry: every mesh's positions, normals and triangles,
// the ground flag and grid, the bounds; not names or albedos.
uint64_t TracedGeometryChecksum(const SceneGeometry& geometry);

// The compression stage's "header_xxh64": XXH64 of the encoded header, 16 hex digits (what a
// transport.prtc in the folder is checked against).
std::string CompressedHeaderKey(const CompressedTransportHeader& header);

// XXH64 of an environment file's bytes, or 0 when it cannot be read.
uint64_t EnvironmentFileChecksum(const std::string& path);

// The manifest for `scene` (as parsed from `scene_text`), its `geometry`, the resolved sampling
// and the command line. Throws InputError naming the scene file on bad compression settings.
// `compression` (optional) receives the plan the compression stage is keyed with (transport
// runs), for the compression phase to use as it is.
RunManifest MakeRunManifest(const SceneDescription& scene, const std::string& scene_text,
                            const SceneGeometry& geometry, const std::string& geometry_bytes,
                            const ResolvedSampling& sampling, const FarmOptions& options,
                            CompressionPlan* compression = nullptr);

}  // namespace prt
