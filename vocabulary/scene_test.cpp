#include "vocabulary/scene.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "vocabulary/errors.h"

namespace prt {
namespace {

namespace fs = std::filesystem;

std::string ReadText(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

void WriteText(const fs::path& path, const std::string& text) {
  fs::create_directories(path.parent_path());
  std::ofstream(path, std::ios::binary) << text;
}

// A fresh folder for one test.
fs::path TestDir(const std::string& name) {
  const fs::path dir = fs::path(testing::TempDir()) / ("prt_scene_test_" + name);
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

// Sets PRT_DATA_PATH for the lifetime of the object.
class ScopedDataPath {
 public:
  explicit ScopedDataPath(const std::string& value) {
    if (const char* old = std::getenv("PRT_DATA_PATH")) {
      old_ = old;
      had_ = true;
    }
    setenv("PRT_DATA_PATH", value.c_str(), 1);
  }
  ~ScopedDataPath() {
    if (had_) {
      setenv("PRT_DATA_PATH", old_.c_str(), 1);
    } else {
      unsetenv("PRT_DATA_PATH");
    }
  }

 private:
  std::string old_;
  bool had_ = false;
};

const char kBox[] =  // an axis-aligned box [10,12]×[−1000,−996]×[5,6], outward wound
    "OFF\n8 12 0\n"
    "10 -1000 5\n12 -1000 5\n10 -996 5\n12 -996 5\n10 -1000 6\n12 -1000 6\n10 -996 6\n12 -996 6\n"
    "3 0 2 1\n3 1 2 3\n3 4 5 6\n3 5 7 6\n3 0 1 4\n3 1 5 4\n"
    "3 2 6 3\n3 3 6 7\n3 0 4 2\n3 2 4 6\n3 1 3 5\n3 3 7 5\n";

TEST(SceneTest, DefaultSceneTextIsScenesDefaultToml) {
  EXPECT_EQ(ReadText(std::string(PRT_SOURCE_DIR) + "/scenes/default.toml"), DefaultSceneText());
}

TEST(SceneTest, DefaultSceneParsesWithDocumentedValues) {
  const SceneDescription s = LoadDefaultScene(PRT_DATA_DIR);
  EXPECT_EQ(s.file, "<default scene>");
  EXPECT_EQ(s.name, "bunny");
  EXPECT_EQ(s.cubemap_n, 32);
  EXPECT_EQ(s.samples, SpatialSamples::kVertices);
  ASSERT_EQ(s.meshes.size(), 1u);
  EXPECT_EQ(s.meshes[0].path, "meshes/bunny00.off");
  ASSERT_TRUE(s.meshes[0].fit.has_value());
  EXPECT_EQ(s.meshes[0].fit->size, 1.0);
  EXPECT_EQ(s.meshes[0].fit->up_axis, "+y");
  EXPECT_TRUE(s.ground.enabled);
  EXPECT_EQ(s.ground.resolution, 64);
  EXPECT_EQ(s.ground.size, 4.0);
  EXPECT_EQ(s.sampling.rays_per_texel, 4);
  EXPECT_EQ(s.sampling.method, "sparse");
  EXPECT_EQ(s.sparse.initial_fraction, 0.05);
  EXPECT_EQ(s.sparse.dense_budget, 0.25);
  EXPECT_EQ(s.sparse.features, 350);
  EXPECT_EQ(s.sparse.max_neighbors, 40);
  EXPECT_EQ(s.sparse.window, 7);
  EXPECT_EQ(s.sparse.unity_weight, 1.0);
  EXPECT_EQ(s.sparse.max_residual, 0.3);
  EXPECT_EQ(s.sparse.min_normal_cos, 0.5);
  EXPECT_EQ(s.compression.bits, 9);
  ASSERT_EQ(s.environments.size(), 2u);
  if (fs::exists(std::string(PRT_DATA_DIR) + "/meshes/bunny00.off")) {
    EXPECT_EQ(fs::path(s.meshes[0].resolved_path),
              (fs::path(PRT_DATA_DIR) / "meshes/bunny00.off").lexically_normal());
  }
  if (fs::exists(std::string(PRT_DATA_DIR) + "/envmaps/sunrise.exr")) {
    EXPECT_EQ(fs::path(s.environments[0]),
              (fs::path(PRT_DATA_DIR) / "envmaps/sunrise.exr").lexically_normal());
  }
}

TEST(SceneTest, DefaultsWhenSectionsAreAbsentAndFeaturesScaleWithN) {
  const SceneDescription s = ParseScene("[ground]\n[scene]\nn = 64\n", "g.toml", "");
  EXPECT_TRUE(s.ground.enabled);  // a [ground] table turns the ground on
  EXPECT_EQ(s.ground.resolution, 64);
  EXPECT_EQ(s.sampling.rays_per_texel, 4);
  EXPECT_EQ(s.compression.bits, 9);
  EXPECT_EQ(s.sparse.features, 1400);  // 350·(64/32)²
  EXPECT_EQ(ParseScene("[ground]\n[scene]\nn = 8\n", "g.toml", "").sparse.features, 22);
  EXPECT_EQ(ParseScene("[ground]\n", "g.toml", "").sparse.features, 350);
}

// The glossy-material keys, [sampling] job and [visibility] (docs/scene-format.md).
TEST(SceneTest, GlossyMaterialsJobAndVisibility) {
  const SceneDescription d = ParseScene("[ground]\n", "g.toml", "");
  EXPECT_EQ(d.sampling.job, "transport");
  EXPECT_EQ(d.visibility.n, 64);
  EXPECT_EQ(d.visibility.supersample, 1);
  EXPECT_EQ(d.visibility.bits, 1);
  EXPECT_EQ(d.ground.glossy.brdf, "lambert");
  EXPECT_EQ(d.ground.glossy.specular, (Rgb{0, 0, 0}));
  const SceneDescription s = ParseScene(
      "[[mesh]]\npath = \"m.off\"\nalbedo = [0.5, 0.5, 0.5]\nbrdf = \"phong\"\n"
      "specular = [0.5, 0.25, 0.1]\nexponent = 120\n"
      "[ground]\nbrdf = \"ashikhmin-shirley\"\nalbedo = [0.4, 0.4, 0.4]\n"
      "specular = [0.3, 0.3, 0.3]\nexponent = 10\nexponent_v = 200\n"
      "[sampling]\njob = \"visibility\"\n[visibility]\nn = 128\nsupersample = 4\nbits = 3\n",
      "g.toml", "");
  EXPECT_EQ(s.sampling.job, "visibility");
  EXPECT_EQ(s.visibility.n, 128);
  EXPECT_EQ(s.visibility.supersample, 4);
  EXPECT_EQ(s.visibility.bits, 3);
  EXPECT_EQ(s.meshes[0].glossy.brdf, "phong");
  EXPECT_EQ(s.meshes[0].glossy.specular, (Rgb{0.5f, 0.25f, 0.1f}));
  EXPECT_EQ(s.meshes[0].glossy.exponent, 120.0);
  EXPECT_EQ(s.meshes[0].glossy.exponent_v, 120.0);  // defaults to exponent
  EXPECT_EQ(s.ground.glossy.brdf, "ashikhmin-shirley");
  EXPECT_EQ(s.ground.glossy.exponent, 10.0);
  EXPECT_EQ(s.ground.glossy.exponent_v, 200.0);
  const std::string mesh = "[[mesh]]\npath = \"m.off\"\nalbedo = [0.8, 0.8, 0.8]\n";
  for (const auto& [text, says] : std::vector<std::pair<std::string, std::string>>{
           {mesh + "brdf = \"ward\"\n", "not one of"},
           {mesh + "specular = [0.3, 0.1, 0.1]\n", "must not exceed 1"},
           {mesh + "exponent = 0\n", "out of range"},
           {mesh + "[sampling]\njob = \"both\"\n", "not one of"},
           {mesh + "[visibility]\nn = 48\n", "power of two"},
           {mesh + "[visibility]\nn = 8\n", "out of range"},
           {mesh + "[visibility]\nbits = 2\n", "need supersample > 1"},
           {mesh + "[visibility]\nrays = 2\n", "unknown key 'rays'"}}) {
    try {
      ParseScene(text, "bad.toml", "");
      ADD_FAILURE() << "accepted: " << text;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(says), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("bad.toml: line"), std::string::npos) << e.what();
    }
  }
}

// GGX (docs/scene-format.md, "Glossy materials"): roughness r in (0, 1], α = r².
TEST(Scene, GgxRoughnessIsReadAndItsRangeIsEnforced) {
  const SceneDescription s = ParseScene(
      "[[mesh]]\npath = \"m.off\"\nalbedo = [0.4, 0.4, 0.4]\nbrdf = \"ggx\"\n"
      "specular = [0.5, 0.5, 0.5]\nroughness = 0.35\n",
      "g.toml", "");
  EXPECT_EQ(s.meshes[0].glossy.brdf, "ggx");
  EXPECT_EQ(s.meshes[0].glossy.roughness, 0.35);
  EXPECT_EQ(ParseScene("[[mesh]]\npath = \"m.off\"\nbrdf = \"ggx\"\nroughness = 1\n", "g.toml", "")
                .meshes[0]
                .glossy.roughness,
            1.0);
  const std::string mesh = "[[mesh]]\npath = \"m.off\"\nbrdf = \"ggx\"\n";
  for (const std::string r : {"0", "-0.1", "1.01", "2"}) {
    try {
      ParseScene(mesh + "roughness = " + r + "\n", "bad.toml", "");
      ADD_FAILURE() << "accepted roughness " << r;
    } catch (const InputError& e) {
      const std::string what = e.what();
      EXPECT_NE(what.find("bad.toml: line 4"), std::string::npos) << what;
      EXPECT_NE(what.find("roughness"), std::string::npos) << what;
      EXPECT_NE(what.find("out of range (0, 1]"), std::string::npos) << what;
    }
  }
}

struct BadScene {
  std::string text;
  int line;
  std::string says;
};

TEST(SceneTest, EveryErrorNamesTheFileAndTheLine) {
  const std::string mesh = "[[mesh]]\npath = \"m.off\"\n";
  const std::vector<BadScene> cases = {
      {"[scene]\nn = 48\n" + mesh, 2, "power of two"},
      {"[scene]\nn = 512\n" + mesh, 2, "out of range"},
      {"[scene]\nn = \"32\"\n" + mesh, 2, "expected an integer"},
      {"[scene]\nn = 32.0\n" + mesh, 2, "expected an integer"},
      {"[scene]\nname = \"x\"\nsampels = \"vertices\"\n" + mesh, 3, "unknown key 'sampels'"},
      {"[scene]\nsamples = \"pixels\"\n" + mesh, 2, "not one of"},
      {"[scen]\nn = 32\n" + mesh, 1, "unknown key 'scen'"},
      {mesh + "albedo = [0.5, -0.1, 0.5]\n", 3, "[0, 1]"},
      {mesh + "albedo = [0.5, 0.5]\n", 3, "3 numbers"},
      {mesh + "scale = 0\n", 3, "out of range"},
      {mesh + "scale = nan\n", 3, "finite"},
      {mesh + "flip_winding = 1\n", 3, "true or false"},
      {mesh + "fit = { size = 1, up = \"sideways\" }\n", 3, "+x -x +y -y +z -z"},
      {mesh + "fit = { size = 1, centre = [0, 0, 0] }\n", 3, "unknown key 'centre'"},
      {mesh + "rotate = [0, 90, 0]\n", 3, "unknown key 'rotate'"},
      {"[mesh]\npath = \"m.off\"\n", 1, "[[mesh]]"},
      {"[[mesh]]\nname = \"a\"\n", 1, "path: is required"},
      {mesh + "name = \"a\"\n[[mesh]]\nname = \"a\"\npath = \"m.off\"\n", 5, "earlier"},
      {mesh + "[sampling]\nrays_per_texel = 0\n", 4, "out of range"},
      {mesh + "[sampling]\nmethod = \"dense\"\n", 4, "not one of"},
      {mesh + "[sampling]\nseed = -1\n", 4, "out of range"},
      {mesh + "[ground]\nresolution = 1\n", 4, "out of range"},
      {mesh + "[ground]\ncenter = [0, 0, 0]\n", 4, "2 numbers"},
      {mesh + "[ground]\nsize = -4\n", 4, "out of range"},
      {mesh + "[camera]\nfov = 180\n", 4, "out of range"},
      {mesh + "[camera]\neye = [0, 0, 1]\ntarget = [0, 0, 1]\n", 5, "equals eye"},
      {mesh + "[sparse]\ninitial_fraction = 1.5\n", 4, "out of range"},
      {mesh + "[sparse]\nfeatures = 7000\n", 4, "out of range"},
      {mesh + "[sparse]\nradius = 0\n", 4, "out of range"},
      {mesh + "[sparse]\ndense_budget = 0.01\n", 4, "initial_fraction"},
      {mesh + "[sparse]\nwindow = 6\n", 4, "must be odd"},
      {mesh + "[sparse]\nwindow = 1\n", 4, "out of range"},
      {mesh + "[sparse]\nmax_residual = -0.1\n", 4, "out of range"},
      {mesh + "[compression]\nbits = 0\n", 4, "out of range"},
      {mesh + "[compression]\nscheme = \"3d\"\n", 4, "not one of"},
      {mesh + "[compression]\nkeep = 0.1\n", 4, "unknown key 'keep'"},
      {mesh + "[environments]\npaths = [\"a.exr\", 3]\n", 4, "path strings"},
      {mesh + "[environments]\nlist = [\"a.exr\"]\n", 4, "unknown key 'list'"},
      {"[scene]\nn = 32\nn = 64\n", 3, "TOML syntax error"},
      {"[scene\n", 1, "TOML syntax error"},
      {"[scene]\nname = \"bunny\"\n", 1, "no geometry"},
  };
  for (const BadScene& c : cases) {
    try {
      ParseScene(c.text, "bad_scene.toml", "");
      ADD_FAILURE() << "accepted:\n" << c.text;
    } catch (const InputError& e) {
      const std::string msg = e.what();
      EXPECT_EQ(msg.rfind("bad_scene.toml: ", 0), 0u) << msg;
      EXPECT_NE(msg.find("line " + std::to_string(c.line) + ":"), std::string::npos)
          << "expected line " << c.line << " in: " << msg;
      EXPECT_NE(msg.find(c.says), std::string::npos) << "expected '" << c.says << "' in: " << msg;
    }
  }
}

TEST(SceneTest, PathsResolveNextToTheSceneThenPrtDataPathThenAsGiven) {
  const fs::path dir = TestDir("paths");
  WriteText(dir / "data1/meshes/box.off", kBox);
  WriteText(dir / "data2/meshes/box.off", kBox);
  WriteText(dir / "data2/envmaps/sky.exr", "not really an exr");
  WriteText(dir / "scenes/s.toml",
            "[[mesh]]\npath = \"meshes/box.off\"\n[environments]\n"
            "paths = [\"envmaps/sky.exr\", \"envmaps/missing.exr\"]\n");
  {
    ScopedDataPath env((dir / "nowhere").string() + ":" + (dir / "data1").string() +
                       "::" + (dir / "data2").string());
    const SceneDescription s = LoadSceneFile((dir / "scenes/s.toml").string());
    EXPECT_EQ(s.meshes[0].resolved_path, (dir / "data1/meshes/box.off").string());
    EXPECT_EQ(s.environments[0], (dir / "data2/envmaps/sky.exr").string());
    EXPECT_EQ(s.environments[1], "envmaps/missing.exr");  // missing at parse time is fine
    try {
      ResolveScenePath(s, s.environments[1], 4);
      ADD_FAILURE() << "missing environment resolved";
    } catch (const InputError& e) {
      const std::string msg = e.what();
      EXPECT_NE(msg.find("s.toml: line 4"), std::string::npos) << msg;
      EXPECT_NE(msg.find((dir / "scenes/envmaps/missing.exr").string()), std::string::npos);
      EXPECT_NE(msg.find((dir / "data1/envmaps/missing.exr").string()), std::string::npos);
      EXPECT_NE(msg.find((dir / "data2/envmaps/missing.exr").string()), std::string::npos);
    }
  }
  // Next to the scene file wins over PRT_DATA_PATH.
  WriteText(dir / "scenes/meshes/box.off", kBox);
  ScopedDataPath env((dir / "data1").string());
  EXPECT_EQ(LoadSceneFile((dir / "scenes/s.toml").string()).meshes[0].resolved_path,
            (dir / "scenes/meshes/box.off").string());
  // Extra folders from the caller come after PRT_DATA_PATH.
  const SceneDescription t = ParseScene("[[mesh]]\npath = \"envmaps/sky.exr\"\n", "t.toml", "",
                                        {(dir / "data2").string()});
  EXPECT_EQ(t.meshes[0].resolved_path, (dir / "data2/envmaps/sky.exr").string());
}

TEST(SceneTest, MissingOrBrokenMeshNamesSceneLineMeshAndWhereItLooked) {
  const fs::path dir = TestDir("missing");
  WriteText(dir / "s.toml",
            "[scene]\nname = \"x\"\n\n[[mesh]]\nname = \"ghost\"\npath = \"meshes/ghost.off\"\n"
            "\n[[mesh]]\nname = \"broken\"\npath = \"broken.off\"\n");
  WriteText(dir / "broken.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n");
  ScopedDataPath env((dir / "data").string());
  const SceneDescription s = LoadSceneFile((dir / "s.toml").string());
  try {
    BuildSceneGeometry(s);
    ADD_FAILURE() << "built a scene with a missing mesh";
  } catch (const InputError& e) {
    const std::string msg = e.what();
    EXPECT_EQ(msg.rfind((dir / "s.toml").string() + ": line 4: mesh 'ghost'", 0), 0u) << msg;
    EXPECT_NE(msg.find((dir / "meshes/ghost.off").string()), std::string::npos) << msg;
    EXPECT_NE(msg.find((dir / "data/meshes/ghost.off").string()), std::string::npos) << msg;
  }
  SceneDescription only_broken = s;
  only_broken.meshes.erase(only_broken.meshes.begin());
  try {
    BuildSceneGeometry(only_broken);
    ADD_FAILURE() << "built a scene with a truncated mesh";
  } catch (const InputError& e) {
    const std::string msg = e.what();
    EXPECT_EQ(msg.rfind((dir / "s.toml").string() + ": line 8: mesh 'broken'", 0), 0u) << msg;
    EXPECT_NE(msg.find("broken.off: truncated"), std::string::npos) << msg;
  }
}

TEST(SceneTest, FitStandsTheMeshOnTheGroundWithTheRequestedSizeAndUpAxis) {
  const fs::path dir = TestDir("fit");
  WriteText(dir / "box.off", kBox);
  // The box is 2 (x) × 4 (y) × 1 (z). With up = +z, z becomes height: extents x 2, y 1, z 4.
  const SceneDescription s = ParseScene(
      "[[mesh]]\npath = \"box.off\"\nfit = { size = 3.0, up = \"+z\" }\n"
      "[ground]\nheight = 0.5\ncenter = [1.0, -2.0]\nresolution = 3\nsize = 10\n",
      "fit.toml", dir.string());
  const SceneGeometry g = BuildSceneGeometry(s);
  ASSERT_EQ(g.meshes.size(), 2u);
  const TriangleMesh& m = g.meshes[0].mesh;
  Vec3 lo{1e9, 1e9, 1e9}, hi{-1e9, -1e9, -1e9};
  for (const Vec3& p : m.positions) {
    lo = {std::min(lo.x, p.x), std::min(lo.y, p.y), std::min(lo.z, p.z)};
    hi = {std::max(hi.x, p.x), std::max(hi.y, p.y), std::max(hi.z, p.z)};
  }
  const double k = 3.0 / 4.0;                // largest extent 4 → 3
  EXPECT_NEAR(lo.y, 0.5, 1e-12);             // bottom on the ground
  EXPECT_NEAR(hi.y - lo.y, 1.0 * k, 1e-12);  // old z extent is the height
  EXPECT_NEAR(hi.x - lo.x, 2.0 * k, 1e-12);
  EXPECT_NEAR(hi.z - lo.z, 4.0 * k, 1e-12);      // old y extent, now along z
  EXPECT_NEAR(0.5 * (lo.x + hi.x), 1.0, 1e-12);  // centred on the ground centre
  EXPECT_NEAR(0.5 * (lo.z + hi.z), -2.0, 1e-12);
  // Vertex 7 = (12, −996, 6) is in one triangle of each of the faces +x (twice the area 4),
  // +y (2) and +z (8): area-weighted normal (2, 1, 4)/√21. Up = +z maps (x, y, z) → (x, z, −y):
  // (2, 4, −1)/√21. The volume scales by k³ and the mesh stays outward.
  const double r = 1 / std::sqrt(21.0);
  EXPECT_NEAR(m.normals[7].x, 2 * r, 1e-12);
  EXPECT_NEAR(m.normals[7].y, 4 * r, 1e-12);
  EXPECT_NEAR(m.normals[7].z, -r, 1e-12);
  EXPECT_NEAR(m.report.signed_volume, 2 * 4 * 1 * k * k * k, 1e-9);
  EXPECT_NEAR(SignedVolume(m), m.report.signed_volume, 1e-9);
  // Ground last; scene bounds cover both.
  EXPECT_TRUE(g.meshes[1].is_ground);
  EXPECT_EQ(g.vertex_count(), 8u + 9u);
  EXPECT_NEAR(g.bounds_min.x, -4.0, 1e-12);
  EXPECT_NEAR(g.bounds_max.y, 0.5 + k, 1e-12);
}

TEST(SceneTest, ScaleRotateTranslateAndFlipWinding) {
  const fs::path dir = TestDir("transform");
  WriteText(dir / "box.off", kBox);
  const SceneDescription s = ParseScene(
      "[[mesh]]\npath = \"box.off\"\nscale = 2.0\nrotate_deg = [0, 90, 0]\n"
      "translate = [1, 2, 3]\nflip_winding = true\n",
      "t.toml", dir.string());
  const SceneGeometry g = BuildSceneGeometry(s);
  ASSERT_EQ(g.meshes.size(), 1u);  // no ground
  const TriangleMesh& m = g.meshes[0].mesh;
  // Vertex 1 = (12, −1000, 5): scaled (24, −2000, 10), rotated 90° about y: (x, z) → (z, −x)
  // = (10, −2000, −24), translated (11, −1998, −21).
  EXPECT_NEAR(m.positions[1].x, 11, 1e-9);
  EXPECT_NEAR(m.positions[1].y, -1998, 1e-9);
  EXPECT_NEAR(m.positions[1].z, -21, 1e-9);
  // Flipped: the closed box is now wound inward with volume −(2·4·1)·8, normals inward.
  EXPECT_TRUE(m.report.inward_wound);
  EXPECT_NEAR(m.report.signed_volume, -64, 1e-9);
  EXPECT_NEAR(SignedVolume(m), -64, 1e-6);
  // Vertex 7 = (12, −996, 6): outward normal (2, 1, 4)/√21 (see the fit test) → flipped
  // (−2, −1, −4)/√21 → rotated (x, z) → (z, −x): (−4, −1, 2)/√21.
  const double r = 1 / std::sqrt(21.0);
  EXPECT_NEAR(m.normals[7].x, -4 * r, 1e-12);
  EXPECT_NEAR(m.normals[7].y, -r, 1e-12);
  EXPECT_NEAR(m.normals[7].z, 2 * r, 1e-12);
}

TEST(SceneTest, GroundGridIsRowMajorXFastestWithUpNormals) {
  GroundPlane gp;
  gp.enabled = true;
  gp.height = 0.25;
  gp.center = {1, 0, -1};
  gp.size = 2;
  gp.resolution = 3;
  TriangleMesh g = MakeGroundGrid(gp);
  ASSERT_EQ(g.positions.size(), 9u);
  ASSERT_EQ(g.triangles.size(), 8u);
  for (int iz = 0; iz < 3; ++iz) {
    for (int ix = 0; ix < 3; ++ix) {
      EXPECT_EQ(g.positions[iz * 3 + ix], (Vec3{double(ix), 0.25, -2.0 + iz})) << ix << "," << iz;
    }
  }
  for (const Vec3& n : g.normals) EXPECT_EQ(n, (Vec3{0, 1, 0}));
  double area = 0;
  for (const auto& t : g.triangles) {
    const Vec3 c =
        Cross(g.positions[t[1]] - g.positions[t[0]], g.positions[t[2]] - g.positions[t[0]]);
    EXPECT_GT(c.y, 0);  // every triangle faces +Y
    area += 0.5 * c.y;
  }
  EXPECT_NEAR(area, 4.0, 1e-12);
  ComputeAreaWeightedNormals(g);
  for (const Vec3& n : g.normals) EXPECT_EQ(n, (Vec3{0, 1, 0}));
  EXPECT_FALSE(g.report.closed);
  EXPECT_EQ(g.report.boundary_edges, 8u);  // 4 sides × 2 edges
  // 64 × 64 default: the last vertex sits exactly on the far corner.
  GroundPlane big;
  const TriangleMesh b = MakeGroundGrid(big);
  ASSERT_EQ(b.positions.size(), 64u * 64u);
  EXPECT_EQ(b.positions.back(), (Vec3{2, 0, 2}));
  EXPECT_EQ(b.positions[63], (Vec3{2, 0, -2}));
}

TEST(SceneTest, DefaultSceneBuildsTheFittedBunnyOnTheGround) {
  const std::string bunny = std::string(PRT_DATA_DIR) + "/meshes/bunny00.off";
  if (!fs::exists(bunny)) GTEST_SKIP() << bunny << " is absent";
  const SceneGeometry g = BuildSceneGeometry(LoadDefaultScene(PRT_DATA_DIR));
  ASSERT_EQ(g.meshes.size(), 2u);
  EXPECT_EQ(g.meshes[0].name, "bunny");
  EXPECT_EQ(g.meshes[0].mesh.positions.size(), 37706u);
  EXPECT_TRUE(g.meshes[1].is_ground);
  EXPECT_EQ(g.meshes[1].grid_resolution, 64);
  EXPECT_EQ(g.vertex_count(), 37706u + 4096u);
  double lo = 1e9, hi = -1e9, ext = 0;
  Vec3 bmin{1e9, 1e9, 1e9}, bmax{-1e9, -1e9, -1e9};
  for (const Vec3& p : g.meshes[0].mesh.positions) {
    bmin = {std::min(bmin.x, p.x), std::min(bmin.y, p.y), std::min(bmin.z, p.z)};
    bmax = {std::max(bmax.x, p.x), std::max(bmax.y, p.y), std::max(bmax.z, p.z)};
  }
  lo = bmin.y;
  hi = bmax.y;
  ext = std::max({bmax.x - bmin.x, bmax.y - bmin.y, bmax.z - bmin.z});
  EXPECT_NEAR(lo, 0.0, 1e-12);
  EXPECT_NEAR(ext, 1.0, 1e-12);
  EXPECT_GT(hi, 0.5);
  EXPECT_FALSE(g.meshes[0].mesh.report.inward_wound);
  EXPECT_NEAR(g.bounds_min.x, -2.0, 1e-12);
  EXPECT_NEAR(g.bounds_max.z, 2.0, 1e-12);
  std::cout << "             default scene: " << g.vertex_count() << " spatial samples, diagonal "
            << g.diagonal() << "\n";
}

TEST(SceneTest, TeapotExampleStandsZUpOnTheGround) {
  const std::string shared = PRT_SHARED_DATA_DIR;
  if (!fs::exists(shared + "/meshes/utah_teapot_24x24.obj")) GTEST_SKIP() << "no shared data";
  const SceneDescription s =
      LoadSceneFile(std::string(PRT_SOURCE_DIR) + "/scenes/teapot.toml", {shared});
  EXPECT_EQ(s.samples, SpatialSamples::kCameraPixels);
  ASSERT_EQ(s.environments.size(), 2u);
  EXPECT_TRUE(fs::exists(s.environments[0]));
  const SceneGeometry g = BuildSceneGeometry(s);
  const TriangleMesh& m = g.meshes[0].mesh;
  EXPECT_EQ(m.positions.size(), 18529u);
  double lo = 1e9, hi = -1e9;
  for (const Vec3& p : m.positions) {
    lo = std::min(lo, p.y);
    hi = std::max(hi, p.y);
  }
  // Z-up source: height 3.15 of a 6.43-wide teapot, fitted to 1.2 → 1.2·3.15/6.43404.
  EXPECT_NEAR(lo, 0.0, 1e-12);
  EXPECT_NEAR(hi, 1.2 * 3.15 / 6.43404, 1e-4);
}

TEST(SceneTest, FlipWindingTurnsTheInwardHorseOutward) {
  const std::string shared = PRT_SHARED_DATA_DIR;
  if (!fs::exists(shared + "/meshes/horse_cyberware.ply")) GTEST_SKIP() << "no shared data";
  const std::string text =
      "[[mesh]]\nname = \"horse\"\npath = \"meshes/horse_cyberware.ply\"\n"
      "fit = { size = 1.0 }\nflip_winding = FLIP\n";
  for (const bool flip : {false, true}) {
    std::string t = text;
    t.replace(t.find("FLIP"), 4, flip ? "true" : "false");
    const SceneGeometry g = BuildSceneGeometry(ParseScene(t, "horse.toml", "", {shared}));
    const TriangleMesh& m = g.meshes[0].mesh;
    ASSERT_EQ(m.positions.size(), 48485u);
    EXPECT_EQ(m.report.inward_wound, !flip);
    EXPECT_EQ(m.report.signed_volume > 0, flip);
    EXPECT_NEAR(SignedVolume(m), m.report.signed_volume, 1e-9);
    // Normals follow the winding: after the flip they agree with the outward area-weighted ones.
    TriangleMesh computed = m;
    ComputeAreaWeightedNormals(computed);
    std::size_t agree = 0;
    for (std::size_t v = 0; v < m.normals.size(); ++v) {
      agree += Dot(m.normals[v], computed.normals[v]) > 0;
    }
    EXPECT_GE(agree, m.normals.size() - 10);
  }
}

}  // namespace
}  // namespace prt
