// Tests for glossy_session.h and prt-view on glossy assets: a small pack with traced visibility
// (a floating square over a ground grid, n = 64, Phong and Ashikhmin–Shirley materials) renders
// headless through Algorithm 1 within a PSNR bound of the pixel-basis reference, its visibility
// reads back exactly as traced, materials come from the metadata, and prt-view writes the same
// radiance as the library.
#include "viewer/glossy_session.h"

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <nlohmann/json.hpp>
#include <sstream>

#include "packager/prtpack_writer.h"
#include "viewer/environment_background.h"
#include "runtime/error_test_support.h"
#include "viewer/rasterizer.h"
#include "viewer/window_test_support.h"
#include "vocabulary/cubemap_resample.h"
#include "vocabulary/environment_io.h"
#include "vocabulary/errors.h"
#include "vocabulary/sky.h"
#include "worker/embree_scene.h"
#include "worker/visibility_sampler.h"

namespace prt {
namespace {

namespace fs = std::filesystem;

fs::path WorkDir() {
  const fs::path d =
      fs::path(::testing::TempDir()) / ("glossy_session_test_" + std::to_string(::getpid()));
  fs::create_directories(d);
  return d;
}

// A square floating over a 12×12 ground grid: the ground is partly shadowed (mixed blocks).
SceneGeometry SquareOverGround() {
  SceneGeometry g;
  SceneMesh square;
  square.name = "square";
  square.albedo = {0.5f, 0.4f, 0.3f};
  square.mesh.positions = {{-0.5, 0.6, -0.5}, {0.5, 0.6, -0.5}, {0.5, 0.6, 0.5}, {-0.5, 0.6, 0.5}};
  square.mesh.normals.assign(4, Vec3{0, 1, 0});
  square.mesh.triangles = {{0, 2, 1}, {0, 3, 2}};
  g.meshes.push_back(square);
  GroundPlane gp;
  gp.enabled = true;
  gp.size = 3;
  gp.resolution = 12;
  SceneMesh ground;
  ground.name = "ground";
  ground.albedo = {0.4f, 0.4f, 0.4f};
  ground.is_ground = true;
  ground.grid_resolution = 12;
  ground.mesh = MakeGroundGrid(gp);
  g.meshes.push_back(ground);
  g.bounds_min = {-1.5, 0, -1.5};
  g.bounds_max = {1.5, 0.6, 1.5};
  return g;
}

struct GlossyPack {
  SceneGeometry geometry = SquareOverGround();
  VisibilityBlocks traced;  // all samples
  std::string pack;
  std::string env;
};

const GlossyPack& TinyGlossyPack() {
  static const GlossyPack p = [] {
    GlossyPack t;
    const std::vector<SpatialSample> samples = SpatialSamplesOf(t.geometry);
    const EmbreeScene embree(t.geometry);
    const VisibilitySampler sampler(embree, VisibilitySamplerOptions{64, 1, 1});
    t.traced = sampler.ComputeBlocks(samples);
    pack::PackInput in;
    pack::VisibilityInput vis;
    std::size_t first = 0;
    for (const SceneMesh& m : t.geometry.meshes) {
      in.meshes.push_back(
          {m.name, m.mesh, m.albedo, m.is_ground, static_cast<uint32_t>(m.grid_resolution)});
      const std::size_t nv = m.mesh.positions.size();
      vis.per_mesh.push_back(EncodeVisibilityBlocks(
          sampler.ComputeBlocks(std::span<const SpatialSample>(samples).subspan(first, nv))));
      first += nv;
    }
    in.visibility = std::move(vis);
    const nlohmann::json meta = {{"scene",
                                  {{"camera",
                                    {{"eye", {0.0, 2.2, 3.0}},
                                     {"target", {0.0, 0.2, 0.0}},
                                     {"fov", 45.0},
                                     {"width", 96},
                                     {"height", 72}}}}},
                                 {"materials",
                                  {{{"name", "square"},
                                    {"brdf", "ashikhmin-shirley"},
                                    {"diffuse", {0.5, 0.4, 0.3}},
                                    {"specular", {0.4, 0.4, 0.4}},
                                    {"exponent", 20.0},
                                    {"exponent_v", 200.0}},
                                   {{"name", "ground"},
                                    {"brdf", "phong"},
                                    {"diffuse", {0.4, 0.4, 0.4}},
                                    {"specular", {0.5, 0.5, 0.5}},
                                    {"exponent", 60.0}}}}};
    in.metadata_json = meta.dump();
    t.pack = (WorkDir() / "glossy.prtpack").string();
    pack::WritePackFile(t.pack, in);
    SkySunParams sky;
    sky.sun_direction = {0.2, 0.6, -0.7};  // in front of the camera: a highlight on the ground
    sky.sun_angular_radius = 0.08;
    sky.sun_radiance = {60.f, 55.f, 50.f};
    t.env = (WorkDir() / "sky.exr").string();
    WriteEnvironmentExr(MakeSkyWithSun(EnvmapLayout::kLatLong, 128, 64, sky), t.env);
    return t;
  }();
  return p;
}

// PSNR of the displayed images (the bench's convention): both tone-mapped with the exposure
// that puts the reference's 99th percentile of covered pixels at 1, clamped, sRGB-encoded, peak
// 1, over the pixels the meshes cover.
double CoveredPsnr(const GlossySession& s, const Camera& cam, const std::vector<float>& test,
                   const std::vector<float>& ref) {
  const RasterImage a = RasterizeTriangles(cam, s.positions(), s.triangles(), test);
  const RasterImage b = RasterizeTriangles(cam, s.positions(), s.triangles(), ref);
  std::vector<float> lum;
  for (std::size_t p = 0; p < b.triangle.size(); ++p)
    if (b.triangle[p] >= 0)
      lum.push_back(std::max({b.rgb[3 * p], b.rgb[3 * p + 1], b.rgb[3 * p + 2]}));
  EXPECT_GT(lum.size(), b.triangle.size() / 4) << "the camera should see the scene";
  std::nth_element(lum.begin(), lum.begin() + lum.size() * 99 / 100, lum.end());
  const double exposure = 1.0 / lum[lum.size() * 99 / 100];
  double se = 0;
  std::size_t count = 0;
  for (std::size_t p = 0; p < b.triangle.size(); ++p) {
    if (b.triangle[p] < 0) continue;
    for (int c = 0; c < 3; ++c) {
      const double x = SrgbEncode(std::clamp(a.rgb[3 * p + c] * exposure, 0.0, 1.0));
      const double y = SrgbEncode(std::clamp(b.rgb[3 * p + c] * exposure, 0.0, 1.0));
      se += (x - y) * (x - y);
      ++count;
    }
  }
  return se == 0 ? 99.0 : 10 * std::log10(static_cast<double>(count) / se);
}

TEST(GlossySession, VisibilityAndMaterialsReadBackFromThePack) {
  const GlossyPack& t = TinyGlossyPack();
  const auto s = GlossySession::Open(t.pack);
  ASSERT_EQ(s->sample_count(), t.traced.vertex_count);
  EXPECT_EQ(s->cubemap_n(), 64);
  EXPECT_EQ(s->mesh_count(), 2u);
  // Lossless: every map decodes to exactly the traced levels.
  for (std::size_t v = 0; v < t.traced.vertex_count; ++v)
    ASSERT_EQ(DecodeVisibilityMap(s->visibility(), v), DecodeVisibilityMap(t.traced, v)) << v;
  ASSERT_EQ(s->materials().size(), 2u);
  EXPECT_EQ(s->materials()[0].model, BrdfModel::kAshikhminShirley);
  EXPECT_DOUBLE_EQ(s->materials()[0].exponent_v, 200.0);
  EXPECT_EQ(s->materials()[1].model, BrdfModel::kPhong);
  EXPECT_DOUBLE_EQ(s->materials()[1].exponent, 60.0);
  EXPECT_FLOAT_EQ(s->materials()[1].specular[1], 0.5f);
  EXPECT_EQ(s->camera().width, 96);
}

TEST(GlossySession, AlgorithmOneMatchesThePixelBasisReferenceWithinAPsnrBound) {
  const GlossyPack& t = TinyGlossyPack();
  auto s = GlossySession::Open(t.pack);
  const CubemapRgb cube = ResampleToCubemap(ReadEnvironment(t.env), s->cubemap_n());
  const BlockLighting light = s->Lighting(cube);
  const Camera cam = s->camera();
  std::vector<float> alg(3 * s->sample_count()), ref(alg.size());
  const TripleProductStats st = s->Relight(light, cam.eye, alg);
  s->RelightReference(light, cam.eye, ref);
  for (float v : alg) ASSERT_TRUE(std::isfinite(v) && v >= 0);
  // Every case of Algorithm 1 occurs on this scene.
  EXPECT_GT(st.blocks_zero, 0u);
  EXPECT_GT(st.blocks_line6, 0u);
  EXPECT_GT(st.blocks_line9 + st.blocks_line11, 0u);
  const double psnr = CoveredPsnr(*s, cam, alg, ref);
  std::printf("glossy: Algorithm 1 vs pixel-basis reference %.1f dB PSNR (covered pixels)\n", psnr);
  EXPECT_GT(psnr, 40.0);

  // The bound is tight enough to see the glossy lobe: the same scene rendered Lambert-only is
  // far from the glossy reference.
  std::vector<Material> glossy = s->materials();
  for (Material& m : s->materials()) m.model = BrdfModel::kLambert;
  std::vector<float> lambert(alg.size());
  s->RelightReference(light, cam.eye, lambert);
  s->materials() = glossy;
  EXPECT_LT(CoveredPsnr(*s, cam, lambert, ref), psnr - 10.0);

  // The view matters for glossy materials: another eye gives another image.
  std::vector<float> moved(alg.size());
  s->Relight(light, Vec3{2.5, 1.0, -1.0}, moved);
  double diff = 0;
  for (std::size_t i = 0; i < alg.size(); ++i)
    diff = std::max(diff, double(std::abs(moved[i] - alg[i])));
  EXPECT_GT(diff, 1e-3);
}

// No silent zeroing in the glossy path (docs/viewer.md, "NaN and Inf"): under a uniform sky of
// 3e38 (finite, and every block's lighting finite) the scene's own materials stay within float,
// but a Phong lobe of exponent 10⁶ (peak (s + 2)/2π ≈ 1.6·10⁵) makes the per-block float
// products overflow: Algorithm 1 and the reference both throw NumericalError naming the pack and
// the vertex, instead of writing 0 for it.
TEST(GlossySession, OverflowIsAnErrorNamingThePackAndVertex) {
  const GlossyPack& t = TinyGlossyPack();
  auto s = GlossySession::Open(t.pack);
  CubemapRgb cube;
  cube.n = s->cubemap_n();
  for (int c = 0; c < 3; ++c) cube.Channel(c).assign(cube.TexelCount(), 3e38f);
  const BlockLighting light = s->Lighting(cube);
  std::vector<float> rgb(3 * s->sample_count());
  s->Relight(light, s->camera().eye, rgb, {.exact_cosine = true});
  for (float v : rgb) ASSERT_TRUE(std::isfinite(v));
  for (Material& m : s->materials()) {
    m.model = BrdfModel::kPhong;
    m.specular = {1.0f, 1.0f, 1.0f};
    m.exponent = m.exponent_v = 1e6;
  }
  const auto message = [](const auto& f) { return testing::NumericalErrorOf(f); };
  for (bool exact : {true, false}) {
    const std::string alg =
        message([&] { s->Relight(light, s->camera().eye, rgb, {.exact_cosine = exact}); });
    EXPECT_EQ(alg.rfind(t.pack + ": triple product: the outgoing radiance of vertex ", 0), 0u)
        << alg;
  }
  const std::string ref = message([&] { s->RelightReference(light, s->camera().eye, rgb); });
  EXPECT_EQ(ref.rfind(t.pack + ": triple product: the outgoing radiance of vertex ", 0), 0u) << ref;
  EXPECT_NE(ref.find("outside the float range"), std::string::npos) << ref;
}

TEST(GlossySession, MalformedMaterialsAndMissingVisibilityAreInputErrors) {
  const std::vector<Rgb> albedo = {{0.5f, 0.5f, 0.5f}};
  EXPECT_THROW(GlossyMaterialsFromMetadata(R"({"materials":[{"brdf":"ward"}]})", albedo, "x"),
               InputError);
  EXPECT_THROW(GlossyMaterialsFromMetadata(R"({"materials":[{"exponent":-1}]})", albedo, "x"),
               InputError);
  EXPECT_THROW(GlossyMaterialsFromMetadata(R"({"materials":[{"specular":[2,0,0]}]})", albedo, "x"),
               InputError);
  const std::vector<Material> none = GlossyMaterialsFromMetadata("{}", albedo, "x");
  ASSERT_EQ(none.size(), 1u);
  EXPECT_EQ(none[0].model, BrdfModel::kLambert);
  EXPECT_FLOAT_EQ(none[0].diffuse[0], 0.5f);

  pack::PackInput in;
  const SceneGeometry g = SquareOverGround();
  in.meshes.push_back({"square", g.meshes[0].mesh, g.meshes[0].albedo, false, 0});
  const std::string path = (WorkDir() / "novis.prtpack").string();
  pack::WritePackFile(path, in);
  EXPECT_THROW(GlossySession::Open(path), InputError);
}

int RunViewer(const std::string& args, std::string* output) {
  const std::string log = (WorkDir() / "prt_view_glossy_output.txt").string();
  const std::string cmd = std::string("'") + PRT_VIEW_EXE + "' " + args + " > '" + log + "' 2>&1";
  const int status = std::system(cmd.c_str());
  std::ifstream f(log);
  std::stringstream ss;
  ss << f.rdbuf();
  *output = ss.str();
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

std::vector<float> ReadNpy(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  std::vector<char> bytes((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  std::vector<float> out;
  if (bytes.size() < 10) return out;
  const std::size_t header =
      10 + (static_cast<unsigned char>(bytes[8]) | (static_cast<unsigned char>(bytes[9]) << 8));
  out.resize((bytes.size() - header) / 4);
  std::memcpy(out.data(), bytes.data() + header, 4 * out.size());
  return out;
}

TEST(GlossySession, PrtViewRendersAGlossyPackAsTheLibraryDoes) {
  const GlossyPack& t = TinyGlossyPack();
  const fs::path dir = WorkDir();
  const std::string png = (dir / "glossy.png").string(), exr = (dir / "glossy.exr").string(),
                    npy = (dir / "glossy.npy").string();
  std::string out;
  ASSERT_EQ(RunViewer("'" + t.pack + "' --env '" + t.env + "' --out '" + png + "' --exr '" + exr +
                          "' --radiance-out '" + npy + "'",
                      &out),
            0)
      << out;
  EXPECT_NE(out.find("glossy"), std::string::npos) << out;
  EXPECT_TRUE(fs::exists(png));
  EXPECT_TRUE(fs::exists(exr));
  const auto s = GlossySession::Open(t.pack);
  const BlockLighting light =
      s->Lighting(ResampleToCubemap(ReadEnvironment(t.env), s->cubemap_n()));
  std::vector<float> expected(3 * s->sample_count());
  s->Relight(light, s->camera().eye, expected, {.exact_cosine = true});  // prt-view's default
  EXPECT_EQ(ReadNpy(npy), expected);
  // --reference writes the pixel-basis sum; --camera moves the eye.
  ASSERT_EQ(RunViewer("'" + t.pack + "' --env '" + t.env + "' --reference --camera 2,1.5,2,0,0,0 " +
                          "--radiance-out '" + npy + "'",
                      &out),
            0)
      << out;
  s->RelightReference(light, Vec3{2, 1.5, 2}, expected);
  EXPECT_EQ(ReadNpy(npy), expected);
  // Options of transport packs are refused on glossy ones.
  EXPECT_EQ(RunViewer("'" + t.pack + "' --env '" + t.env + "' --frames 3 --out-dir '" +
                          (dir / "f").string() + "'",
                      &out),
            1)
      << out;
}

// The glossy pack in the SDL2 window (under xvfb-run): the last frame as the window shows it
// equals the headless Algorithm 1 render from the same camera to one 8-bit code per channel.
TEST(GlossySession, WindowScreenshotMatchesHeadlessRender) {
#ifndef PRT_VIEW_HAS_SDL2
  GTEST_SKIP() << "prt-view built without SDL2";
#else
  if (std::system("command -v xvfb-run >/dev/null 2>&1") != 0) GTEST_SKIP() << "no xvfb-run";
  const GlossyPack& t = TinyGlossyPack();
  const fs::path dir = WorkDir() / "window";
  fs::create_directories(dir);
  const std::string shot =
      testing::RunWindowScreenshot(PRT_VIEW_EXE, t.pack, t.env, dir, "--window-frames 3");
  ASSERT_FALSE(shot.empty()) << "prt-view --window failed, see " << (dir / "log.txt");
  const std::vector<float> codes = ReadNpy(shot);
  const auto s = GlossySession::Open(t.pack);
  const CubemapRgb cube = ResampleToCubemap(ReadEnvironment(t.env), s->cubemap_n());
  std::vector<float> rgb(3 * s->sample_count());
  s->Relight(s->Lighting(cube), s->camera().eye, rgb, {.exact_cosine = true});
  // The window's background is the environment image itself, as prt-view's.
  const ImageRgb image = s->Render(
      s->camera(), rgb,
      EnvironmentBackground(std::make_shared<const EnvironmentLookup>(ReadEnvironment(t.env))));
  ASSERT_EQ(codes.size(), image.pixels.size());
  EXPECT_LE(testing::LargestCodeDifference(codes, image), 1.0);
#endif
}

}  // namespace
}  // namespace prt
