#include "worker/embree_scene.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <limits>
#include <random>
#include <span>
#include <stdexcept>
#include <vector>

#include "vocabulary/errors.h"

namespace prt {
namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();

// A unit square [0,1]² in the plane y = height, two triangles.
SceneMesh Square(double height, const std::string& name = "square") {
  SceneMesh m;
  m.name = name;
  m.mesh.source = name + ".off";
  m.mesh.positions = {{0, height, 0}, {1, height, 0}, {1, height, 1}, {0, height, 1}};
  m.mesh.normals.assign(4, Vec3{0, 1, 0});
  m.mesh.triangles = {{0, 2, 1}, {0, 3, 2}};
  return m;
}

OcclusionRay Ray(Vec3 o, Vec3 d, float tfar = kInf) {
  const Vec3 u = Normalize(d);
  return OcclusionRay{{static_cast<float>(o.x), static_cast<float>(o.y), static_cast<float>(o.z)},
                      0.0f,
                      {static_cast<float>(u.x), static_cast<float>(u.y), static_cast<float>(u.z)},
                      tfar};
}

TEST(EmbreeScene, BuildsOneGeometryPerMeshWithBounds) {
  SceneGeometry g;
  g.meshes = {Square(0.0, "a"), Square(2.0, "b")};
  const EmbreeScene scene(g);
  EXPECT_EQ(scene.geometry_count(), 2u);
  EXPECT_EQ(scene.triangle_count(), 4u);
  EXPECT_EQ(scene.bounds_min(), (Vec3{0, 0, 0}));
  EXPECT_EQ(scene.bounds_max(), (Vec3{1, 2, 1}));
  EXPECT_DOUBLE_EQ(scene.extent(), std::sqrt(6.0));
  EXPECT_NEAR(scene.max_triangle_diameter(), std::sqrt(2.0), 1e-15);
}

TEST(EmbreeScene, OccludedHitsAndMissesBothSidesAndRespectsTfar) {
  SceneGeometry g;
  g.meshes = {Square(1.0)};
  const EmbreeScene scene(g);
  EXPECT_TRUE(scene.Occluded(Ray({0.5, 0, 0.5}, {0, 1, 0})));
  EXPECT_TRUE(scene.Occluded(Ray({0.5, 2, 0.5}, {0, -1, 0})));  // back face hits too
  EXPECT_FALSE(scene.Occluded(Ray({0.5, 0, 0.5}, {0, -1, 0})));
  EXPECT_FALSE(scene.Occluded(Ray({1.5, 0, 0.5}, {0, 1, 0})));
  EXPECT_FALSE(scene.Occluded(Ray({0.5, 0, 0.5}, {0, 1, 0}, 0.99f)));
  EXPECT_TRUE(scene.Occluded(Ray({0.5, 0, 0.5}, {0, 1, 0}, 1.01f)));
  const std::vector<OcclusionRay> rays = {Ray({0.5, 0, 0.5}, {0, 1, 0}),
                                          Ray({0.5, 0, 0.5}, {0, -1, 0}),
                                          Ray({0.2, 0, 0.7}, {0.1, 1, 0.1})};
  EXPECT_EQ(scene.CountOccluded(rays), 2u);
}

// Packets give each ray Occluded()'s answer, whatever the packet's size (1…16), its lanes'
// origins and limits (rays from different points, tfar before and after the square, rays
// grazing its edges), and refuse more than 16 rays; the counting loop agrees with CountOccluded.
TEST(EmbreeScene, OccludedPacketAgreesWithOccludedRayByRay) {
  SceneGeometry g;
  g.meshes = {Square(1.0), Square(2.5, "upper")};
  const EmbreeScene scene(g);
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-0.5, 1.5);
  std::vector<OcclusionRay> rays;
  for (int i = 0; i < 997; ++i) {
    const Vec3 o{u(rng), u(rng) - 0.5, u(rng)};
    const Vec3 d{u(rng) - 0.5, u(rng), u(rng) - 0.5};
    if (Length(d) == 0) continue;
    rays.push_back(Ray(o, d, i % 3 == 0 ? static_cast<float>(0.2 + u(rng)) : kInf));
  }
  rays.push_back(Ray({1.0, 0, 0.5}, {0, 1, 0}));  // along an edge
  rays.push_back(Ray({0.0, 0, 0.0}, {0, 1, 0}));  // through a corner
  const ScopedFlushDenormals ftz;
  std::size_t checked = 0, occluded = 0;
  for (std::size_t i = 0, size = 1; i < rays.size(); i += size, size = size % 16 + 1) {
    const std::size_t count = std::min(size, rays.size() - i);
    bool blocked[EmbreeScene::kPacket];
    std::fill_n(blocked, EmbreeScene::kPacket, false);
    scene.OccludedPacket(std::span<const OcclusionRay>(rays).subspan(i, count), blocked);
    for (std::size_t j = 0; j < count; ++j) {
      EXPECT_EQ(blocked[j], scene.Occluded(rays[i + j])) << i + j;
      occluded += blocked[j] ? 1 : 0;
      ++checked;
    }
  }
  EXPECT_EQ(checked, rays.size());
  EXPECT_GT(occluded, rays.size() / 10);  // both answers occur
  EXPECT_LT(occluded, rays.size() * 9 / 10);
  EXPECT_EQ(scene.CountOccludedInPackets(rays), scene.CountOccluded(rays));
  scene.OccludedPacket({}, nullptr);  // nothing to do
  bool blocked[17];
  EXPECT_THROW(scene.OccludedPacket(std::span<const OcclusionRay>(rays).first(17), blocked),
               std::invalid_argument);
}

TEST(EmbreeScene, IntersectReportsTheClosestHit) {
  SceneGeometry g;
  g.meshes = {Square(1.0, "low"), Square(2.0, "high")};
  const EmbreeScene scene(g);
  RayHit hit;
  ASSERT_TRUE(scene.Intersect(Ray({0.75, 3, 0.25}, {0, -1, 0}), hit));
  EXPECT_FLOAT_EQ(hit.t, 1.0f);
  EXPECT_EQ(hit.geometry, 1u);
  EXPECT_EQ(hit.primitive, 0u);  // (0.75, 0.25) is in triangle {0, 2, 1}
  EXPECT_NEAR(std::abs(hit.geometric_normal.y), 1.0, 1e-12);
  ASSERT_TRUE(scene.Intersect(Ray({0.25, 1.5, 0.75}, {0, -1, 0}), hit));
  EXPECT_FLOAT_EQ(hit.t, 0.5f);
  EXPECT_EQ(hit.geometry, 0u);
  EXPECT_EQ(hit.primitive, 1u);
  EXPECT_FALSE(scene.Intersect(Ray({0.5, 0.5, 0.5}, {0, -1, 0}), hit));
}

TEST(EmbreeScene, EmptySceneOccludesNothing) {
  const EmbreeScene scene(SceneGeometry{});
  EXPECT_EQ(scene.geometry_count(), 0u);
  EXPECT_FALSE(scene.Occluded(Ray({0, 0, 0}, {0, 1, 0})));
  EXPECT_GT(scene.RayOffset({0, 0, 0}), 0.0);
}

TEST(EmbreeScene, RejectsBadInputNamingTheMesh) {
  SceneGeometry g;
  g.meshes = {Square(0.0, "nan")};
  g.meshes[0].mesh.positions[2].y = std::nan("");
  try {
    EmbreeScene scene(g);
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), "nan.off");
    EXPECT_NE(std::string(e.what()).find("vertex 2"), std::string::npos);
  }
  g.meshes = {Square(0.0, "index")};
  g.meshes[0].mesh.triangles[1][2] = 4;
  EXPECT_THROW(EmbreeScene scene(g), InputError);
  g.meshes = {Square(0.0, "huge")};
  g.meshes[0].mesh.positions[0].x = 1e39;  // not a float
  EXPECT_THROW(EmbreeScene scene(g), InputError);
}

// The offset is kRayOffsetUlps float epsilons of max(‖p‖∞, largest triangle diameter), and the
// rounded origin lies strictly on the normal's side of the surface.
TEST(EmbreeScene, RobustOriginIsScaleAwareAndOnTheRightSide) {
  SceneGeometry g;
  g.meshes = {Square(0.0)};
  const EmbreeScene scene(g);
  const double eps = kRayOffsetUlps * FLT_EPSILON;
  EXPECT_DOUBLE_EQ(scene.RayOffset({0.5, 0, 0.5}), eps * std::sqrt(2.0));
  EXPECT_DOUBLE_EQ(scene.RayOffset({1e3, 0, -5e3}), eps * 5e3);
  for (double far : {1.0, 1e3, 1e6}) {
    const Vec3 p{far + 0.1, 0.0, -far};
    float o[3];
    scene.RobustOrigin(p, {0, 1, 0}, o);
    EXPECT_GT(o[1], 0.0f);
    EXPECT_EQ(o[0], static_cast<float>(p.x));
    EXPECT_EQ(o[2], static_cast<float>(p.z));
  }
  // A tilted normal: the origin is above the plane through fl(p) by about δ·1.
  const Vec3 n = Normalize(Vec3{1, 2, 3});
  const Vec3 p{123.456, -7.89, 1000.5};
  float o[3];
  scene.RobustOrigin(p, n, o);
  const Vec3 pf{static_cast<float>(p.x), static_cast<float>(p.y), static_cast<float>(p.z)};
  const double height = Dot(Vec3{o[0], o[1], o[2]} - pf, n);
  EXPECT_GT(height, 0.5 * scene.RayOffset(p));
  EXPECT_LT(height, 1.5 * scene.RayOffset(p));
}

TEST(ScopedFlushDenormals, FlushesInsideAndRestoresAfter) {
  volatile float tiny = FLT_MIN / 4;  // a denormal
  volatile float one = 1.0f;
  {
    const ScopedFlushDenormals ftz;
    const float product = tiny * one;
    EXPECT_EQ(product, 0.0f);  // DAZ: the denormal input reads as 0
  }
  const float product = tiny * one;
  EXPECT_EQ(product, FLT_MIN / 4);
}

}  // namespace
}  // namespace prt
