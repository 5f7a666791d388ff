// Glossy vertex transport end to end under mpirun (docs/glossy-transport.md):
// tests/data/glossy_vertex_tiny.toml farmed with [glossy] terms = 3. The rows are the sampler's
// term rows (T_t = V·f_t with the run's own factor table), byte-identical for 1 and 2 ranks by
// brute force and by the sparse method; the pack (1.6, GLSY) relights them and combines the
// terms for the eye as Eq. 3 says; a glossy mesh with bounces is refused, naming why.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "formats/glossy_factors.h"
#include "formats/transport_file.h"
#include "packager/prtpack_reader.h"
#include "runtime/lighting.h"
#include "runtime/relight_session.h"
#include "tests/run_prt_farm.h"
#include "vocabulary/durable_file.h"
#include "vocabulary/envmap.h"
#include "vocabulary/scene.h"
#include "worker/brdf_factorisation.h"
#include "worker/embree_scene.h"
#include "worker/transport_sampler.h"

namespace prt {
namespace {

namespace fs = std::filesystem;

const std::string kSmallJobs = " --max-job-rows 23 --rows-per-block 32 --log-interval 0.2";

std::string WorkDir(const std::string& name) {
  const fs::path dir = fs::path(PRT_TEST_WORK_DIR) / ("glossy_vertex_" + name);
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir.string();
}

std::string Scene(const std::string& dir, const std::string& sampling = "") {
  std::string text = ReadWholeFile(std::string(PRT_TESTS_DATA_DIR) + "/glossy_vertex_tiny.toml");
  testing::ReplaceOnce(text, "[sampling]\n", "[sampling]\n" + sampling);
  return testing::WriteTestScene(text, dir + "/glossy_vertex_tiny.toml");
}

std::vector<float> AllRows(const std::string& file) {
  const TransportFileReader r(file);
  std::vector<float> rows(r.info().rows * r.info().cols());
  r.ReadRows(0, r.info().rows, rows.data());
  return rows;
}

TEST(GlossyVertexMpiTest, TermRowsAreTheSamplersAndByteIdenticalForAnyRankCount) {
  const std::string dir = WorkDir("brute");
  const std::string scene = Scene(dir);
  const auto one = testing::RunPrtFarm(1, scene + " --out " + dir + "/one" + kSmallJobs);
  ASSERT_EQ(one.exit_code, 0) << one.output;
  const auto two = testing::RunPrtFarm(2, scene + " --out " + dir + "/two" + kSmallJobs);
  ASSERT_EQ(two.exit_code, 0) << two.output;
  EXPECT_NE(one.output.find("BRDF terms, factorisation error"), std::string::npos) << one.output;
  for (const char* f : {"transport.prtt", "transport.prtc", "glossy.prtf"})
    EXPECT_EQ(ReadWholeFile(dir + "/one/" + f), ReadWholeFile(dir + "/two/" + f)) << f;
  // The rows: the vertices once per term, each the sampler's row with the run's factors.
  const SceneDescription s = LoadSceneFile(scene);
  const SceneGeometry g = BuildSceneGeometry(s);
  const EmbreeScene embree(g);
  auto table = std::make_shared<GlossyFactorTable>(
      ParseGlossyFactors(ReadWholeFile(dir + "/one/glossy.prtf"), "glossy.prtf"));
  ASSERT_EQ(table->terms, 3);
  EXPECT_TRUE(table->glossy(0));
  EXPECT_FALSE(table->glossy(1));
  const std::vector<SpatialSample> samples = TermSamples(SpatialSamplesOf(g), g, *table);
  ASSERT_EQ(samples.size(), 3 * g.vertex_count());
  TransportSamplerOptions so;
  so.rays_per_texel = 4;
  so.seed = 3;
  const TransportSampler sampler(embree, s.cubemap_n, so, GlossySampling{{}, {}, table});
  const std::vector<float> rows = AllRows(dir + "/one/transport.prtt");
  const std::size_t cols = sampler.layout().texel_count();
  ASSERT_EQ(rows.size(), samples.size() * cols);
  std::vector<float> row(cols);
  double ground_later_terms = 0;
  for (std::size_t i = 0; i < samples.size(); ++i) {
    sampler.ComputeRow(samples[i], i, row.data());
    for (std::size_t j = 0; j < cols; ++j) ASSERT_EQ(rows[i * cols + j], row[j]) << i << " " << j;
    if (i >= g.vertex_count() && samples[i].background)
      for (float x : row) ground_later_terms += std::abs(x);
  }
  EXPECT_EQ(ground_later_terms, 0.0);  // a diffuse mesh has no term after the first
}

TEST(GlossyVertexMpiTest, TheSparseMethodRunsPerTermAndIsByteIdentical) {
  const std::string dir = WorkDir("sparse");
  const std::string scene = Scene(dir) + " --method sparse";
  const auto one = testing::RunPrtFarm(1, scene + " --out " + dir + "/one" + kSmallJobs);
  ASSERT_EQ(one.exit_code, 0) << one.output;
  EXPECT_NE(one.output.find("sparse"), std::string::npos);
  const auto two = testing::RunPrtFarm(2, scene + " --out " + dir + "/two" + kSmallJobs);
  ASSERT_EQ(two.exit_code, 0) << two.output;
  EXPECT_EQ(ReadWholeFile(dir + "/one/transport.prtt"), ReadWholeFile(dir + "/two/transport.prtt"));
  EXPECT_EQ(ReadWholeFile(dir + "/one/transport.prtc"), ReadWholeFile(dir + "/two/transport.prtc"));
}

// Eq. 3 through the pack: the session's relit terms combined for an eye equal Σ_t g_t(ω_o)·(T_t·L)
// from the rows, a glossy vertex changes with the eye and a diffuse one does not.
TEST(GlossyVertexMpiTest, ThePackCombinesTheTermsForTheEye) {
  const std::string dir = WorkDir("pack");
  const std::string scene = Scene(dir);
  const auto run = testing::RunPrtFarm(2, scene + " --out " + dir + "/run" + kSmallJobs);
  ASSERT_EQ(run.exit_code, 0) << run.output;
  const std::string pack = dir + "/g.prtpack";
  ASSERT_EQ(std::system(
                (std::string(PRT_PACK_EXE) + " pack " + dir + "/run --out " + pack + " > /dev/null")
                    .c_str()),
            0);
  const pack::PackReader reader = pack::PackReader::OpenFile(pack);
  EXPECT_EQ(reader.version_minor(), 6);
  EXPECT_TRUE(reader.has_glossy());
  const auto session = RelightSession::Open(pack);
  ASSERT_EQ(session->terms(), 3u);
  const std::size_t V = session->sample_count();
  CubemapRgb cube;
  cube.n = session->cubemap_n();
  for (int c = 0; c < 3; ++c) cube.Channel(c).assign(cube.TexelCount(), 0.2f);
  for (std::size_t j = 0; j < 40; ++j) cube.r[j * 7] = cube.g[j * 5] = cube.b[j * 3] = 4.0f;
  const SampleRadiance radiance = session->RelightExact(ProjectLighting(cube));
  ASSERT_EQ(radiance.size(), 3 * V);
  const Vec3 eye_a{0.0, 2.5, 3.5}, eye_b{2.5, 1.0, -1.0};
  const SampleRadiance a = session->CombineTerms(radiance, eye_a);
  const SampleRadiance b = session->CombineTerms(radiance, eye_b);
  const GlossyFactorTable& table = *session->glossy();
  std::size_t glossy_changed = 0, diffuse = 0;
  const std::vector<float> shade = session->ToPackOrder(session->Shade(radiance, eye_a));
  for (std::size_t p = 0; p < V; ++p) {
    const uint32_t v = session->pack_sample()[p];
    const bool box = v < 8;  // the box's 8 vertices come first
    if (!box) {
      ++diffuse;
      for (int c = 0; c < 3; ++c) {
        EXPECT_EQ(a.channel[c][p], radiance.channel[c][p]);
        EXPECT_EQ(a.channel[c][p], b.channel[c][p]);
      }
      continue;
    }
    // Σ_t g_t(ω_o)·(T_t·L) by hand, with the pack's normal and position.
    const Vec3 x = session->positions()[p];
    const pack::UnpackedMesh mesh = reader.ReadMesh(0);
    const Vec3 normal{mesh.normals[3 * v], mesh.normals[3 * v + 1], mesh.normals[3 * v + 2]};
    float g[16];
    table.factors[0].GAll(MakeFactorFrame(normal).ToLocal(eye_a - x), g);
    for (int c = 0; c < 3; ++c) {
      double expect = 0;
      for (std::size_t t = 0; t < 3; ++t) expect += g[t] * radiance.channel[c][t * V + p];
      EXPECT_NEAR(a.channel[c][p], expect, 1e-9 * (1 + std::abs(expect)));
      EXPECT_NEAR(shade[3 * v + c], table.mesh_weight[0][c] * expect,
                  1e-5 * (1 + std::abs(expect)));
    }
    glossy_changed += std::abs(a.channel[0][p] - b.channel[0][p]) > 1e-6 ? 1 : 0;
  }
  EXPECT_EQ(diffuse, 64u);
  EXPECT_GE(glossy_changed, 4u);  // the view moves a glossy vertex's radiance
  // prt-view renders it from the scene's camera and from another.
  ASSERT_EQ(std::system((std::string(PRT_VIEW_EXE) + " " + pack + " --env " + PRT_DATA_DIR +
                         "/envmaps/sunrise.exr --exact --quiet --out " + dir +
                         "/a.png --camera 2.5,1.0,-1.0,0,0.3,0 > /dev/null 2>&1")
                            .c_str()),
            0);
  EXPECT_TRUE(fs::exists(dir + "/a.png"));
}

TEST(GlossyVertexMpiTest, BouncesWithAGlossyMeshAreRefusedNamingWhy) {
  const std::string dir = WorkDir("bounces");
  const auto r = testing::RunPrtFarm(1, Scene(dir, "bounces = 1\n") + " --out " + dir + "/run");
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("glossy vertex transport bakes the direct term only"), std::string::npos)
      << r.output;
}

}  // namespace
}  // namespace prt
