#include "vocabulary/mesh.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "vocabulary/errors.h"
#include "vocabulary/mesh_io.h"

namespace prt {
namespace {

namespace fs = std::filesystem;

// Expects `fn` to throw InputError whose message contains every one of `parts`.
template <class Fn>
void ExpectInputError(Fn fn, const std::vector<std::string>& parts) {
  try {
    fn();
    ADD_FAILURE() << "no InputError thrown";
  } catch (const InputError& e) {
    const std::string msg = e.what();
    for (const std::string& p : parts) {
      EXPECT_NE(msg.find(p), std::string::npos) << "'" << p << "' missing from: " << msg;
    }
  }
}

// The unit cube [0,1]³ as an indexed, outward-wound mesh (12 triangles). Vertex i has
// coordinates (i&1, (i>>1)&1, (i>>2)&1).
TriangleMesh UnitCube() {
  TriangleMesh m;
  for (int i = 0; i < 8; ++i)
    m.positions.push_back({double(i & 1), double(i >> 1 & 1), double(i >> 2 & 1)});
  m.triangles = {{0, 2, 1}, {1, 2, 3},   // z = 0, normal −z
                 {4, 5, 6}, {5, 7, 6},   // z = 1, normal +z
                 {0, 1, 4}, {1, 5, 4},   // y = 0, normal −y
                 {2, 6, 3}, {3, 6, 7},   // y = 1, normal +y
                 {0, 4, 2}, {2, 4, 6},   // x = 0, normal −x
                 {1, 3, 5}, {3, 7, 5}};  // x = 1, normal +x
  return m;
}

TEST(MeshTest, SignedVolumeOfUnitCubeIsOneAndOfInvertedCubeMinusOne) {
  TriangleMesh cube = UnitCube();
  EXPECT_NEAR(SignedVolume(cube), 1.0, 1e-15);
  AnalyzeTopology(cube);
  EXPECT_TRUE(cube.report.closed);
  EXPECT_EQ(cube.report.boundary_edges, 0u);
  EXPECT_FALSE(cube.report.inward_wound);
  ComputeAreaWeightedNormals(cube);
  FlipWinding(cube);
  EXPECT_NEAR(SignedVolume(cube), -1.0, 1e-15);
  AnalyzeTopology(cube);
  EXPECT_TRUE(cube.report.closed);
  EXPECT_TRUE(cube.report.inward_wound);
  // Translation does not change the volume of a closed mesh.
  for (Vec3& p : cube.positions) p += Vec3{10, -1000, 3};
  EXPECT_NEAR(SignedVolume(cube), -1.0, 1e-9);
}

TEST(MeshTest, AreaWeightedNormalsOfCubeCorners) {
  TriangleMesh cube = UnitCube();
  ComputeAreaWeightedNormals(cube);
  // Vertex 0 is in one triangle of each face: z=0 {0,2,1}, y=0 {0,1,4}, x=0 {0,4,2}. Equal
  // areas: the normal is −(1,1,1)/√3.
  const double s = 1 / std::sqrt(3.0);
  EXPECT_NEAR(cube.normals[0].x, -s, 1e-15);
  EXPECT_NEAR(cube.normals[0].y, -s, 1e-15);
  EXPECT_NEAR(cube.normals[0].z, -s, 1e-15);
  // Vertex 1 = (1,0,0): z=0 {0,2,1},{1,2,3} → 2 triangles (weight 2 on −z); y=0 {0,1,4},{1,5,4}
  // → 2 (−y); x=1 {1,3,5} → 1 (+x). Area weighting gives (1,−2,−2)/3; angle weighting would
  // give (1,−1,−1)/√3 since the corner angles add up to 90° on every face.
  EXPECT_NEAR(cube.normals[1].x, 1.0 / 3, 1e-15);
  EXPECT_NEAR(cube.normals[1].y, -2.0 / 3, 1e-15);
  EXPECT_NEAR(cube.normals[1].z, -2.0 / 3, 1e-15);
}

TEST(MeshTest, OffKeepsFileOrderCountsUnreferencedFansPolygonsDropsDegenerates) {
  const std::string off =
      "OFF\n# comment line\n7 4 0\n"
      "0 0 0\n"
      "5 5 5\n"  // unreferenced
      "1 0 0\n"
      "1 1 0\n"
      "0 1 0\n"
      "2 0 0\n"
      "3 0 0\n"
      "4 0 2 3 4\n"  // quad → (0,2,3), (0,3,4)
      "3 0 0 2\n"    // repeated index
      "3 0 5 6 # collinear: zero area\n"
      "3  2 3 4  0.1 0.2 0.3\n";  // colour after the indices
  const TriangleMesh m = ParseMesh(off, "t.off");
  ASSERT_EQ(m.positions.size(), 7u);
  EXPECT_EQ(m.positions[1], (Vec3{5, 5, 5}));
  EXPECT_EQ(m.positions[6], (Vec3{3, 0, 0}));
  ASSERT_EQ(m.triangles.size(), 3u);
  EXPECT_EQ(m.triangles[0], (std::array<uint32_t, 3>{0, 2, 3}));
  EXPECT_EQ(m.triangles[1], (std::array<uint32_t, 3>{0, 3, 4}));
  EXPECT_EQ(m.triangles[2], (std::array<uint32_t, 3>{2, 3, 4}));
  EXPECT_EQ(m.report.polygons_triangulated, 1u);
  EXPECT_EQ(m.report.degenerate_triangles_dropped, 2u);
  EXPECT_EQ(m.report.unreferenced_vertices, 3u);  // 1, 5 and 6 (5, 6 only in a dropped face)
  EXPECT_EQ(m.normals[1], (Vec3{0, 1, 0}));       // unreferenced: +Y
  EXPECT_NEAR(m.normals[0].z, 1.0, 1e-15);
  EXPECT_FALSE(m.report.normals_from_file);
  EXPECT_FALSE(m.report.closed);
}

TEST(MeshTest, ObjFaceFormsNegativeIndicesAndConsistentNormals) {
  const std::string obj =
      "# square\nmtllib x.mtl\no sq\n"
      "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
      "vt 0 0\nvn 0 0 2\n"
      "s off\n"
      "f 1/1/1 2/1/1 3/1/1\n"
      "f -4//1 -2//1 -1//1\n";
  const TriangleMesh m = ParseMesh(obj, "sq.obj");
  ASSERT_EQ(m.positions.size(), 4u);
  EXPECT_EQ(m.positions[2], (Vec3{1, 1, 0}));
  ASSERT_EQ(m.triangles.size(), 2u);
  EXPECT_EQ(m.triangles[1], (std::array<uint32_t, 3>{0, 2, 3}));
  EXPECT_TRUE(m.report.normals_from_file);
  EXPECT_EQ(m.normals[3], (Vec3{0, 0, 1}));

  // Two different normals on one position: not a single normal per position → area-weighted.
  const std::string obj2 =
      "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvn 0 0 1\nvn 1 0 0\n"
      "f 1//1 2//1 3//1\nf 1//2 3//2 4//2\n";
  const TriangleMesh m2 = ParseMesh(obj2, "sq2.obj");
  EXPECT_FALSE(m2.report.normals_from_file);
  EXPECT_NEAR(m2.normals[0].z, 1.0, 1e-15);
  // A face may refer to vertices defined after it.
  const TriangleMesh m4 =
      ParseMesh("vn 0 0 1\nf 1//1 2//1 3//1\nv 0 0 0\nv 1 0 0\nv 0 1 0\n", "fwd.obj");
  EXPECT_EQ(m4.triangles.size(), 1u);
  EXPECT_TRUE(m4.report.normals_from_file);
  // Faces without vn → area-weighted; polygon with 5 corners → 3 triangles.
  const std::string obj3 = "v 0 0 0\nv 2 0 0\nv 2 1 0\nv 1 2 0\nv 0 1 0\nf 1 2 3 4 5\n";
  const TriangleMesh m3 = ParseMesh(obj3, "pent.obj");
  EXPECT_EQ(m3.triangles.size(), 3u);
  EXPECT_EQ(m3.report.polygons_triangulated, 1u);
}

// --- PLY in three encodings -------------------------------------------------------------------

// Appends v as T in the given byte order.
template <class T>
void Put(std::string& out, T v, bool big_endian) {
  char b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));
  if (big_endian == (std::endian::native == std::endian::little)) std::reverse(b, b + sizeof(T));
  out.append(b, sizeof(T));
}

// A tetrahedron with normals, an extra scalar property, a face list of 4 and an extra element.
std::string TetraPly(const std::string& format) {
  const float p[4][3] = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  const float n[4][3] = {{-1, -1, -1}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  std::string s = "ply\nformat " + format +
                  " 1.0\ncomment made by the test\nelement vertex 4\nproperty float x\n"
                  "property float y\nproperty float z\nproperty uchar quality\n"
                  "property float nx\nproperty float ny\nproperty float nz\n"
                  "element face 4\nproperty list uchar int vertex_indices\nproperty short flags\n"
                  "element edge 1\nproperty int vertex1\nproperty int vertex2\nend_header\n";
  const int f[4][3] = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  if (format == "ascii") {
    std::ostringstream a;
    for (int i = 0; i < 4; ++i) {
      a << p[i][0] << " " << p[i][1] << " " << p[i][2] << " 7 " << n[i][0] << " " << n[i][1] << " "
        << n[i][2] << "\n";
    }
    for (const auto& t : f) a << "3 " << t[0] << " " << t[1] << " " << t[2] << " -1\n";
    a << "0 1\n";
    return s + a.str();
  }
  const bool be = format == "binary_big_endian";
  for (int i = 0; i < 4; ++i) {
    for (float c : p[i]) Put(s, c, be);
    Put(s, uint8_t{7}, be);
    for (float c : n[i]) Put(s, c, be);
  }
  for (const auto& t : f) {
    Put(s, uint8_t{3}, be);
    for (int v : t) Put(s, int32_t(v), be);
    Put(s, int16_t(-1), be);
  }
  Put(s, int32_t(0), be);
  Put(s, int32_t(1), be);
  return s;
}

TEST(MeshTest, PlyAsciiLittleAndBigEndianReadTheSame) {
  const TriangleMesh a = ParseMesh(TetraPly("ascii"), "t.ply");
  const TriangleMesh le = ParseMesh(TetraPly("binary_little_endian"), "t.ply");
  const TriangleMesh be = ParseMesh(TetraPly("binary_big_endian"), "t.ply");
  EXPECT_EQ(a.report.format, "ply-ascii");
  EXPECT_EQ(le.report.format, "ply-binary-le");
  EXPECT_EQ(be.report.format, "ply-binary-be");
  for (const TriangleMesh* m : {&a, &le, &be}) {
    ASSERT_EQ(m->positions.size(), 4u);
    EXPECT_EQ(m->positions[3], (Vec3{0, 0, 1}));
    ASSERT_EQ(m->triangles.size(), 4u);
    EXPECT_EQ(m->triangles[3], (std::array<uint32_t, 3>{1, 2, 3}));
    EXPECT_TRUE(m->report.normals_from_file);
    const double s = 1 / std::sqrt(3.0);
    EXPECT_NEAR(m->normals[0].x, -s, 1e-7);  // file normal, normalised
    EXPECT_TRUE(m->report.closed);
    EXPECT_NEAR(m->report.signed_volume, 1.0 / 6, 1e-12);
    EXPECT_FALSE(m->report.inward_wound);
  }
}

TEST(MeshTest, StlAsciiAndBinaryAreWeldedInOrderOfFirstAppearance) {
  const TriangleMesh cube = UnitCube();
  std::string ascii = "solid cube\n";
  std::string binary(80, ' ');
  Put(binary, uint32_t(cube.triangles.size()), false);
  for (const auto& t : cube.triangles) {
    ascii += "  facet normal 0 0 0\n    outer loop\n";
    for (int k = 0; k < 12; ++k) binary.push_back(0);  // facet normal (ignored)
    for (uint32_t v : t) {
      const Vec3& p = cube.positions[v];
      std::ostringstream line;
      line << "      vertex " << p.x << " " << p.y << " " << p.z << "\n";
      ascii += line.str();
      // −0 must weld with +0.
      Put(binary, p.x == 0 ? -0.0f : float(p.x), false);
      Put(binary, float(p.y), false);
      Put(binary, float(p.z), false);
    }
    ascii += "    endloop\n  endfacet\n";
    binary += std::string(2, '\0');
  }
  ascii += "endsolid cube\n";
  // Expected order: vertices as they first appear in the corner stream.
  std::vector<uint32_t> first;
  for (const auto& t : cube.triangles) {
    for (uint32_t v : t) {
      if (std::find(first.begin(), first.end(), v) == first.end()) first.push_back(v);
    }
  }
  for (const std::string& bytes : {ascii, binary}) {
    const TriangleMesh m = ParseMesh(bytes, "cube.stl");
    ASSERT_EQ(m.positions.size(), 8u);
    for (std::size_t i = 0; i < 8; ++i) {
      EXPECT_EQ(m.positions[i], cube.positions[first[i]]);
    }
    EXPECT_EQ(m.report.welded_vertices, 36u - 8u);
    EXPECT_TRUE(m.report.closed);
    EXPECT_NEAR(m.report.signed_volume, 1.0, 1e-12);
  }
  EXPECT_EQ(ParseMesh(binary, "cube.stl").report.format, "stl-binary");
  EXPECT_EQ(ParseMesh(ascii, "cube.stl").report.format, "stl-ascii");
}

// --- errors ---------------------------------------------------------------------------------

TEST(MeshTest, ErrorsNameTheFileAndTheLineOrElement) {
  ExpectInputError([] { LoadMesh("/nonexistent/dir/bunny.off"); },
                   {"/nonexistent/dir/bunny.off", "no such file"});
  ExpectInputError([] { ParseMesh("x", "model.3ds"); }, {"model.3ds", "unknown mesh format"});
  ExpectInputError([] { ParseMesh("OFF\n3 1 0\n0 0 0\nnan 0 0\n0 1 0\n3 0 1 2\n", "n.off"); },
                   {"n.off", "line 4", "not a finite"});
  ExpectInputError([] { ParseMesh("OFF\n3 1 0\n0 0 0\n1e39 0 0\n0 1 0\n3 0 1 2\n", "f.off"); },
                   {"f.off", "line 4", "float32"});
  ExpectInputError([] { ParseMesh("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n", "r.off"); },
                   {"r.off", "line 6", "out of range"});
  ExpectInputError([] { ParseMesh("OFF\n4 2 0\n0 0 0\n1 0 0\n0 1 0\n", "t.off"); },
                   {"t.off", "truncated", "3 of 4 vertices"});
  ExpectInputError([] { ParseMesh("OFF\n3 2 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n", "t2.off"); },
                   {"t2.off", "truncated", "1 of 2 faces"});
  ExpectInputError([] { ParseMesh("OFF\n0 0 0\n", "e.off"); }, {"e.off", "empty mesh"});
  ExpectInputError([] { ParseMesh("OFF\n3 1 0\n0 0 0\n1 0 0\n2 0 0\n3 0 1 2\n", "z.off"); },
                   {"z.off", "no triangles", "1 degenerate"});
  ExpectInputError([] { ParseMesh("OFF\n3000000000 1 0\n", "big.off"); }, {"big.off", "truncated"});
  ExpectInputError([] { ParseMesh("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", "r.obj"); },
                   {"r.obj", "line 4", "out of range"});
  // A huge forward reference with a normal must fail fast, without allocating for it.
  ExpectInputError(
      [] { ParseMesh("v 0 0 0\nvn 0 0 1\nf 1999999999//1 1//1 1//1\nv 1 0 0\n", "h.obj"); },
      {"h.obj", "line 3", "out of range (the file has 2 vertices)"});
  ExpectInputError([] { ParseMesh("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", "z.obj"); },
                   {"z.obj", "line 4"});
  ExpectInputError([] { ParseMesh("v 0 0 0\nv 1 inf 0\n", "i.obj"); }, {"i.obj", "line 2"});
  ExpectInputError([] { ParseMesh("v 0 0 0\nv 1 0\n", "s.obj"); }, {"s.obj", "line 2"});
  ExpectInputError([] { ParseMesh("", "e.obj"); }, {"e.obj", "empty mesh"});
  // Binary PLY cut in the middle of the face list: names the element.
  const std::string ply = TetraPly("binary_little_endian");
  ExpectInputError([&] { ParseMesh(ply.substr(0, ply.size() - 20), "cut.ply"); },
                   {"cut.ply", "truncated", "face 3 of 4"});
  std::string bad = TetraPly("ascii");
  bad.replace(bad.find("3 1 2 3"), 7, "3 1 2 9");
  ExpectInputError([&] { ParseMesh(bad, "bad.ply"); }, {"bad.ply", "line 26", "out of range"});
  std::string nanply = TetraPly("ascii");
  nanply.replace(nanply.find("\n1 0 0"), 6, "\nnan 0 0");
  ExpectInputError([&] { ParseMesh(nanply, "nan.ply"); }, {"nan.ply", "line 20", "finite"});
  ExpectInputError([] { ParseMesh("ply\nformat ascii 1.0\nelement vertex 3\n", "h.ply"); },
                   {"h.ply", "end_header"});
  // Binary STL whose size does not match its triangle count.
  std::string stl(80, ' ');
  Put(stl, uint32_t(2), false);
  stl += std::string(60, '\0');
  ExpectInputError([&] { ParseMesh(stl, "cut.stl"); }, {"cut.stl", "truncated", "2 triangles"});
  ExpectInputError([] { ParseMesh("solid x\n facet normal 0 0 1\n outer loop\n", "a.stl"); },
                   {"a.stl", "truncated"});
}

// Safety on untrusted input: truncated, overwritten, inserted and erased bytes either give a
// valid mesh or an InputError (never another exception, a crash, or an out-of-range index).
// The same mutations ran 21,000 times under AddressSanitizer/UBSan while this reader was written.
TEST(MeshTest, MutatedInputsGiveAValidMeshOrAnInputError) {
  std::string stl_binary(80, ' ');
  Put(stl_binary, uint32_t(2), false);
  for (int t = 0; t < 2; ++t) {
    stl_binary += std::string(12, '\0');
    const float corners[2][9] = {{0, 0, 0, 1, 0, 0, 1, 1, 0}, {0, 0, 0, 1, 1, 0, 0, 1, 0}};
    for (float c : corners[t]) Put(stl_binary, c, false);
    stl_binary += std::string(2, '\0');
  }
  const std::vector<std::pair<std::string, std::string>> seeds = {
      {TetraPly("ascii"), "m.ply"},
      {TetraPly("binary_little_endian"), "m.ply"},
      {TetraPly("binary_big_endian"), "m.ply"},
      {"OFF\n4 2 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n4 0 2 3 1\n", "m.off"},
      {"v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//1 3//1\nf -4 -2 -1\n", "m.obj"},
      {"solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 1 1 0\n"
       "endloop\nendfacet\nendsolid x\n",
       "m.stl"},
      {stl_binary, "m.stl"},
  };
  const char* const tokens[] = {"-1", "999999999", "nan", "4294967295", "1e39",
                                "#",  "\n",        " ",   "0",          "255"};
  std::mt19937_64 rng(7);
  std::size_t valid = 0, rejected = 0;
  for (const auto& [seed, name] : seeds) {
    for (int it = 0; it < 400; ++it) {
      std::string s = seed;
      switch (it % 4) {
        case 0:
          s.resize(rng() % (s.size() + 1));
          break;
        case 1:
          for (int k = 0; k < 1 + int(rng() % 8); ++k) s[rng() % s.size()] = char(rng());
          break;
        case 2:
          for (int k = 0; k < 1 + int(rng() % 4); ++k)
            s.insert(rng() % s.size(), tokens[rng() % 10]);
          break;
        default:
          s.erase(rng() % s.size(), rng() % 16);
      }
      try {
        const TriangleMesh m = ParseMesh(s, name);
        ++valid;
        ASSERT_FALSE(m.positions.empty());
        ASSERT_FALSE(m.triangles.empty());
        ASSERT_EQ(m.normals.size(), m.positions.size());
        for (const auto& t : m.triangles) {
          for (uint32_t v : t) ASSERT_LT(v, m.positions.size());
        }
        for (const Vec3& p : m.positions) ASSERT_TRUE(IsFinite(p));
        for (const Vec3& n : m.normals) ASSERT_NEAR(Length(n), 1.0, 1e-9);
      } catch (const InputError&) {
        ++rejected;
      }
    }
  }
  std::cout << "             " << valid << " mutated inputs still valid, " << rejected
            << " rejected with InputError\n";
  EXPECT_GT(valid, 0u);
  EXPECT_GT(rejected, 0u);
}

// --- real meshes ------------------------------------------------------------------------------

struct RealMesh {
  std::string path;
  std::size_t vertices;
  std::size_t faces;
  bool closed;
  std::size_t boundary_edges;  // when known (open meshes)
};

std::string DataPath(const char* dir, const std::string& file) {
  return std::string(dir) + "/meshes/" + file;
}

TEST(MeshTest, RealMeshesLoadWithPublishedCounts) {
  const std::vector<RealMesh> meshes = {
      {DataPath(PRT_DATA_DIR, "bunny00.off"), 37706, 75408, true, 0},
      {DataPath(PRT_DATA_DIR, "armadillo.off"), 26002, 52000, true, 0},
      {DataPath(PRT_DATA_DIR, "ChineseDragon-10kv.off"), 10000, 19994, false, 6},
      {DataPath(PRT_DATA_DIR, "camel.off"), 9770, 19536, true, 0},
      {DataPath(PRT_DATA_DIR, "lion-head.off"), 8356, 16674, false, 36},
      {DataPath(PRT_DATA_DIR, "pig.stl"), 8642, 16848, false, 0},
      {DataPath(PRT_SHARED_DATA_DIR, "pig_cgal.stl"), 8642, 16848, false, 0},
      {DataPath(PRT_SHARED_DATA_DIR, "utah_teapot_24x24.obj"), 18529, 36672, false, 0},
      {DataPath(PRT_SHARED_DATA_DIR, "bunny_npm_lowres.obj"), 1839, 3674, true, 0},
      {DataPath(PRT_SHARED_DATA_DIR, "horse_cyberware.ply"), 48485, 96966, true, 0},
  };
  int loaded = 0;
  for (const RealMesh& r : meshes) {
    if (!fs::exists(r.path)) {
      std::cout << "[ skipped  ] " << r.path << " is absent\n";
      continue;
    }
    const TriangleMesh m = LoadMesh(r.path);
    ++loaded;
    std::cout << "             " << DescribeImport(m) << "\n";
    EXPECT_EQ(m.positions.size(), r.vertices) << r.path;
    EXPECT_EQ(m.triangles.size(), r.faces) << r.path;
    EXPECT_EQ(m.normals.size(), r.vertices) << r.path;
    EXPECT_EQ(m.report.degenerate_triangles_dropped, 0u) << r.path;
    EXPECT_EQ(m.report.closed, r.closed) << r.path;
    if (!r.closed && r.boundary_edges > 0) {
      EXPECT_EQ(m.report.boundary_edges, r.boundary_edges) << r.path;
    }
    for (const Vec3& n : m.normals) ASSERT_NEAR(Length(n), 1.0, 1e-6) << r.path;
    const bool horse = r.path.find("horse") != std::string::npos;
    EXPECT_EQ(m.report.inward_wound, horse) << r.path;
    if (r.closed) {
      EXPECT_EQ(m.report.signed_volume < 0, horse) << r.path;
    }
    if (horse) {
      EXPECT_TRUE(m.report.normals_from_file);
      EXPECT_EQ(m.report.format, "ply-binary-le");
      // The file's normals follow its (inward) winding.
      EXPECT_LE(m.report.normals_against_winding, 10u);
    }
    if (r.path.find(".stl") != std::string::npos) {
      EXPECT_EQ(m.report.welded_vertices, 3 * r.faces - r.vertices);
    }
  }
  EXPECT_GE(loaded, 1) << "no real mesh found; run scripts/install-deps.sh and re-configure";
}

// Vertex i of the mesh is the i-th vertex line of the file, parsed here independently.
TEST(MeshTest, VertexIEqualsTheIthVertexLineOfTheFile) {
  const std::string obj = DataPath(PRT_SHARED_DATA_DIR, "bunny_npm_lowres.obj");
  if (fs::exists(obj)) {
    std::ifstream in(obj);
    std::vector<Vec3> expected;
    std::string line;
    while (std::getline(in, line)) {
      if (line.rfind("v ", 0) != 0) continue;
      std::istringstream s(line.substr(2));
      Vec3 p;
      s >> p.x >> p.y >> p.z;
      expected.push_back(p);
    }
    const TriangleMesh m = LoadMesh(obj);
    ASSERT_EQ(m.positions.size(), expected.size());
    for (std::size_t i = 0; i < expected.size(); ++i) ASSERT_EQ(m.positions[i], expected[i]) << i;
  }
  const std::string off = DataPath(PRT_DATA_DIR, "camel.off");
  if (fs::exists(off)) {
    std::ifstream in(off);
    std::string header;
    std::size_t nv = 0, nf = 0, ne = 0;
    in >> header >> nv >> nf >> ne;
    std::vector<Vec3> expected(nv);
    for (Vec3& p : expected) in >> p.x >> p.y >> p.z;
    const TriangleMesh m = LoadMesh(off);
    ASSERT_EQ(m.positions.size(), nv);
    for (std::size_t i = 0; i < nv; ++i) ASSERT_EQ(m.positions[i], expected[i]) << i;
    // And the first face.
    std::size_t k = 0;
    uint32_t a = 0, b = 0, c = 0;
    in >> k >> a >> b >> c;
    EXPECT_EQ(m.triangles[0], (std::array<uint32_t, 3>{a, b, c}));
  }
}

// The bound is multiplied by PRT_TEST_TIME_SCALE when set: scripts/sanitize.sh sets it, since an
// ASan/UBSan build read the bunny in 1.35 s on a loaded 2-core machine (docs/testing.md).
TEST(MeshTest, ReadingTheBunnyTakesWellUnderASecond) {
  const std::string path = DataPath(PRT_DATA_DIR, "bunny00.off");
  if (!fs::exists(path)) GTEST_SKIP() << path << " is absent";
  double scale = 1.0;
  if (const char* env = std::getenv("PRT_TEST_TIME_SCALE"); env != nullptr && *env != '\0')
    scale = std::max(1.0, std::atof(env));
  const auto t0 = std::chrono::steady_clock::now();
  const TriangleMesh m = LoadMesh(path);
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::cout << "             bunny00.off (" << m.positions.size() << " vertices): " << s << " s\n";
  EXPECT_LT(s, 0.5 * scale);
}

}  // namespace
}  // namespace prt
