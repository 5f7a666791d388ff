// prt-pack's library side: a run folder (geometry.prtg, scene.toml, report.json, transport.prtc)
// packs into a .prtpack whose meshes, compressed transport and metadata read back unchanged;
// inspect and verify report on it.
#include "packager/run_folder_pack.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <nlohmann/json.hpp>

#include "formats/compressed_transport.h"
#include "formats/cpca_transport.h"
#include "formats/geometry_file.h"
#include "formats/transport_file.h"
#include "packager/prtpack_test_util.h"
#include "packager/prtpack_transport.h"
#include "vocabulary/durable_file.h"
#include "vocabulary/errors.h"

namespace prt::pack {
namespace {

namespace fs = std::filesystem;

struct RunFolderFixture {
  fs::path dir;
  SceneGeometry geometry;
  CompressedTransport transport;
};

RunFolderFixture MakeRunFolder(const std::string& name) {
  RunFolderFixture f;
  f.dir = fs::temp_directory_path() / name;
  fs::remove_all(f.dir);
  fs::create_directories(f.dir);
  SceneMesh a;
  a.name = "octa";
  a.mesh = testing::MakeSmallMesh();
  a.albedo = {0.6f, 0.5f, 0.4f};
  SceneMesh g;
  g.name = "ground";
  g.mesh = testing::MakeSmallMesh(2.0);
  g.is_ground = true;
  g.grid_resolution = 2;
  f.geometry.meshes = {a, g};
  f.geometry.bounds_min = {-2, -2, -2};
  f.geometry.bounds_max = {2, 2, 2};
  WriteSceneGeometryFile((f.dir / kGeometryFileName).string(), f.geometry);
  WriteFileDurably((f.dir / kSceneCopyFileName).string(), "name = \"octa-scene\"\ncubemap_n = 2\n");
  WriteFileDurably((f.dir / kReportFileName).string(),
                   R"({"wall_seconds": 1.5, "method": "brute", "cubemap_n": 2,
                       "compression": {"relative_frobenius_error": 0.0125, "scheme": "2d"},
                       "accuracy": {"monte_carlo": {"estimable": true, "environments": [
                         {"name": "uniform", "relative_rms": 0.0012},
                         {"name": "sunrise.exr", "relative_rms": 0.0085}]}}})");
  f.transport.header.cubemap_n = 2;
  f.transport.header.sample_count = 12;
  f.transport.header.terms_per_column = 2;
  SpatialSegment s1, s2;
  s1.count = 6;
  s2.count = 6;
  f.transport.header.domain.segments = {s1, s2};
  for (uint32_t col = 0; col < 24; col += 3) {
    CompressedColumn c;
    c.column = col;
    c.scale = 1.0f + float(col);
    c.index = {col % 12};
    c.q = {int32_t(col) - 12 == 0 ? 1 : int32_t(col) - 12};
    f.transport.columns.push_back(c);
  }
  const std::vector<uint8_t> bytes = EncodeCompressedTransport(f.transport, 7);
  WriteFileDurably((f.dir / kCompressedTransportFileName).string(),
                   std::string_view(reinterpret_cast<const char*>(bytes.data()), bytes.size()));
  return f;
}

TEST(RunFolderPack, RunFolderRoundTrip) {
  const RunFolderFixture f = MakeRunFolder("prtpack_run_folder_test");
  RunPackOptions o;
  o.columns_per_block = 5;
  const std::vector<uint8_t> bytes = WritePack(PackInputFromRunFolder(f.dir.string(), o));
  const PackReader r = PackReader::OpenMemory(bytes.data(), bytes.size(), "run.prtpack");
  ASSERT_EQ(r.mesh_count(), 2u);
  for (std::size_t m = 0; m < 2; ++m) {
    const UnpackedMesh u = r.ReadMesh(m);
    EXPECT_EQ(u.name, f.geometry.meshes[m].name);
    EXPECT_EQ(u.albedo, f.geometry.meshes[m].albedo);
    EXPECT_EQ(u.is_ground, f.geometry.meshes[m].is_ground);
    EXPECT_EQ(u.ToTriangleMesh().triangles, f.geometry.meshes[m].mesh.triangles);
  }
  const CompressedTransport back = ReadCompressedTransport(r);
  EXPECT_EQ(r.ReadTransportIndex().blocks.size(), 5u);  // 24 columns in blocks of 5
  ASSERT_EQ(back.columns.size(), f.transport.columns.size());
  for (std::size_t k = 0; k < back.columns.size(); ++k) {
    EXPECT_EQ(back.columns[k].column, f.transport.columns[k].column);
    EXPECT_EQ(back.columns[k].scale, f.transport.columns[k].scale);
    EXPECT_EQ(back.columns[k].index, f.transport.columns[k].index);
    EXPECT_EQ(back.columns[k].q, f.transport.columns[k].q);
  }
  const nlohmann::json meta = nlohmann::json::parse(r.ReadMetadata());
  EXPECT_EQ(meta["scene"]["name"], "octa-scene");
  EXPECT_EQ(meta["scene"]["cubemap_n"], 2);
  EXPECT_EQ(meta["report"]["wall_seconds"], 1.5);
  EXPECT_EQ(meta["parameters"]["sample_count"], 12);
  EXPECT_EQ(meta["parameters"]["columns_per_block"], 5);

  // The run's error estimates (docs/prtpack-format.md, META "error_estimates").
  EXPECT_EQ(meta["error_estimates"]["compression"]["relative_frobenius_error"], 0.0125);
  EXPECT_EQ(meta["error_estimates"]["monte_carlo"]["environments"][1]["relative_rms"], 0.0085);

  const std::string inspect = InspectPack(r);
  EXPECT_NE(inspect.find("error estimates: compression 1.250% of T (relative Frobenius); "
                         "Monte-Carlo, relative RMS of B: 0.120% uniform, 0.850% sunrise.exr"),
            std::string::npos)
      << inspect;
  EXPECT_NE(inspect.find("run: brute, n = 2"), std::string::npos) << inspect;
  EXPECT_EQ(inspect.find("wall_seconds"), std::string::npos) << inspect;  // no JSON dump
  EXPECT_NE(inspect.find("scene: \"octa-scene\""), std::string::npos) << inspect;
  EXPECT_NE(inspect.find("transport: 12 samples x 1 channel (one row per sample for r, g, b) x 24 "
                         "columns in 5 blocks"),
            std::string::npos)
      << inspect;
  EXPECT_FALSE(meta["parameters"].contains("channels"));  // one-channel META as before
  EXPECT_NE(inspect.find("mesh 1 \"ground\": 6 vertices, 8 triangles"), std::string::npos)
      << inspect;
  const std::string verify = VerifyPack(r);
  EXPECT_NE(verify.find("OK"), std::string::npos);
  EXPECT_NE(verify.find("8 compressed columns decoded"), std::string::npos) << verify;
  fs::remove_all(f.dir);
}

TEST(RunFolderPack, MissingOrMismatchedTransportIsAnError) {
  const RunFolderFixture f = MakeRunFolder("prtpack_run_folder_test2");
  CompressedTransport wrong = f.transport;
  wrong.header.sample_count = 10;
  wrong.header.domain.segments[1].count = 4;
  for (CompressedColumn& c : wrong.columns) c.index = {c.index[0] % 10};
  const std::vector<uint8_t> bytes = EncodeCompressedTransport(wrong);
  WriteFileDurably((f.dir / kCompressedTransportFileName).string(),
                   std::string_view(reinterpret_cast<const char*>(bytes.data()), bytes.size()));
  try {
    PackInputFromRunFolder(f.dir.string(), {});
    FAIL() << "accepted a transport for another geometry";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(
                  "10 rows (1 colour channel(s) × 10 samples) but the geometry has 12"),
              std::string::npos)
        << e.what();
  }
  // 3 × 12 rows packed as one channel would be 36 samples; 3 × 10 rows are not 12 vertices.
  for (uint32_t channels : {1u, 3u}) {
    CompressedTransport t = testing::MakeSmallCompressedTransport(3);
    if (channels == 1) {
      t.header.channels = 1;
      t.header.domain.segments = {SpatialSegment{SpatialSegment::Kind::kMesh1D, 36, 0, 0, {}}};
    } else {
      wrong = t;
      t.header.sample_count = 30;
      for (SpatialSegment& s : t.header.domain.segments) s.count = 10;
      for (CompressedColumn& c : t.columns)
        for (uint32_t& i : c.index) i = i / 12 * 10 + i % 12 % 10;
    }
    const std::vector<uint8_t> b = EncodeCompressedTransport(t);
    WriteFileDurably((f.dir / kCompressedTransportFileName).string(),
                     std::string_view(reinterpret_cast<const char*>(b.data()), b.size()));
    try {
      PackInputFromRunFolder(f.dir.string(), {});
      FAIL() << "accepted " << t.header.sample_count << " rows of " << channels << " channel(s)";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(channels == 1 ? "36 rows (1 colour channel(s) × 36"
                                                         : "30 rows (3 colour channel(s) × 10"),
                std::string::npos)
          << e.what();
    }
  }
  fs::remove(f.dir / kCompressedTransportFileName);
  EXPECT_THROW(PackInputFromRunFolder(f.dir.string(), {}), InputError);
  RunPackOptions geometry_only;
  geometry_only.geometry_only = true;
  const PackInput in = PackInputFromRunFolder(f.dir.string(), geometry_only);
  EXPECT_FALSE(in.transport.has_value());
  EXPECT_EQ(in.meshes.size(), 2u);
  fs::remove_all(f.dir);
  EXPECT_THROW(PackInputFromRunFolder(f.dir.string(), {}), InputError);
}

// A run with interreflection and coloured albedos (issue #22): transport.prtc has 3 × 12
// channel-major rows for the 12 vertices; the pack is 1.1, TRNS and META say 3 channels, inspect
// shows them and verify decodes every column.
TEST(RunFolderPack, ThreeChannelTransportPacksWithItsChannels) {
  const RunFolderFixture f = MakeRunFolder("prtpack_run_folder_test_rgb");
  const CompressedTransport t = testing::MakeSmallCompressedTransport(3);
  const std::vector<uint8_t> b = EncodeCompressedTransport(t, 7);
  WriteFileDurably((f.dir / kCompressedTransportFileName).string(),
                   std::string_view(reinterpret_cast<const char*>(b.data()), b.size()));
  RunPackOptions o;
  o.columns_per_block = 5;
  const std::vector<uint8_t> bytes = WritePack(PackInputFromRunFolder(f.dir.string(), o));
  const PackReader r = PackReader::OpenMemory(bytes.data(), bytes.size(), "rgb.prtpack");
  EXPECT_EQ(r.version_minor(), 1);
  EXPECT_EQ(r.ReadTransportIndex().channels, 3u);
  EXPECT_EQ(r.ReadTransportIndex().row_count, 36u);
  const nlohmann::json meta = nlohmann::json::parse(r.ReadMetadata());
  EXPECT_EQ(meta["parameters"]["channels"], 3);
  EXPECT_EQ(meta["parameters"]["sample_count"], 36);
  EXPECT_EQ(ReadCompressedTransport(r).header.channels, 3u);
  const std::string inspect = InspectPack(r);
  EXPECT_NE(inspect.find("rgb.prtpack: .prtpack 1.1"), std::string::npos) << inspect;
  EXPECT_NE(inspect.find("transport: 12 samples x 3 colour channels (rows channel-major) x 24 "
                         "columns in 5 blocks (encoding 3)"),
            std::string::npos)
      << inspect;
  EXPECT_NE(VerifyPack(r).find("5 compressed columns decoded"), std::string::npos) << VerifyPack(r);
  fs::remove_all(f.dir);
}

// A visibility run (farm job "visibility"): visibility.prtv and no transport packs into one
// VISB section per mesh whose maps decode to exactly the run's; the scene's glossy materials
// go to META "materials"; inspect and verify report the visibility.
TEST(RunFolderPack, VisibilityRunPacksLosslesslyWithItsMaterials) {
  const RunFolderFixture f = MakeRunFolder("prtpack_run_folder_test_vis");
  fs::remove(f.dir / kCompressedTransportFileName);
  const std::vector<uint8_t> vis = testing::MakeSmallVisibility(12, 5);
  WriteFileDurably((f.dir / kVisibilityFileName).string(),
                   std::string_view(reinterpret_cast<const char*>(vis.data()), vis.size()));
  WriteFileDurably((f.dir / kSceneCopyFileName).string(),
                   "[[mesh]]\nname = \"octa\"\npath = \"octa.off\"\nalbedo = [0.6, 0.5, 0.4]\n"
                   "brdf = \"phong\"\nspecular = [0.3, 0.3, 0.3]\nexponent = 30\n"
                   "[ground]\nbrdf = \"ashikhmin-shirley\"\nspecular = [0.2, 0.2, 0.2]\n"
                   "exponent = 10\nexponent_v = 100\n");
  const PackInput in = PackInputFromRunFolder(f.dir.string(), {});
  EXPECT_FALSE(in.transport.has_value());
  ASSERT_TRUE(in.visibility.has_value());
  ASSERT_EQ(in.visibility->per_mesh.size(), 2u);
  const std::vector<uint8_t> bytes = WritePack(in);
  const PackReader r = PackReader::OpenMemory(bytes.data(), bytes.size(), "vis.prtpack");
  ASSERT_TRUE(r.has_visibility());
  const VisibilityBlocks back = r.ReadAllVisibility();
  const VisibilityBlocks original = DecodeVisibilityBlocks(vis);
  ASSERT_EQ(back.vertex_count, 12u);
  for (std::size_t v = 0; v < 12; ++v)
    EXPECT_EQ(DecodeVisibilityMap(back, v), DecodeVisibilityMap(original, v)) << v;
  EXPECT_EQ(r.ReadVisibility(1).vertex_count, 6u);
  const nlohmann::json meta = nlohmann::json::parse(r.ReadMetadata());
  ASSERT_EQ(meta["materials"].size(), 2u);
  EXPECT_EQ(meta["materials"][0]["brdf"], "phong");
  EXPECT_EQ(meta["materials"][0]["exponent"], 30.0);
  EXPECT_EQ(meta["materials"][1]["brdf"], "ashikhmin-shirley");
  EXPECT_EQ(meta["materials"][1]["exponent_v"], 100.0);
  EXPECT_EQ(meta["visibility"]["n"], 16);
  EXPECT_EQ(meta["visibility"]["raw_bitmap_bytes"], 12 * 6 * 16 * 16 / 8);
  const std::string inspect = InspectPack(r);
  EXPECT_NE(inspect.find("visibility: 2 VISB sections"), std::string::npos) << inspect;
  EXPECT_NE(VerifyPack(r).find("12 visibility maps decoded"), std::string::npos);

  // Maps for another vertex count are refused, naming the file.
  const std::vector<uint8_t> wrong = testing::MakeSmallVisibility(10, 5);
  WriteFileDurably((f.dir / kVisibilityFileName).string(),
                   std::string_view(reinterpret_cast<const char*>(wrong.data()), wrong.size()));
  try {
    PackInputFromRunFolder(f.dir.string(), {});
    FAIL() << "accepted visibility for another geometry";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("visibility.prtv"), std::string::npos) << e.what();
  }
  fs::remove_all(f.dir);
}

// A CPCA run (scheme cpca, issue #24): transport.prtc is EncodeCpcaTransport's bytes; the pack
// carries the CPCA section instead of TRNS (1.3), META "parameters" names the clusters and bases,
// the transport reads back identical, inspect shows its shape and verify decodes it. A CPCA
// transport of other rows than the geometry's vertices is refused.
TEST(RunFolderPack, CpcaRunPacksTheCpcaSection) {
  const RunFolderFixture f = MakeRunFolder("prtpack_run_folder_test_cpca");
  for (uint32_t channels : {1u, 3u}) {
    SCOPED_TRACE(channels);
    const CpcaTransport t = testing::MakeSmallCpcaTransport(channels);
    const std::vector<uint8_t> b = EncodeCpcaTransport(t);
    WriteFileDurably((f.dir / kCompressedTransportFileName).string(),
                     std::string_view(reinterpret_cast<const char*>(b.data()), b.size()));
    const PackInput in = PackInputFromRunFolder(f.dir.string(), {});
    EXPECT_FALSE(in.transport.has_value());
    ASSERT_TRUE(in.cpca.has_value());
    const std::vector<uint8_t> bytes = WritePack(in);
    const PackReader r = PackReader::OpenMemory(bytes.data(), bytes.size(), "cpca.prtpack");
    EXPECT_EQ(r.version_minor(), 3);
    EXPECT_TRUE(r.has_cpca());
    EXPECT_FALSE(r.has_transport());
    EXPECT_EQ(EncodeCpcaTransport(ReadCpcaTransport(r)), b);  // identical
    const nlohmann::json meta = nlohmann::json::parse(r.ReadMetadata());
    EXPECT_EQ(meta["parameters"]["scheme"], "cpca");
    EXPECT_EQ(meta["parameters"]["clusters"], 2);
    EXPECT_EQ(meta["parameters"]["bases"], 2);
    EXPECT_EQ(meta["parameters"]["coefficient_bits"], 12);
    EXPECT_EQ(meta["parameters"]["cpca_method"], "standard");
    EXPECT_EQ(meta["parameters"]["sample_count"], 12 * channels);
    EXPECT_FALSE(meta["parameters"].contains("columns_per_block"));
    EXPECT_EQ(meta["parameters"].contains("channels"), channels == 3);
    const std::string inspect = InspectPack(r);
    EXPECT_NE(inspect.find("cpca.prtpack: .prtpack 1.3"), std::string::npos) << inspect;
    EXPECT_NE(inspect.find("transport: CPCA (clustered PCA), 12 samples x " +
                           std::string(channels == 1 ? "1 channel (one row per sample for r, g, b)"
                                                     : "3 colour channels (rows channel-major)") +
                           " x 24 columns (haar): 2 clusters x 2 bases, " +
                           std::to_string(t.term_count()) + " mean and basis terms (9 bits), " +
                           std::to_string(24 * channels) + " coefficients (12 bits)"),
              std::string::npos)
        << inspect;
    EXPECT_NE(inspect.find("  CPCA     0  zstd"), std::string::npos) << inspect;  // section table
    const std::string verify = VerifyPack(r);
    EXPECT_NE(verify.find("OK"), std::string::npos) << verify;
    EXPECT_NE(
        verify.find("CPCA transport decoded (" + std::to_string(12 * channels) +
                    " rows, 2 clusters x 2 bases, " + std::to_string(t.term_count()) + " terms)"),
        std::string::npos)
        << verify;
  }
  // 10 rows for 12 vertices.
  CpcaTransport wrong = testing::MakeSmallCpcaTransport();
  wrong.header.sample_count = 10;
  wrong.header.domain.segments[0].count = 10;
  wrong.cluster_of.resize(10);
  wrong.coefficients.resize(20);
  const std::vector<uint8_t> b = EncodeCpcaTransport(wrong);
  WriteFileDurably((f.dir / kCompressedTransportFileName).string(),
                   std::string_view(reinterpret_cast<const char*>(b.data()), b.size()));
  try {
    PackInputFromRunFolder(f.dir.string(), {});
    FAIL() << "accepted a CPCA transport for another geometry";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(
                  "10 rows (1 colour channel(s) × 10 samples) but the geometry has 12"),
              std::string::npos)
        << e.what();
  }
  // A damaged CPCA body is refused naming the file.
  std::vector<uint8_t> cut = EncodeCpcaTransport(testing::MakeSmallCpcaTransport());
  cut.pop_back();
  WriteFileDurably((f.dir / kCompressedTransportFileName).string(),
                   std::string_view(reinterpret_cast<const char*>(cut.data()), cut.size()));
  try {
    PackInputFromRunFolder(f.dir.string(), {});
    FAIL() << "accepted a truncated CPCA transport";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("transport.prtc"), std::string::npos) << e.what();
  }
  fs::remove_all(f.dir);
}

}  // namespace
}  // namespace prt::pack
