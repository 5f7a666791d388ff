#include "worker/visibility_sampler.h"

#include <gtest/gtest.h>

#include <vector>

#include "vocabulary/scene.h"

namespace prt {
namespace {

// A single upward quad: nothing above it, so a vertex on it sees exactly the texels whose
// centre is above its horizon.
SceneGeometry OpenPlane() {
  SceneGeometry g;
  SceneMesh m;
  m.name = m.mesh.source = "plane";
  m.mesh.positions = {{-1, 0, -1}, {1, 0, -1}, {1, 0, 1}, {-1, 0, 1}};
  m.mesh.normals.assign(4, {0, 1, 0});
  m.mesh.triangles = {{0, 2, 1}, {0, 3, 2}};
  g.meshes.push_back(m);
  g.bounds_min = {-1, 0, -1};
  g.bounds_max = {1, 0, 1};
  return g;
}

TEST(VisibilitySampler, OpenPlaneSeesItsUpperHemisphere) {
  const SceneGeometry g = OpenPlane();
  const EmbreeScene scene(g);
  const SpatialSample s{{0.1, 0, 0.2}, {0, 1, 0}, {0, 1, 0}};
  const VisibilitySampler sampler(scene, {.n = 16});
  std::vector<uint8_t> map(sampler.layout().texel_count());
  const VisibilitySamplerStats st = sampler.ComputeMap(s, map);
  for (std::size_t j = 0; j < map.size(); ++j)
    EXPECT_EQ(map[j], sampler.layout().TexelCenter(j).y > 0 ? 1 : 0) << j;
  EXPECT_EQ(st.texels_below_horizon + st.rays_traced, map.size());
  // Anti-aliased: texels entirely above the horizon are fully visible (level 2^bits − 1), those
  // entirely below are 0, and levels count the visible sub-texel centres.
  const VisibilitySampler aa(scene, {.n = 16, .supersample = 4, .bits = 4});
  aa.ComputeMap(s, map);
  for (std::size_t j = 0; j < map.size(); ++j) {
    int above = 0;
    for (int y = 0; y < 4; ++y)
      for (int x = 0; x < 4; ++x)
        above += aa.layout().TexelDirection(j, (x + 0.5) / 4, (y + 0.5) / 4).y > 0;
    EXPECT_EQ(map[j], std::lround(above * 15.0 / 16.0)) << j;
  }
}

// The default benchmark scene (the CGAL bunny on its ground grid): block-coded maps of real
// vertices decode to exactly the traced maps, survive serialisation, and do not depend on
// threading.
TEST(VisibilitySampler, RealMeshRoundTripIsLossless) {
  const SceneGeometry g = BuildSceneGeometry(LoadDefaultScene(PRT_DATA_DIR));
  const EmbreeScene scene(g);
  const std::vector<SpatialSample> all = SpatialSamplesOf(g);
  std::vector<SpatialSample> samples;
  for (std::size_t i = 0; i < all.size(); i += all.size() / 40) samples.push_back(all[i]);
  for (int bits : {1, 6}) {
    if (bits > 1) samples.resize(samples.size() / 2);  // 4 rays per texel: fewer vertices
    const VisibilitySampler sampler(scene,
                                    {.n = 64, .supersample = bits == 1 ? 1 : 2, .bits = bits});
    const VisibilityBlocks blocks = sampler.ComputeBlocks(samples);
    ASSERT_EQ(blocks.vertex_count, samples.size());
    std::vector<uint8_t> map(sampler.layout().texel_count());
    std::size_t occluded_above = 0;
    for (std::size_t v = 0; v < samples.size(); ++v) {
      sampler.ComputeMap(samples[v], map);
      ASSERT_EQ(DecodeVisibilityMap(blocks, v), map) << v;
      for (std::size_t j = 0; j < map.size(); ++j)
        occluded_above +=
            map[j] == 0 && Dot(sampler.layout().TexelCenter(j), samples[v].normal) > 0.2;
    }
    EXPECT_GT(occluded_above, 0u);  // the bunny and the ground do shadow each other
    const VisibilityBlocks back = DecodeVisibilityBlocks(EncodeVisibilityBlocks(blocks));
    EXPECT_EQ(back.change_pos, blocks.change_pos);
    EXPECT_EQ(back.change_value, blocks.change_value);
    EXPECT_EQ(back.kind, blocks.kind);
    const VisibilityBlockCounts c = CountVisibilityBlocks(blocks);
    EXPECT_GT(c.zero, c.mixed / 4);  // below-horizon halves are all-zero blocks
    EXPECT_GT(c.one, 0u);
  }
}

}  // namespace
}  // namespace prt
