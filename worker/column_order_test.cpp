#include "worker/column_order.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdlib>
#include <numeric>
#include <random>

namespace prt {
namespace {

TEST(HilbertIndex3D, IsABijectionWhoseConsecutiveCellsAreFaceNeighbours) {
  for (int bits = 1; bits <= 4; ++bits) {
    const uint32_t side = 1u << bits;
    const std::size_t cells = static_cast<std::size_t>(side) * side * side;
    std::vector<int> x(cells, -1), y(cells, -1), z(cells, -1);
    for (uint32_t i = 0; i < side; ++i)
      for (uint32_t j = 0; j < side; ++j)
        for (uint32_t k = 0; k < side; ++k) {
          const uint64_t h = HilbertIndex3D(i, j, k, bits);
          ASSERT_LT(h, cells);
          ASSERT_EQ(x[h], -1) << "index used twice";
          x[h] = static_cast<int>(i);
          y[h] = static_cast<int>(j);
          z[h] = static_cast<int>(k);
        }
    for (std::size_t h = 1; h < cells; ++h) {
      const int d =
          std::abs(x[h] - x[h - 1]) + std::abs(y[h] - y[h - 1]) + std::abs(z[h] - z[h - 1]);
      EXPECT_EQ(d, 1) << "bits " << bits << " index " << h;
    }
  }
}

TEST(HilbertOrder, VisitsAShuffledLatticeOneStepAtATime) {
  std::vector<Vec3> p;
  for (int i = 0; i < 16; ++i)
    for (int j = 0; j < 16; ++j)
      for (int k = 0; k < 16; ++k) p.push_back({0.5 * i - 3, 0.5 * j + 1, 0.5 * k});
  std::shuffle(p.begin(), p.end(), std::mt19937(4));
  const std::vector<uint32_t> order = HilbertOrder(p, 4);
  ASSERT_EQ(order.size(), p.size());
  std::vector<uint32_t> sorted = order;
  std::sort(sorted.begin(), sorted.end());
  for (uint32_t i = 0; i < sorted.size(); ++i) ASSERT_EQ(sorted[i], i);
  for (std::size_t k = 1; k < order.size(); ++k)
    EXPECT_NEAR(Length(p[order[k]] - p[order[k - 1]]), 0.5, 1e-12);
}

TEST(SpatialDomainOf, MeshesAreHilbertSegmentsAndTheGroundIsAGrid) {
  SceneGeometry g;
  SceneMesh m;
  for (int i = 0; i < 10; ++i)
    m.mesh.positions.push_back({std::cos(i * 0.6), std::sin(i * 0.6), 0.1 * i});
  g.meshes.push_back(m);
  SceneMesh ground;
  ground.is_ground = true;
  ground.grid_resolution = 4;
  ground.mesh.positions.resize(16);
  g.meshes.push_back(ground);
  const SpatialDomain d = SpatialDomainOf(g);
  ASSERT_EQ(d.segments.size(), 2u);
  EXPECT_EQ(d.segments[0].kind, SpatialSegment::Kind::kMesh1D);
  EXPECT_EQ(d.segments[0].count, 10u);
  EXPECT_EQ(d.segments[0].order.size(), 10u);
  EXPECT_EQ(d.segments[1].kind, SpatialSegment::Kind::kGrid2D);
  EXPECT_EQ(d.segments[1].width, 4u);
  EXPECT_EQ(d.sample_count(), 26u);
  EXPECT_EQ(ImageDomain(7, 3).segments[0].count, 21u);
}

}  // namespace
}  // namespace prt
