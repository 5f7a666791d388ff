#include "worker/column_order.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdlib>
#include <numeric>
#include <random>

#include "vocabulary/errors.h"

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

TEST(HilbertIndex, EveryDimensionIsABijectionWhoseConsecutiveCellsAreFaceNeighbours) {
  for (int dims = 1; dims <= 6; ++dims) {
    for (int bits = 1; bits <= (dims <= 3 ? 4 : 2); ++bits) {
      const uint32_t side = 1u << bits;
      std::size_t cells = 1;
      for (int i = 0; i < dims; ++i) cells *= side;
      std::vector<std::vector<uint32_t>> at(cells);
      std::vector<uint32_t> axes(dims, 0);
      for (std::size_t c = 0; c < cells; ++c) {
        std::size_t r = c;
        for (int i = 0; i < dims; ++i, r /= side) axes[i] = static_cast<uint32_t>(r % side);
        const uint64_t h = HilbertIndex(axes, bits);
        ASSERT_LT(h, cells);
        ASSERT_TRUE(at[h].empty()) << "index used twice";
        at[h] = axes;
      }
      for (std::size_t h = 1; h < cells; ++h) {
        int d = 0;
        for (int i = 0; i < dims; ++i)
          d += std::abs(static_cast<int>(at[h][i]) - static_cast<int>(at[h - 1][i]));
        EXPECT_EQ(d, 1) << dims << "D, bits " << bits << ", index " << h;
      }
    }
  }
  const uint32_t a[3] = {5, 9, 2};
  EXPECT_EQ(HilbertIndex(a, 4), HilbertIndex3D(5, 9, 2, 4));
  EXPECT_THROW(HilbertIndex(std::vector<uint32_t>(6, 0), 11), std::invalid_argument);
}

TEST(HilbertOrder, NormalWeightSeparatesTheTwoSidesOfAThinSheet) {
  // Two sides of a sheet 1e-3 thick, points interleaved in space, normals opposite: by position
  // alone the order alternates sides; with the normal axes each side is a few long runs (the
  // curve crosses the normal's half-spaces a few times, as the Gray code of the top bits does).
  std::vector<Vec3> p, nrm;
  for (int i = 0; i < 32; ++i)
    for (int j = 0; j < 32; ++j)
      for (int side = 0; side < 2; ++side) {
        p.push_back({i / 31.0, j / 31.0, side * 1e-3});
        nrm.push_back({0, 0, side ? 1.0 : -1.0});
      }
  const auto switches = [&](const std::vector<uint32_t>& order) {
    int n = 0;
    for (std::size_t k = 1; k < order.size(); ++k) n += nrm[order[k]].z != nrm[order[k - 1]].z;
    return n;
  };
  EXPECT_GT(switches(HilbertOrder(p)), 500);
  EXPECT_LE(switches(HilbertOrder(p, nrm, 1.0)), 8);
  EXPECT_THROW(HilbertOrder(p, std::vector<Vec3>(3), 1.0), std::invalid_argument);
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

// With 3 colour channels the domain of the 3·V channel-major rows: the spatial segments three
// times, so that every segment lies inside one channel.
TEST(SpatialDomainOf, ThreeChannelsRepeatTheSpatialSegments) {
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
  const SpatialDomain one = SpatialDomainOf(g);
  const SpatialDomain three = SpatialDomainOf(g, 2.0, 3);
  ASSERT_EQ(three.segments.size(), 6u);
  EXPECT_EQ(three.sample_count(), 78u);
  for (std::size_t i = 0; i < 6; ++i) {
    EXPECT_EQ(three.segments[i].kind, one.segments[i % 2].kind);
    EXPECT_EQ(three.segments[i].count, one.segments[i % 2].count);
    EXPECT_EQ(three.segments[i].order, one.segments[i % 2].order);
  }
  EXPECT_EQ(SpatialDomainOf(g, 2.0, 1).segments.size(), 2u);
  EXPECT_THROW(SpatialDomainOf(g, 2.0, 2), InputError);
}

TEST(SpatialDomainOf, MeshOrderUsesTheNormalsWithTheGivenWeight) {
  SceneGeometry g;
  SceneMesh m;
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-1, 1);
  for (int i = 0; i < 200; ++i) {
    m.mesh.positions.push_back({u(rng), u(rng), 0.01 * u(rng)});
    m.mesh.normals.push_back({0, 0, i % 2 ? 1.0 : -1.0});
  }
  g.meshes.push_back(m);
  EXPECT_EQ(SpatialDomainOf(g, 0.0).segments[0].order, HilbertOrder(m.mesh.positions));
  EXPECT_EQ(SpatialDomainOf(g, 2.0).segments[0].order,
            HilbertOrder(m.mesh.positions, m.mesh.normals, 2.0));
  EXPECT_NE(SpatialDomainOf(g, 2.0).segments[0].order, HilbertOrder(m.mesh.positions));
  EXPECT_EQ(
      SpatialDomainOf(g).segments[0].order,
      HilbertOrder(m.mesh.positions, m.mesh.normals, CompressionSettings{}.order_normal_weight));
}

}  // namespace
}  // namespace prt
