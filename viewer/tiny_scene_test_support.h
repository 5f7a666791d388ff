// Test support for viewer_tests: the tiny scene of tests/data/tiny.toml (a unit box on an 8×8
// ground grid, 72 samples) ray traced with the worker's TransportSampler, compressed (adaptive
// 4D) and packed with the packager's writer, as the farm and prt-pack would.
#pragma once

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "formats/compressed_transport.h"
#include "packager/prtpack_transport.h"
#include "packager/prtpack_writer.h"
#include "vocabulary/scene.h"
#include "vocabulary/scene_geometry.h"
#include "worker/column_order.h"
#include "worker/embree_scene.h"
#include "worker/transport_compressor.h"
#include "worker/transport_sampler.h"

namespace prt::testing {

struct TinyScene {
  SceneGeometry geometry;
  std::vector<float> rows;  // samples × 6n², texel basis, albedo-free, the pack's sample order
  int n = 8;
  std::string pack;
};

// Traces tests/data/tiny.toml at cubemap size n (0: the file's, 8) with `rays` stratified rays
// per texel.
inline TinyScene TraceTinyScene(int n = 0, int rays = 16) {
  TinyScene t;
  SceneDescription d = LoadSceneFile(std::string(PRT_SOURCE_DIR) + "/tests/data/tiny.toml");
  if (n > 0) d.cubemap_n = n;
  t.n = d.cubemap_n;
  t.geometry = BuildSceneGeometry(d);
  const EmbreeScene embree(t.geometry);
  const TransportSampler sampler(embree, t.n, {rays, 1});
  const std::vector<SpatialSample> samples = SpatialSamplesOf(t.geometry);
  t.rows.resize(samples.size() * sampler.layout().texel_count());
  sampler.ComputeRows(samples, 0, t.rows.data());
  return t;
}

// Adaptive 4D, every coefficient kept, at 16 bits: compression adds ~1e-4 to a relit image.
inline CompressionOptions KeepAllCompression(int bits = 16) {
  CompressionOptions o;
  o.bits = bits;
  o.keep_fraction = 1.0;
  return o;
}

// Compresses `rows` (the scene's samples × 6n² texels; with channels = 3, 3 × samples rows,
// channel-major: row c·samples + s is colour channel c of sample s) with `o` and packs them with
// the scene's meshes and a camera into `path`.
inline std::string PackTinyRows(const TinyScene& t, const std::vector<float>& rows,
                                const std::string& path,
                                const CompressionOptions& o = KeepAllCompression(),
                                uint32_t channels = 1) {
  const CompressedTransport ct =
      channels == 1 ? CompressTransport(rows.data(), t.n, SpatialDomainOf(t.geometry), o)
                    : CompressTransport(
                          rows.data(),
                          MakeCompressedHeader(
                              o, t.n,
                              SpatialDomainOf(t.geometry, CompressionSettings{}.order_normal_weight,
                                              channels),
                              channels),
                          o);
  pack::PackInput in;
  in.metadata_json =
      R"({"scene": {"scene": {"name": "tiny"}, "camera": {"eye": [2.0, 2.0, 3.0],
         "target": [0.0, 0.3, 0.0], "up": [0.0, 1.0, 0.0], "fov": 45.0, "width": 64,
         "height": 48}}})";
  in.meshes = pack::PackMeshesOf(t.geometry);
  in.transport = pack::MakeTransportInput(ct, 64);
  pack::WritePackFile(path, in);
  return path;
}

}  // namespace prt::testing
