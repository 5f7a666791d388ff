// Tests for viewer_session.h, npy_writer.h and the prt-view executable, on a small pack built
// here: tests/data/tiny.toml (a box on an 8×8 ground grid, n = 8, 72 samples) ray traced with the
// worker's TransportSampler, compressed (adaptive 4D, every coefficient kept, 16 bits) and
// packed with the packager's writer.
#include "viewer/viewer_session.h"

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <memory>
#include <numbers>
#include <sstream>
#include <string>
#include <vector>

#include "formats/column_coding.h"
#include "formats/cpca_transport.h"
#include "runtime/camera_metadata.h"
#include "viewer/environment_background.h"
#include "runtime/error_test_support.h"
#include "viewer/npy_writer.h"
#include "runtime/per_band_incremental.h"
#include "viewer/tiny_scene_test_support.h"
#include "viewer/window_test_support.h"
#include "vocabulary/cubemap.h"
#include "vocabulary/cubemap_resample.h"
#include "vocabulary/environment_io.h"
#include "vocabulary/errors.h"
#include "worker/cpca.h"

namespace prt {
namespace {

namespace fs = std::filesystem;

fs::path WorkDir() {
  // One folder per process: CTest runs these tests as parallel processes.
  const fs::path d =
      fs::path(::testing::TempDir()) / ("viewer_session_test_" + std::to_string(::getpid()));
  fs::create_directories(d);
  return d;
}

using testing::TinyScene;

// Packs `rows` of the tiny scene (every coefficient at 16 bits) into WorkDir()/file.
std::string PackRows(const TinyScene& t, const std::vector<float>& rows, const std::string& file) {
  return testing::PackTinyRows(t, rows, (WorkDir() / file).string());
}

// Traces, compresses and packs the tiny scene once per test process.
const TinyScene& Tiny() {
  static const TinyScene scene = [] {
    TinyScene t = testing::TraceTinyScene();
    t.pack = PackRows(t, t.rows, "tiny.prtpack");
    return t;
  }();
  return scene;
}

// A lat-long environment: constant `base` plus a small bright "sun" around (sun_x, sun_y).
EnvironmentImage SunSky(float base, float sun, int sun_x = 40, int sun_y = 10) {
  EnvironmentImage e = EnvironmentImage::Zero(EnvmapLayout::kLatLong, 64, 32);
  for (int y = 0; y < e.height; ++y)
    for (int x = 0; x < e.width; ++x) {
      const bool in_sun = std::abs(x - sun_x) <= 1 && std::abs(y - sun_y) <= 1;
      const float v = base + (in_sun ? sun : 0.f);
      e.r[e.Index(x, y)] = v;
      e.g[e.Index(x, y)] = 0.9f * v;
      e.b[e.Index(x, y)] = 0.7f * v + 0.05f * static_cast<float>(y) / 32.f;
    }
  return e;
}

std::vector<float> ReadFile(const std::string& path) {
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

int RunViewer(const std::string& args, std::string* output = nullptr) {
  const std::string log = (WorkDir() / "prt_view_output.txt").string();
  const std::string cmd = std::string("'") + PRT_VIEW_EXE + "' " + args + " > '" + log + "' 2>&1";
  const int status = std::system(cmd.c_str());
  if (output != nullptr) {
    std::ifstream f(log);
    std::stringstream s;
    s << f.rdbuf();
    *output = s.str();
  }
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

TEST(NpyWriterTest, HeaderIsVersion1AlignedAndDataFollows) {
  const std::vector<float> v = {1.f, -2.5f, 3.f, 0.f, 1e-3f, 7.f};
  const std::vector<char> b = EncodeNpyFloat32(v, 2, 3);
  ASSERT_GE(b.size(), 10u);
  EXPECT_EQ(std::memcmp(b.data(), "\x93NUMPY", 6), 0);
  EXPECT_EQ(b[6], 1);
  EXPECT_EQ(b[7], 0);
  const std::size_t len = static_cast<unsigned char>(b[8]) |
                          (static_cast<std::size_t>(static_cast<unsigned char>(b[9])) << 8);
  EXPECT_EQ((10 + len) % 64, 0u);
  const std::string header(b.data() + 10, len);
  EXPECT_NE(header.find("'descr': '<f4'"), std::string::npos);
  EXPECT_NE(header.find("'fortran_order': False"), std::string::npos);
  EXPECT_NE(header.find("'shape': (2, 3)"), std::string::npos);
  EXPECT_EQ(header.back(), '\n');
  ASSERT_EQ(b.size(), 10 + len + 4 * v.size());
  std::vector<float> back(v.size());
  std::memcpy(back.data(), b.data() + 10 + len, 4 * v.size());
  EXPECT_EQ(back, v);
  EXPECT_THROW(EncodeNpyFloat32(v, 4, 2), std::invalid_argument);
}

TEST(ViewerSessionTest, CameraSpecAndMetadata) {
  const Camera base;
  const Camera c = ParseCameraSpec("1,2,3,0,0.5,0", base);
  EXPECT_EQ(c.eye.x, 1);
  EXPECT_EQ(c.eye.z, 3);
  EXPECT_EQ(c.target.y, 0.5);
  EXPECT_EQ(c.fov_deg, base.fov_deg);
  const Camera d = ParseCameraSpec("1,2,3,0,0.5,0,0,0,1,60", base);
  EXPECT_EQ(d.up.z, 1);
  EXPECT_EQ(d.fov_deg, 60);
  EXPECT_THROW(ParseCameraSpec("1,2,3,4", base), std::invalid_argument);
  EXPECT_THROW(ParseCameraSpec("1,2,3,0,x,0", base), std::invalid_argument);
  EXPECT_THROW(ParseCameraSpec("1,2,3,0,nan,0", base), std::invalid_argument);

  Camera m;
  EXPECT_TRUE(CameraFromMetadata(R"({"scene": {"camera": {"eye": [0, 1.2, 3.2], "fov": 35,
                                    "width": 320}}})",
                                 "x", m));
  EXPECT_EQ(m.eye.z, 3.2);
  EXPECT_EQ(m.fov_deg, 35);
  EXPECT_EQ(m.width, 320);
  EXPECT_EQ(m.height, Camera{}.height);
  Camera none;
  EXPECT_FALSE(CameraFromMetadata(R"({"report": {}})", "x", none));
  EXPECT_THROW(CameraFromMetadata(R"({"scene": {"camera": {"eye": [0, 1]}}})", "x", none),
               InputError);
}

// Under a uniform environment of radiance 1 an unoccluded vertex gets B = albedo (DESIGN.md
// "Conventions"); the ground's far corners see (nearly) the whole sky past a 1-unit box.
TEST(ViewerSessionTest, UniformSkyGivesAlbedoOnUnoccludedGround) {
  const TinyScene& tiny = Tiny();
  const auto s = ViewerSession::Open(tiny.pack);
  ASSERT_EQ(s->sample_count(), tiny.geometry.vertex_count());
  EXPECT_TRUE(s->camera_from_metadata());
  EXPECT_EQ(s->camera().width, 64);
  EXPECT_EQ(s->cubemap_n(), 8);
  const WaveletLighting l = ProjectLighting(ResampleToCubemap(SunSky(1.f, 0.f), 8));
  // Blue has a gradient; use red (constant 1).
  // In the pack's order (the session computes in its coefficient order, viewer_session.h).
  const std::vector<float> rgb = s->ToPackOrder(s->Shade(s->RelightExact(l)));
  const std::size_t ground0 = tiny.geometry.meshes[0].mesh.positions.size();
  const std::size_t res = 8;
  for (std::size_t corner :
       {ground0, ground0 + res - 1, ground0 + res * (res - 1), ground0 + res * res - 1}) {
    EXPECT_NEAR(rgb[3 * corner], 0.8, 0.8 * 0.03) << "corner sample " << corner;
  }
  // A ground vertex next to the box sees less sky than a corner.
  double centre_min = 1e9;
  for (std::size_t k = 0; k < res * res; ++k)
    centre_min = std::min(centre_min, double(rgb[3 * (ground0 + k)]));
  EXPECT_LT(centre_min, 0.7);
}

// Exact relighting from the pack equals the traced rows' T·L up to compression (every term
// kept at 16 bits) and the dense path equals the per-term operator.
TEST(ViewerSessionTest, ExactRelightMatchesTracedTransport) {
  const TinyScene& tiny = Tiny();
  const auto s = ViewerSession::Open(tiny.pack);
  const CubemapRgb cube = ResampleToCubemap(SunSky(0.3f, 40.f), tiny.n);
  const WaveletLighting l = ProjectLighting(cube);
  const SampleRadiance dense = s->RelightExact(l);
  const SampleRadiance terms = s->transport().Apply(ExactLightingTerms(l));
  const std::size_t ns = s->sample_count(), texels = 6u * 64u;
  std::vector<float> ref(3 * ns), a(3 * ns), b(3 * ns);
  for (std::size_t v = 0; v < ns; ++v)
    for (int c = 0; c < 3; ++c) {
      double sum = 0;
      for (std::size_t j = 0; j < texels; ++j)
        sum += double(tiny.rows[v * texels + j]) * cube.Channel(c)[j];
      ref[3 * v + c] = static_cast<float>(sum);  // the pack's order, from the traced rows
      a[3 * v + c] = static_cast<float>(dense.channel[c][v]);  // the session's order
      b[3 * v + c] = static_cast<float>(terms.channel[c][v]);
    }
  EXPECT_LT(RelativeRmsError(a, b), 1e-5);
  // The session's order is the box's Hilbert order, not the pack's: only ToPackOrder matches.
  const std::vector<float> a_pack = s->ToPackOrder(a);
  EXPECT_LT(RelativeRmsError(a_pack, ref), 2e-3);
  EXPECT_GT(RelativeRmsError(a_pack, ref), 0.0);  // it really went through compression
  EXPECT_GT(RelativeRmsError(a, ref), 0.05);
  // pack_sample() is a permutation, and ToPackOrder its scatter.
  std::vector<uint32_t> sorted(s->pack_sample().begin(), s->pack_sample().end());
  std::sort(sorted.begin(), sorted.end());
  for (std::size_t v = 0; v < ns; ++v) ASSERT_EQ(sorted[v], v);
  for (std::size_t p = 0; p < ns; ++p) EXPECT_EQ(a_pack[3 * s->pack_sample()[p] + 1], a[3 * p + 1]);
  // The render buffers moved with the samples: positions()[p] is pack sample pack_sample()[p]'s,
  // and triangles() mapped back through pack_sample() are the scene's triangles.
  std::vector<Vec3> pack_positions;
  std::vector<std::array<uint32_t, 3>> pack_triangles;
  for (const SceneMesh& m : tiny.geometry.meshes) {
    const auto offset = static_cast<uint32_t>(pack_positions.size());
    for (auto t : m.mesh.triangles) {
      for (uint32_t& v : t) v += offset;
      std::sort(t.begin(), t.end());
      pack_triangles.push_back(t);
    }
    pack_positions.insert(pack_positions.end(), m.mesh.positions.begin(), m.mesh.positions.end());
  }
  ASSERT_EQ(s->positions().size(), ns);
  for (std::size_t p = 0; p < ns; ++p) {
    const Vec3 d = s->positions()[p] - pack_positions[s->pack_sample()[p]];
    EXPECT_LT(std::abs(d.x) + std::abs(d.y) + std::abs(d.z), 1e-3) << p;  // Draco quantisation
  }
  std::vector<std::array<uint32_t, 3>> back;
  for (auto t : s->triangles()) {
    for (uint32_t& v : t) v = s->pack_sample()[v];
    std::sort(t.begin(), t.end());
    back.push_back(t);
  }
  std::sort(back.begin(), back.end());
  std::sort(pack_triangles.begin(), pack_triangles.end());
  EXPECT_EQ(back, pack_triangles);
}

// Interreflection with coloured albedos (issue #22): a transport of 3 rows per vertex,
// channel-major (row c·V + v is colour channel c of vertex v). Here T_r is the traced T, T_g half
// of it on the box and zero on the ground, T_b the traced T with the texels of faces 2–5 doubled:
// each channel must be lit from its own rows by its own lighting channel,
// B_c(v) = Σ_j T_c[v][j]·L_c[j], to within the compression error, through every path the viewer
// has (RelightExact, the TransportOperator's terms, NWA, BI/PBI, shading and rendering).
TEST(ViewerSessionTest, ThreeChannelPackRelightsEachChannelFromItsRows) {
  const TinyScene& tiny = Tiny();
  const std::size_t V = tiny.rows.size() / (6u * 64u), texels = 6u * 64u;
  const std::size_t box = tiny.geometry.meshes[0].mesh.positions.size();
  ASSERT_FALSE(tiny.geometry.meshes[0].is_ground);
  std::vector<float> rows(3 * V * texels);
  for (std::size_t v = 0; v < V; ++v)
    for (std::size_t j = 0; j < texels; ++j) {
      const float t = tiny.rows[v * texels + j];
      rows[(0 * V + v) * texels + j] = t;
      rows[(1 * V + v) * texels + j] = v < box ? 0.5f * t : 0.0f;
      rows[(2 * V + v) * texels + j] = j >= 2 * 64 ? 2.0f * t : t;
    }
  const std::string pack = testing::PackTinyRows(
      tiny, rows, (WorkDir() / "tiny_rgb.prtpack").string(), testing::KeepAllCompression(), 3);
  const auto s = ViewerSession::Open(pack);
  EXPECT_EQ(s->transport_header().channels, 3u);
  EXPECT_EQ(s->transport_header().sample_count, 3 * V);
  ASSERT_EQ(s->sample_count(), V);
  ASSERT_EQ(s->transport().sample_count(), V);
  const CubemapRgb cube = ResampleToCubemap(SunSky(0.3f, 40.f), tiny.n);
  const WaveletLighting l = ProjectLighting(cube);
  std::vector<float> ref(3 * V), ref_one(3 * V);  // pack order, interleaved RGB
  for (std::size_t v = 0; v < V; ++v)
    for (int c = 0; c < 3; ++c) {
      double sum = 0, one = 0;
      for (std::size_t j = 0; j < texels; ++j) {
        sum += double(rows[(c * V + v) * texels + j]) * cube.Channel(c)[j];
        one += double(tiny.rows[v * texels + j]) * cube.Channel(c)[j];
      }
      ref[3 * v + c] = static_cast<float>(sum);
      ref_one[3 * v + c] = static_cast<float>(one);
    }
  const auto interleave = [&](const SampleRadiance& r) {
    std::vector<float> out(3 * V);
    for (std::size_t p = 0; p < V; ++p)
      for (int c = 0; c < 3; ++c) out[3 * p + c] = static_cast<float>(r.channel[c][p]);
    return out;
  };
  const std::vector<float> exact = interleave(s->RelightExact(l));
  const std::vector<float> exact_pack = s->ToPackOrder(exact);
  EXPECT_LT(RelativeRmsError(exact_pack, ref), 2e-3);
  EXPECT_GT(RelativeRmsError(exact_pack, ref), 0.0);      // through compression
  EXPECT_GT(RelativeRmsError(exact_pack, ref_one), 0.1);  // not the one-channel radiance
  // Each channel on its own, where its rows differ from the others'.
  for (int c = 0; c < 3; ++c) {
    std::vector<float> got, want;
    for (std::size_t v = 0; v < V; ++v) {
      got.push_back(exact_pack[3 * v + c]);
      want.push_back(ref[3 * v + c]);
    }
    EXPECT_LT(RelativeRmsError(got, want), 2e-3) << "channel " << c;
  }
  for (std::size_t v = box; v < V; ++v) EXPECT_NEAR(exact_pack[3 * v + 1], 0.0f, 1e-4f) << v;
  // The operator (sparse terms, incremental relighters) agrees with the dense relight.
  EXPECT_LT(RelativeRmsError(interleave(s->transport().Apply(ExactLightingTerms(l))), exact), 1e-5);
  EXPECT_LT(
      RelativeRmsError(
          interleave(RelightApproximate(s->transport(), l, LightingMode::kNwa, 6 * 64)), exact),
      1e-5);
  EXPECT_LT(
      RelativeRmsError(
          interleave(RelightApproximate(s->transport(), l, LightingMode::kPbi, 6 * 64)), exact),
      1e-5);
  // Shading multiplies the receiving vertex's albedo, and the image renders.
  const std::vector<float> rgb = s->Shade(s->RelightExact(l));
  for (std::size_t p = 0; p < V; ++p)
    for (int c = 0; c < 3; ++c)
      EXPECT_FLOAT_EQ(rgb[3 * p + c], static_cast<float>(s->albedo()[p][c] * exact[3 * p + c]));
  const ImageRgb image = s->Render(s->camera(), rgb, static_cast<const CubemapRgb*>(nullptr));
  EXPECT_GT(std::count_if(image.pixels.begin(), image.pixels.end(), [](float x) { return x > 0; }),
            0);
  // A 3-channel pack whose channels are all T relights like the one-channel pack of T (both
  // within their compression error of the same radiance).
  std::vector<float> same(3 * V * texels);
  for (std::size_t c = 0; c < 3; ++c)
    std::copy(tiny.rows.begin(), tiny.rows.end(),
              same.begin() + static_cast<std::ptrdiff_t>(c * V * texels));
  const auto s3 = ViewerSession::Open(
      testing::PackTinyRows(tiny, same, (WorkDir() / "tiny_rgb_same.prtpack").string(),
                            testing::KeepAllCompression(), 3));
  const auto s1 = ViewerSession::Open(tiny.pack);
  const std::vector<float> b3 = s3->ToPackOrder(interleave(s3->RelightExact(l)));
  const std::vector<float> b1 = s1->ToPackOrder(interleave(s1->RelightExact(l)));
  EXPECT_LT(RelativeRmsError(b3, ref_one), 2e-3);
  EXPECT_LT(RelativeRmsError(b1, ref_one), 2e-3);
  EXPECT_LT(RelativeRmsError(b3, b1), 2e-3);
}

// NWA with every non-zero coefficient is exact; fewer terms are not. BI/PBI from zero with N
// terms equal NWA's first frame up to the ranking they share (area-weighted |L|).
TEST(ViewerSessionTest, ApproximationsConvergeToExact) {
  const TinyScene& tiny = Tiny();
  const auto s = ViewerSession::Open(tiny.pack);
  const WaveletLighting l = ProjectLighting(ResampleToCubemap(SunSky(0.3f, 40.f), tiny.n));
  const std::vector<float> exact = s->Shade(s->RelightExact(l));
  const std::vector<float> all =
      s->Shade(RelightApproximate(s->transport(), l, LightingMode::kNwa, 6 * 64));
  EXPECT_LT(RelativeRmsError(all, exact), 1e-5);
  const std::vector<float> nwa10 =
      s->Shade(RelightApproximate(s->transport(), l, LightingMode::kNwa, 10));
  const std::vector<float> pbi10 =
      s->Shade(RelightApproximate(s->transport(), l, LightingMode::kPbi, 10));
  const double e_nwa = RelativeRmsError(nwa10, exact);
  EXPECT_GT(e_nwa, 1e-3);
  EXPECT_LT(e_nwa, 1.0);
  EXPECT_GT(RelativeRmsError(pbi10, exact), 1e-3);
}

// Overbeck et al. §5: BI and PBI start exact (frame 0 is the full multiply), track a rotation
// with N terms per frame, and once the environment is still reach the exact image within
// ⌈384 / N⌉ frames (per_band_incremental.h), to float rounding of the compressed path.
TEST(ViewerSessionTest, RotationThenHoldConverges) {
  const TinyScene& tiny = Tiny();
  const auto s = ViewerSession::Open(tiny.pack);
  RotationOptions o;
  o.degrees_per_frame = 5;
  o.rotate_frames = 6;
  o.hold_frames = 16;
  o.terms = 30;
  int calls = 0;
  // SunSky's sun: 3×3 pixels of 40.3 (red) around pixel (40, 10) of the 64×32 map.
  const auto lookup = std::make_shared<const EnvironmentLookup>(SunSky(0.3f, 40.f));
  const Vec3 sun = LatLongDirection(64, 32, 40, 10);
  const CubemapLayout layout(tiny.n);
  const std::vector<RotationFrame> f =
      RunRotation(*s, SunSky(0.3f, 40.f), o, [&](const RotationFrameView& v) {
        ++calls;
        EXPECT_EQ(v.exact_rgb.size(), 3 * s->sample_count());
        // The frame's rotation is its lighting's, and the background made with it shows the sun
        // where that lighting has it (prt-view's rotation frames, environment_background.h).
        const double angle = std::min(v.errors.frame, o.rotate_frames) * o.degrees_per_frame;
        EXPECT_DOUBLE_EQ(v.rotation_y, angle * std::numbers::pi / 180);
        const Vec3 lit_from = RotateAboutY(sun, v.rotation_y);
        EXPECT_GT(v.cube.r[layout.TexelOf(lit_from)], 10.0f) << v.errors.frame;
        EXPECT_EQ(EnvironmentBackground(lookup, v.rotation_y)(lit_from)[0], 40.3f);
      });
  ASSERT_EQ(f.size(), 23u);
  EXPECT_EQ(calls, 23);
  EXPECT_LT(f[0].image_error[1], 1e-5);
  EXPECT_LT(f[0].image_error[2], 1e-5);
  EXPECT_LT(f[0].lighting_error[2], 1e-9);
  EXPECT_GT(f[0].image_error[0], 1e-4);  // NWA-30 of 384 coefficients is not exact
  EXPECT_DOUBLE_EQ(f[6].angle_deg, 30.0);
  EXPECT_DOUBLE_EQ(f[22].angle_deg, 30.0);
  EXPECT_GT(f[3].lighting_error[2], 1e-6);  // the rotation moved the sun
  const int pbi = FramesToConverge(f, o, 2, 1e-3);
  const int bi = FramesToConverge(f, o, 1, 1e-3);
  EXPECT_GE(pbi, 1);
  EXPECT_LE(pbi, 13);
  EXPECT_GE(bi, 1);
  EXPECT_LE(bi, 13);
  EXPECT_LT(f.back().lighting_error[2], 1e-9);
  EXPECT_LT(f.back().image_error[2], 1e-5);
  EXPECT_EQ(FramesToConverge(f, o, 0, 1e-3), -1);  // NWA-30 never gets there

  const std::string csv = (WorkDir() / "rotation.csv").string();
  WriteRotationCsv(f, o.terms, csv);
  std::ifstream in(csv);
  std::string line;
  int lines = 0;
  while (std::getline(in, line)) ++lines;
  EXPECT_EQ(lines, 2 + 23);
}

// A CPCA pack (docs/cpca.md): the session relights from the clusters in the pack's own sample
// order, RelightExact and the operator agree with the decoded rows times the lighting, the
// traced transport is matched to the CPCA error, and the rotation's PBI column (Overbeck 2006
// §6.3: PBI on the lighting, Eq. 10's S/4 basis terms) converges to the exact image once the
// lighting holds still.
TEST(ViewerSessionTest, CpcaPackRelightsFromItsClusters) {
  const TinyScene& tiny = Tiny();
  const std::size_t ns = tiny.rows.size() / (6u * 64u), texels = 6u * 64u;
  CompressionOptions o;
  o.scheme = CompressionScheme::kCpca;
  o.cpca_clusters = 12;
  o.cpca_bases = 8;
  o.bits = 14;
  o.keep_fraction = 0.5;
  o.cpca_coefficient_bits = 14;
  const CompressedTransportHeader h =
      MakeCompressedHeader(o, tiny.n, SpatialDomainOf(tiny.geometry));
  std::vector<float> hat = tiny.rows;
  PrepareRows(h, o, hat.data(), ns);
  CpcaStats stats;
  const CpcaTransport t = CompressCpca(hat.data(), h, CpcaOptionsFrom(h), nullptr, &stats);
  pack::PackInput in;
  in.metadata_json = R"({"scene": {"camera": {"eye": [2.0, 2.0, 3.0], "target": [0.0, 0.3, 0.0],
      "up": [0.0, 1.0, 0.0], "fov": 45.0, "width": 64, "height": 48}}})";
  in.meshes = pack::PackMeshesOf(tiny.geometry);
  in.cpca = t;
  const std::string path = (WorkDir() / "tiny_cpca.prtpack").string();
  pack::WritePackFile(path, in);
  const auto s = ViewerSession::Open(path);
  ASSERT_NE(s->cpca(), nullptr);
  EXPECT_EQ(s->transport_header().scheme, CompressionScheme::kCpca);
  EXPECT_THROW(s->relighter(), std::logic_error);
  for (std::size_t p = 0; p < ns; ++p) EXPECT_EQ(s->pack_sample()[p], p);
  const CubemapRgb cube = ResampleToCubemap(SunSky(0.3f, 40.f), tiny.n);
  const WaveletLighting l = ProjectLighting(cube);
  const SampleRadiance exact = s->RelightExact(l);
  const SampleRadiance terms = s->transport().Apply(ExactLightingTerms(l));
  std::vector<float> decoded(texels), a(3 * ns), b(3 * ns), ref(3 * ns), traced(3 * ns);
  for (std::size_t v = 0; v < ns; ++v) {
    DecodeCpcaRow(t, v, decoded);
    for (int c = 0; c < 3; ++c) {
      double sum = 0, sum_traced = 0;
      for (std::size_t j = 0; j < texels; ++j) {
        sum += double(decoded[j]) * l.coefficient[c][j];
        sum_traced += double(tiny.rows[v * texels + j]) * cube.Channel(c)[j];
      }
      ref[3 * v + c] = static_cast<float>(sum);
      traced[3 * v + c] = static_cast<float>(sum_traced);
      a[3 * v + c] = static_cast<float>(exact.channel[c][v]);
      b[3 * v + c] = static_cast<float>(terms.channel[c][v]);
    }
  }
  EXPECT_LT(RelativeRmsError(a, ref), 1e-5);
  EXPECT_LT(RelativeRmsError(b, ref), 1e-5);
  // The relit error is at most the transport's (Frobenius) error, here a few per cent.
  EXPECT_LT(RelativeRmsError(a, traced), std::max(0.01, stats.relative_error));
  EXPECT_GT(RelativeRmsError(a, traced), 0.0);
  RotationOptions ro;
  ro.degrees_per_frame = 5;
  ro.rotate_frames = 4;
  ro.hold_frames = 16;
  ro.terms = 40;
  const std::vector<RotationFrame> f = RunRotation(*s, SunSky(0.3f, 40.f), ro, {});
  EXPECT_LT(f[0].image_error[2], 1e-5);
  EXPECT_GT(f[2].image_error[2], 1e-6);
  EXPECT_LT(f.back().image_error[2], 1e-5);
  EXPECT_LT(f.back().lighting_error[2], 1e-9);
  // prt-view: the clusters as a picture (Overbeck Figure 12) and the relit image; a pack of
  // columns has no clusters to draw.
  const fs::path dir = WorkDir() / "cpca_cli";
  fs::remove_all(dir);
  fs::create_directories(dir);
  const std::string env = (dir / "sky.exr").string();
  WriteEnvironmentExr(SunSky(0.3f, 40.f), env);
  std::string out;
  EXPECT_EQ(RunViewer("'" + path + "' --env '" + env + "' --exact --out '" +
                          (dir / "relit.png").string() + "' --clusters-out '" +
                          (dir / "clusters.png").string() + "'",
                      &out),
            0)
      << out;
  EXPECT_NE(out.find("12 clusters of 8 bases"), std::string::npos) << out;
  EXPECT_TRUE(fs::exists(dir / "relit.png"));
  EXPECT_GT(fs::file_size(dir / "clusters.png"), 100u);
  EXPECT_EQ(RunViewer("'" + tiny.pack + "' --env '" + env + "' --clusters-out '" +
                          (dir / "x.png").string() + "'",
                      &out),
            1)
      << out;
  EXPECT_NE(out.find("holds no CPCA transport"), std::string::npos) << out;
  // Cluster colours: one colour per cluster.
  const std::vector<float> colours = ClusterColours(*s->cpca());
  for (std::size_t v = 0; v < ns; ++v)
    for (std::size_t u = 0; u < ns; ++u)
      if (t.cluster_of[u] == t.cluster_of[v]) {
        EXPECT_EQ(colours[3 * u], colours[3 * v]);
      }
}

// No NaN or Inf is turned into a black pixel (docs/viewer.md, "NaN and Inf"): an environment
// with an Inf pixel is refused by its reader, lighting past the relighter's float range and finite
// T and L whose product overflows float are errors naming the pack (and the sample), in the
// library and as prt-view's one-line message with exit code 2.
TEST(ViewerSessionTest, NonFiniteRadianceIsAnErrorNamingThePack) {
  const TinyScene& tiny = Tiny();
  const fs::path dir = WorkDir() / "nonfinite";
  fs::remove_all(dir);
  fs::create_directories(dir);
  std::string out;
  // 1. An Inf pixel: the EXR reader refuses it (vocabulary/environment_io.h) before anything is
  //    resampled, naming the file and the pixel; in memory, the resampler refuses it too.
  EnvironmentImage inf_sky = SunSky(0.3f, 40.f);
  inf_sky.r[inf_sky.Index(5, 3)] = std::numeric_limits<float>::infinity();
  const std::string inf_env = (dir / "inf_sky.exr").string();
  WriteEnvironmentExr(inf_sky, inf_env);
  EXPECT_THROW(ReadEnvironment(inf_env), InputError);
  EXPECT_THROW(ResampleToCubemap(inf_sky, tiny.n), NumericalError);
  EXPECT_EQ(RunViewer("'" + tiny.pack + "' --env '" + inf_env + "' --exact --quiet --out '" +
                          (dir / "x.png").string() + "'",
                      &out),
            2);
  EXPECT_NE(out.find("inf_sky.exr: Inf at pixel (x=5, y=3, channel R)"), std::string::npos) << out;

  // 2. Finite T and finite L whose product overflows float: T scaled by 1e15 (still a finite,
  //    valid pack), a uniform sky of 1e30: T·L ≈ 1e45.
  std::vector<float> bright_rows = tiny.rows;
  for (float& v : bright_rows) v *= 1e15f;
  const std::string bright = PackRows(tiny, bright_rows, "bright.prtpack");
  const auto s = ViewerSession::Open(bright);
  const WaveletLighting l = ProjectLighting(ResampleToCubemap(SunSky(1e30f, 0.f), tiny.n));
  const auto message = [](const auto& f) { return testing::NumericalErrorOf(f); };
  const std::string exact = message([&] { s->RelightExact(l); });
  EXPECT_EQ(exact.rfind(bright + ": the relit radiance of sample ", 0), 0u) << exact;
  EXPECT_NE(exact.find("overflows the relighter's float range"), std::string::npos) << exact;
  const std::string nwa =
      message([&] { RelightApproximate(s->transport(), l, LightingMode::kNwa, 10); });
  EXPECT_EQ(nwa.rfind(bright + ": the relit radiance of sample ", 0), 0u) << nwa;
  // A radiance that is a finite double but not a float (1e39, e.g. from an operator that sums in
  // double) is named by the pack's own sample number at shading.
  SampleRadiance r(s->sample_count());
  r.channel[1][5] = 1e39;
  const std::string shade = message([&] { s->Shade(r); });
  EXPECT_EQ(shade.rfind(bright + ": the shaded radiance of sample " +
                            std::to_string(s->pack_sample()[5]) + " (channel 1), albedo ",
                        0),
            0u)
      << shade;
  EXPECT_NE(shade.find(" × T·L 1e+39, is outside the float range (3.4e38)"), std::string::npos)
      << shade;
  const std::string bright_env = (dir / "bright_sky.exr").string();
  WriteEnvironmentExr(SunSky(1e30f, 0.f), bright_env);
  EXPECT_EQ(RunViewer("'" + bright + "' --env '" + bright_env + "' --exact --quiet --out '" +
                          (dir / "x.png").string() + "'",
                      &out),
            2);
  // One line, naming the pack.
  EXPECT_EQ(out.rfind("prt-view: " + bright + ": the relit radiance of sample ", 0), 0u) << out;
  EXPECT_EQ(std::count(out.begin(), out.end(), '\n'), 1) << out;
  EXPECT_EQ(RunViewer("'" + bright + "' --env '" + bright_env +
                          "' --lighting pbi --terms 20 "
                          "--quiet --out '" +
                          (dir / "x.png").string() + "'",
                      &out),
            2);
  EXPECT_EQ(out.rfind("prt-view: " + bright + ": ", 0), 0u) << out;
  EXPECT_FALSE(fs::exists(dir / "x.png"));

  // 3. Lighting past the float range of the relighter (a uniform 3e38 sky: each face's scaling
  //    coefficient is n·3e38 = 2.4e39) on the ordinary pack.
  const std::string max_env = (dir / "max_sky.exr").string();
  WriteEnvironmentExr(SunSky(3e38f, 0.f), max_env);
  EXPECT_EQ(RunViewer("'" + tiny.pack + "' --env '" + max_env + "' --exact --quiet --out '" +
                          (dir / "x.png").string() + "'",
                      &out),
            2);
  EXPECT_EQ(out.rfind("prt-view: " + tiny.pack + ": lighting coefficient ", 0), 0u) << out;
  EXPECT_NE(out.find("outside the float range of the relighter"), std::string::npos) << out;
}

// prt-view end to end: exit codes, PNG/EXR/npy outputs, --exact radiance equal to the library's,
// and the rotation mode's frames, CSV and plot.
TEST(PrtViewCliTest, EndToEnd) {
  const TinyScene& tiny = Tiny();
  const fs::path dir = WorkDir() / "cli";
  fs::remove_all(dir);
  fs::create_directories(dir);
  const std::string env = (dir / "sky.exr").string();
  WriteEnvironmentExr(SunSky(0.3f, 40.f), env);

  std::string out;
  EXPECT_EQ(RunViewer("--help", &out), 0);
  EXPECT_NE(out.find("--radiance-out"), std::string::npos);
  EXPECT_EQ(RunViewer("--version", &out), 0);
  EXPECT_NE(out.find("prt-view"), std::string::npos);
  EXPECT_EQ(RunViewer("'" + tiny.pack + "' --env '" + env + "' --bogus"), 1);
  EXPECT_EQ(RunViewer("'" + tiny.pack + "'"), 1);  // --env missing
  EXPECT_EQ(RunViewer("'" + tiny.pack + "' --env '" + env + "' --out x.png --lighting foo"), 1);
  EXPECT_EQ(RunViewer("'" + (dir / "missing.prtpack").string() + "' --env '" + env + "' --out '" +
                          (dir / "x.png").string() + "'",
                      &out),
            2);
  EXPECT_NE(out.find("missing.prtpack"), std::string::npos);
  {
    std::ofstream bad(dir / "bad.prtpack");
    bad << "not a pack";
  }
  EXPECT_EQ(RunViewer("'" + (dir / "bad.prtpack").string() + "' --env '" + env + "' --out '" +
                      (dir / "x.png").string() + "'"),
            2);
  EXPECT_EQ(RunViewer("'" + tiny.pack + "' --env '" + (dir / "nosky.exr").string() + "' --out '" +
                      (dir / "x.png").string() + "'"),
            2);

  const std::string png = (dir / "frame.png").string(), exr = (dir / "frame.exr").string(),
                    npy = (dir / "radiance.npy").string();
  ASSERT_EQ(
      RunViewer("'" + tiny.pack + "' --env '" + env + "' --exact --out '" + png + "' --exr '" +
                    exr + "' --radiance-out '" + npy + "' --width 40 --height 30",
                &out),
      0)
      << out;
  EXPECT_TRUE(fs::exists(png));
  EXPECT_TRUE(fs::exists(exr));
  const std::vector<float> radiance = ReadFile(npy);
  const auto s = ViewerSession::Open(tiny.pack);
  // --radiance-out is in the pack's order.
  const std::vector<float> expected = s->ToPackOrder(
      s->Shade(s->RelightExact(ProjectLighting(ResampleToCubemap(ReadEnvironment(env), tiny.n)))));
  ASSERT_EQ(radiance.size(), expected.size());
  EXPECT_LT(RelativeRmsError(radiance, expected), 1e-6);

  ASSERT_EQ(RunViewer("'" + tiny.pack + "' --env '" + env + "' --terms 20 --lighting nwa " +
                          "--camera 0,3,4,0,0,0 --out '" + png + "' --radiance-out '" + npy + "'",
                      &out),
            0)
      << out;
  const std::vector<float> nwa = ReadFile(npy);
  EXPECT_GT(RelativeRmsError(nwa, expected), 1e-4);

  const fs::path frames = dir / "frames";
  ASSERT_EQ(RunViewer("'" + tiny.pack + "' --env '" + env + "' --terms 30 --rotate 5 " +
                          "--frames 3 --hold 2 --out-dir '" + frames.string() + "'",
                      &out),
            0)
      << out;
  for (int f = 0; f <= 5; ++f) {
    char name[32];
    std::snprintf(name, sizeof name, "frame_%04d.png", f);
    EXPECT_TRUE(fs::exists(frames / name)) << name;
  }
  std::ifstream csv(frames / "rotation_errors.csv");
  std::string line;
  int lines = 0;
  while (std::getline(csv, line)) {
    ++lines;
    // The last field: PBI's reset decision per band, one '0'/'1' per band after frame 0.
    const std::string last = line.substr(line.rfind(',') + 1);
    if (lines == 2) {
      EXPECT_EQ(last, "pbi_reset_bands");
    } else if (lines == 3) {
      EXPECT_EQ(last, "") << line;  // frame 0: Initialize, no decision
    }
    if (lines >= 4) {
      EXPECT_EQ(last.size(), static_cast<std::size_t>(HaarLightingBasis(tiny.n).band_count()))
          << line;
      EXPECT_EQ(last.find_first_not_of("01"), std::string::npos) << line;
    }
  }
  EXPECT_EQ(lines, 2 + 6);
  if (std::system("command -v gnuplot >/dev/null 2>&1") == 0) {
    EXPECT_TRUE(fs::exists(frames / "rotation_errors.png"));
  }
}

// prt-view --window under Xvfb: after a few frames of PBI under still lighting (exact from frame 0,
// Initialize) the window shows the headless exact render, to one 8-bit code per channel.
TEST(PrtViewCliTest, WindowScreenshotMatchesHeadlessRender) {
#ifndef PRT_VIEW_HAS_SDL2
  GTEST_SKIP() << "prt-view built without SDL2";
#else
  if (std::system("command -v xvfb-run >/dev/null 2>&1") != 0) GTEST_SKIP() << "no xvfb-run";
  const TinyScene& tiny = Tiny();
  const fs::path dir = WorkDir() / "window";
  fs::remove_all(dir);
  fs::create_directories(dir);
  const std::string env = (dir / "sky.exr").string();
  WriteEnvironmentExr(SunSky(0.3f, 40.f), env);
  const std::string shot = testing::RunWindowScreenshot(
      PRT_VIEW_EXE, tiny.pack, env, dir, "--window-frames 5 --lighting pbi --terms 50");
  ASSERT_FALSE(shot.empty()) << "prt-view --window failed, see " << (dir / "log.txt");
  const std::vector<float> codes = ReadFile(shot);
  const auto s = ViewerSession::Open(tiny.pack);
  const CubemapRgb cube = ResampleToCubemap(ReadEnvironment(env), tiny.n);
  // The window's background is the environment image itself, as prt-view's.
  const ImageRgb image = s->Render(
      s->camera(), s->Shade(s->RelightExact(ProjectLighting(cube))),
      EnvironmentBackground(std::make_shared<const EnvironmentLookup>(ReadEnvironment(env))));
  ASSERT_EQ(codes.size(), image.pixels.size());
  EXPECT_LE(testing::LargestCodeDifference(codes, image), 1.0);
#endif
}

}  // namespace
}  // namespace prt
