// The C API (runtime/prt_runtime.h) against prt-view on the same pack and map: exact lighting
// and the first frame of NWA / PBI equal prt-view --radiance-out to 1e-5 relative, for the test
// corpus' 2D, adaptive-4D, CPCA, image and 3-channel packs, and a glossy pack's frames (towards
// its camera's eye and an orbited one) equal prt-view's; a frame split into ranges equals the
// whole frame; rotations; every misuse and hostile input an error code and a message.
#include "runtime/prt_runtime.h"

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>
#include <vector>

#include "formats/image_file.h"
#include "packager/prtpack_writer.h"
#include "runtime/lighting.h"
#include "runtime/relight_session.h"
#include "viewer/tiny_scene_test_support.h"
#include "vocabulary/cubemap.h"
#include "vocabulary/cubemap_resample.h"
#include "vocabulary/environment_io.h"
#include "vocabulary/envmap.h"
#include "worker/column_order.h"
#include "worker/cpca.h"
#include "worker/transport_compressor.h"
#include "worker/visibility_sampler.h"

namespace {

namespace fs = std::filesystem;

const std::string kCorpus = PRT_CORPUS_DIR;

fs::path WorkDir() {
  const fs::path d = fs::temp_directory_path() / ("prt_runtime_test_" + std::to_string(getpid()));
  fs::create_directories(d);
  return d;
}

// The packs the tests relight, built once from tests/data/tiny.toml ray traced at n = 8 (72
// samples) as the farm would: adaptive 4D, 4D, 2D, 3 colour channels, CPCA, and an image pack
// (24 × 16 pixels over the tiny scene's meshes, a smooth made-up transport).
std::string Pack(const std::string& kind) {
  using namespace prt;
  static const prt::testing::TinyScene tiny = prt::testing::TraceTinyScene(8, 4);
  const fs::path path = WorkDir() / (kind + ".prtpack");
  if (fs::exists(path)) return path.string();
  CompressionOptions o;
  o.bits = 12;
  o.keep_fraction = 0.3;
  if (kind == "adaptive4d") return prt::testing::PackTinyRows(tiny, tiny.rows, path.string(), o);
  if (kind == "4d") {
    o.scheme = CompressionScheme::k4D;
    return prt::testing::PackTinyRows(tiny, tiny.rows, path.string(), o);
  }
  if (kind == "2d") {
    o.scheme = CompressionScheme::k2D;
    return prt::testing::PackTinyRows(tiny, tiny.rows, path.string(), o);
  }
  if (kind == "rgb") {  // channel c: the rows scaled by a colour, as a tinted bounce would
    std::vector<float> rows;
    for (float k : {1.0f, 0.6f, 0.3f})
      for (float v : tiny.rows) rows.push_back(k * v);
    return prt::testing::PackTinyRows(tiny, rows, path.string(), o, 3);
  }
  pack::PackInput in;
  in.metadata_json = R"({"scene": {"camera": {"eye": [2.0, 2.0, 3.0], "target": [0.0, 0.3, 0.0],
      "up": [0.0, 1.0, 0.0], "fov": 45.0, "width": 24, "height": 16}}})";
  in.meshes = pack::PackMeshesOf(tiny.geometry);
  if (kind == "cpca") {
    const std::size_t ns = tiny.rows.size() / (6u * 64u);
    o.scheme = CompressionScheme::kCpca;
    o.cpca_clusters = 6;
    o.cpca_bases = 4;
    o.cpca_coefficient_bits = 14;
    const CompressedTransportHeader h =
        MakeCompressedHeader(o, tiny.n, SpatialDomainOf(tiny.geometry));
    std::vector<float> hat = tiny.rows;
    PrepareRows(h, o, hat.data(), ns);
    in.cpca = CompressCpca(hat.data(), h, CpcaOptionsFrom(h), nullptr, nullptr);
  } else {  // "image", or "image-ss": the same supersampled 2×2 with row y = 3 half covered
    const uint32_t w = 24, hgt = 16, texels = 6 * 64;
    ImageSamplesInfo info;
    info.camera.width = static_cast<int>(w);
    info.camera.height = static_cast<int>(hgt);
    info.camera.eye = {2.0, 2.0, 3.0};
    info.camera.target = {0.0, 0.3, 0.0};
    info.camera.fov_deg = 45.0;
    std::vector<float> rows(std::size_t{w} * hgt * texels);
    info.pixel_mesh.resize(std::size_t{w} * hgt);
    for (uint32_t y = 0; y < hgt; ++y)
      for (uint32_t x = 0; x < w; ++x) {
        const std::size_t p = std::size_t{y} * w + x;
        info.pixel_mesh[p] = y < 3 ? kImageBackground : (x < w / 2 ? 0u : 1u);
        if (info.pixel_mesh[p] == kImageBackground) continue;
        for (uint32_t t = 0; t < texels; ++t)  // smooth in the pixel, varied over directions
          rows[p * texels + t] =
              0.002f *
              (1.0f + std::sin(0.3f * static_cast<float>(x) + 0.05f * static_cast<float>(t))) *
              (1.0f +
               0.5f * std::cos(0.2f * static_cast<float>(y) + 0.11f * static_cast<float>(t)));
      }
    const CompressedTransport ct = CompressTransport(rows.data(), 8, ImageDomain(w, hgt), o);
    in.transport = pack::MakeTransportInput(ct, 64);
    if (kind == "image-ss") {
      info.supersample = 2;
      info.coverage.assign(info.pixels(), 1.f);
      info.pixel_weight.resize(info.pixels());
      for (std::size_t p = 0; p < info.pixels(); ++p) {
        const uint32_t m = info.pixel_mesh[p];
        const float cov = m == kImageBackground ? 0.f : (p / w == 3 ? 0.5f : 1.f);
        info.coverage[p] = cov;
        for (int c = 0; c < 3; ++c)
          info.pixel_weight[p][c] =
              m == kImageBackground ? 0.f : cov * tiny.geometry.meshes[m].albedo[c];
      }
    }
    in.image = info;
  }
  pack::WritePackFile(path.string(), in);
  return path.string();
}
const std::string kEnv = std::string(PRT_DATA_DIR) + "/envmaps/sunrise.exr";

// A glossy pack of tests/data/tiny.toml (the box, then the ground grid: 8 + 64 vertices):
// visibility traced at cubemap size n (1 bit, one ray per texel) as the farm's visibility job
// does, the box Ashikhmin-Shirley (anisotropic), the ground Lambert, the other packs' camera.
// runtime/fuzz_corpus/glossy.prtpack is GlossyPack(16).
constexpr std::size_t kGlossyBoxVertices = 8;
std::string GlossyPack(int n) {
  using namespace prt;
  const fs::path path = WorkDir() / ("glossy" + std::to_string(n) + ".prtpack");
  if (fs::exists(path)) return path.string();
  const SceneGeometry geometry =
      BuildSceneGeometry(LoadSceneFile(std::string(PRT_SOURCE_DIR) + "/tests/data/tiny.toml"));
  const std::vector<SpatialSample> samples = SpatialSamplesOf(geometry);
  const EmbreeScene embree(geometry);
  const VisibilitySampler sampler(embree, VisibilitySamplerOptions{n, 1, 1});
  pack::PackInput in;
  in.meshes = pack::PackMeshesOf(geometry);
  pack::VisibilityInput vis;
  std::size_t first = 0;
  for (const SceneMesh& m : geometry.meshes) {
    const std::size_t nv = m.mesh.positions.size();
    vis.per_mesh.push_back(EncodeVisibilityBlocks(
        sampler.ComputeBlocks(std::span<const SpatialSample>(samples).subspan(first, nv))));
    first += nv;
  }
  in.visibility = std::move(vis);
  const nlohmann::json meta = {{"scene",
                                {{"camera",
                                  {{"eye", {2.0, 2.0, 3.0}},
                                   {"target", {0.0, 0.3, 0.0}},
                                   {"up", {0.0, 1.0, 0.0}},
                                   {"fov", 45.0},
                                   {"width", 64},
                                   {"height", 48}}}}},
                               {"materials",
                                {{{"name", "box"},
                                  {"brdf", "ashikhmin-shirley"},
                                  {"diffuse", {0.3, 0.3, 0.3}},
                                  {"specular", {0.5, 0.5, 0.5}},
                                  {"exponent", 30.0},
                                  {"exponent_v", 150.0}},
                                 {{"name", "ground"}, {"brdf", "lambert"}}}}};
  in.metadata_json = meta.dump();
  pack::WritePackFile(path.string(), in);
  return path.string();
}

// The map as the C API takes it: interleaved RGB, rows from the top.
std::vector<float> Interleaved(const prt::EnvironmentImage& e) {
  std::vector<float> rgb(3 * e.PixelCount());
  for (std::size_t i = 0; i < e.PixelCount(); ++i) {
    rgb[3 * i] = e.r[i];
    rgb[3 * i + 1] = e.g[i];
    rgb[3 * i + 2] = e.b[i];
  }
  return rgb;
}

// A float32 .npy of prt-view (samples × 3, C order).
std::vector<float> ReadNpy(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  std::string bytes((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  if (bytes.size() < 10) return {};
  const std::size_t header = static_cast<uint8_t>(bytes[8]) | (static_cast<uint8_t>(bytes[9]) << 8);
  const std::size_t begin = 10 + header;
  std::vector<float> v((bytes.size() - begin) / 4);
  std::memcpy(v.data(), bytes.data() + begin, v.size() * 4);
  return v;
}

// prt-view's radiance for the pack under kEnv: --exact, or `terms` of `lighting`.
std::vector<float> PrtViewRadiance(const std::string& pack, const std::string& mode_args,
                                   const std::string& name) {
  // This process's own folder: CTest runs each pack's case as its own process, in parallel.
  const fs::path dir = WorkDir();
  const std::string npy = (dir / (name + ".npy")).string();
  fs::remove(npy);
  const std::string cmd = std::string("'") + PRT_VIEW_EXE + "' '" + pack + "' --env '" + kEnv +
                          "' " + mode_args + " --quiet --radiance-out '" + npy + "' > '" +
                          (dir / (name + ".log")).string() + "' 2>&1";
  const int status = std::system(cmd.c_str());
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) return {};
  return ReadNpy(npy);
}

// max |a − b| / max |b|.
double RelativeMaxError(const std::vector<float>& a, const std::vector<float>& b) {
  double err = 0, scale = 0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    err = std::max(err, std::abs(static_cast<double>(a[i]) - b[i]));
    scale = std::max(scale, std::abs(static_cast<double>(b[i])));
  }
  return scale > 0 ? err / scale : err;
}

struct Handle {
  prt_runtime* rt;
  explicit Handle(const std::string& path) : rt(prt_runtime_open_file(path.c_str())) {}
  ~Handle() { prt_runtime_close(rt); }
};

class RuntimeVsPrtView : public ::testing::TestWithParam<const char*> {};

TEST_P(RuntimeVsPrtView, ExactNwaAndPbiEqualPrtView) {
  if (!fs::exists(kEnv)) GTEST_SKIP() << kEnv << " missing (scripts/install-deps.sh)";
  const std::string pack = Pack(GetParam());
  Handle h(pack);
  ASSERT_NE(h.rt, nullptr) << prt_runtime_last_error();
  const std::size_t n = prt_runtime_sample_count(h.rt);
  ASSERT_GT(n, 0u);
  const prt::EnvironmentImage env = prt::ReadEnvironment(kEnv);
  const std::vector<float> map = Interleaved(env);
  ASSERT_EQ(prt_runtime_set_environment_latlong(h.rt, map.data(), env.width, env.height),
            PRT_RUNTIME_OK)
      << prt_runtime_last_error();
  std::vector<float> rgb(3 * n);

  const std::vector<float> exact = PrtViewRadiance(pack, "--exact", "exact");
  ASSERT_EQ(exact.size(), 3 * n) << "prt-view --exact failed on " << pack;
  ASSERT_EQ(prt_runtime_relight(h.rt, 0, rgb.data(), n), PRT_RUNTIME_OK)
      << prt_runtime_last_error();
  EXPECT_LE(RelativeMaxError(rgb, exact), 1e-5) << pack;
  double sum = 0;
  for (float v : rgb) sum += v;
  EXPECT_GT(sum, 0.0) << "a lit pack relit to black";

  // NWA and the first PBI frame (from no light) at 40 terms: prt-view --terms 40.
  const std::vector<float> nwa = PrtViewRadiance(pack, "--terms 40 --lighting nwa", "nwa");
  ASSERT_EQ(prt_runtime_set_lighting_mode(h.rt, PRT_RUNTIME_LIGHTING_NWA), PRT_RUNTIME_OK);
  ASSERT_EQ(prt_runtime_relight(h.rt, 40, rgb.data(), n), PRT_RUNTIME_OK)
      << prt_runtime_last_error();
  EXPECT_LE(RelativeMaxError(rgb, nwa), 1e-5) << pack;
  const std::vector<float> pbi = PrtViewRadiance(pack, "--terms 40 --lighting pbi", "pbi");
  ASSERT_EQ(prt_runtime_set_lighting_mode(h.rt, PRT_RUNTIME_LIGHTING_PBI), PRT_RUNTIME_OK);
  ASSERT_EQ(prt_runtime_relight(h.rt, 40, rgb.data(), n), PRT_RUNTIME_OK)
      << prt_runtime_last_error();
  EXPECT_LE(RelativeMaxError(rgb, pbi), 1e-5) << pack;

  // Still lighting: PBI frames converge to the exact radiance (6n² / 40 frames at most).
  const unsigned frames = prt_runtime_coefficient_count(h.rt) / 40 + 2;
  for (unsigned f = 0; f < frames; ++f)
    ASSERT_EQ(prt_runtime_relight(h.rt, 40, rgb.data(), n), PRT_RUNTIME_OK);
  EXPECT_LE(RelativeMaxError(rgb, exact), 1e-5) << pack;
}

INSTANTIATE_TEST_SUITE_P(Packs, RuntimeVsPrtView,
                         ::testing::Values("adaptive4d", "4d", "2d", "rgb", "cpca", "image"),
                         [](const auto& param_info) { return std::string(param_info.param); });

// A frame split into ranges (from several threads at once) writes what the whole frame writes,
// in both orders and every lighting mode.
TEST(RuntimeRanges, SplitFramesEqualWholeFrames) {
  const prt::EnvironmentImage env = prt::ReadEnvironment(kEnv);
  const std::vector<float> map = Interleaved(env);
  for (const char* name : {"adaptive4d", "cpca", "image"}) {
    for (int order : {PRT_RUNTIME_ORDER_PACK, PRT_RUNTIME_ORDER_RUNTIME}) {
      for (int mode : {PRT_RUNTIME_LIGHTING_NWA, PRT_RUNTIME_LIGHTING_PBI}) {
        Handle whole(Pack(name)), split(Pack(name));
        ASSERT_NE(whole.rt, nullptr);
        ASSERT_NE(split.rt, nullptr);
        const std::size_t n = prt_runtime_sample_count(whole.rt);
        for (prt_runtime* rt : {whole.rt, split.rt}) {
          ASSERT_EQ(prt_runtime_set_environment_latlong(rt, map.data(), env.width, env.height),
                    PRT_RUNTIME_OK);
          ASSERT_EQ(prt_runtime_set_sample_order(rt, order), PRT_RUNTIME_OK);
          ASSERT_EQ(prt_runtime_set_lighting_mode(rt, mode), PRT_RUNTIME_OK);
        }
        std::vector<float> a(3 * n), b(3 * n, -1.0f);
        for (int frame = 0; frame < 3; ++frame) {
          for (prt_runtime* rt : {whole.rt, split.rt})
            ASSERT_EQ(prt_runtime_set_rotation_y(rt, 0.3 * frame), PRT_RUNTIME_OK);
          const unsigned terms = frame == 0 ? 0u : 30u;
          ASSERT_EQ(prt_runtime_relight(whole.rt, terms, a.data(), n), PRT_RUNTIME_OK);
          ASSERT_EQ(prt_runtime_prepare(split.rt, terms), PRT_RUNTIME_OK)
              << prt_runtime_last_error();
          std::vector<std::thread> threads;
          std::array<int, 3> status{};
          for (std::size_t r = 0; r < 3; ++r)
            threads.emplace_back([&, r] {
              const std::size_t lo = n * r / 3, hi = n * (r + 1) / 3;
              status[r] = prt_runtime_relight_range(split.rt, lo, hi - lo, b.data(), n);
            });
          for (std::thread& t : threads) t.join();
          for (int s : status) ASSERT_EQ(s, PRT_RUNTIME_OK);
          EXPECT_LE(RelativeMaxError(b, a), 1e-6)
              << name << " order " << order << " mode " << mode << " frame " << frame;
        }
      }
    }
  }
}

// An incremental frame left half relit refuses the next prepare (its state would be torn).
TEST(RuntimeRanges, TornIncrementalFrameIsAStateError) {
  Handle h(Pack("adaptive4d"));
  ASSERT_NE(h.rt, nullptr);
  const std::size_t n = prt_runtime_sample_count(h.rt);
  std::vector<float> map(2 * 8 * 8 * 3, 1.0f), out(3 * n);
  ASSERT_EQ(prt_runtime_set_environment_latlong(h.rt, map.data(), 16, 8), PRT_RUNTIME_OK);
  ASSERT_EQ(prt_runtime_prepare(h.rt, 20), PRT_RUNTIME_OK);
  ASSERT_EQ(prt_runtime_relight_range(h.rt, 0, n / 2, out.data(), n), PRT_RUNTIME_OK);
  EXPECT_EQ(prt_runtime_prepare(h.rt, 20), PRT_RUNTIME_ERROR_STATE);
  EXPECT_NE(std::string(prt_runtime_last_error()).find("relit"), std::string::npos);
}

// A uniform map of radiance 1 lights every sample with the same radiance under any rotation; a
// rotation about +Y given as a matrix takes prt-view's path (the angle), and a general one
// resamples each leaf rotated: it keeps the map's power and, for a map symmetric about the
// rotation's axis, its lighting.
TEST(RuntimeRotation, MatricesAndAngles) {
  const prt::EnvironmentImage env = prt::ReadEnvironment(kEnv);
  const std::vector<float> map = Interleaved(env);
  Handle a(Pack("adaptive4d")), b(Pack("adaptive4d"));
  ASSERT_NE(a.rt, nullptr);
  const std::size_t n = prt_runtime_sample_count(a.rt);
  std::vector<float> ra(3 * n), rb(3 * n);
  for (prt_runtime* rt : {a.rt, b.rt})
    ASSERT_EQ(prt_runtime_set_environment_latlong(rt, map.data(), env.width, env.height),
              PRT_RUNTIME_OK);
  const double angle = 0.7;
  ASSERT_EQ(prt_runtime_set_rotation_y(a.rt, angle), PRT_RUNTIME_OK);
  const float c = static_cast<float>(std::cos(angle)), s = static_cast<float>(std::sin(angle));
  const float ry[9] = {c, 0, s, 0, 1, 0, -s, 0, c};
  ASSERT_EQ(prt_runtime_set_rotation(b.rt, ry), PRT_RUNTIME_OK);
  ASSERT_EQ(prt_runtime_relight(a.rt, 0, ra.data(), n), PRT_RUNTIME_OK);
  ASSERT_EQ(prt_runtime_relight(b.rt, 0, rb.data(), n), PRT_RUNTIME_OK);
  EXPECT_LE(RelativeMaxError(rb, ra), 1e-5);

  // The general resampler against the angle's for the same rotation about +Y.
  const std::array<double, 9> m{std::cos(angle),  0, std::sin(angle), 0, 1, 0,
                                -std::sin(angle), 0, std::cos(angle)};
  const prt::CubemapRgb by_angle = prt::ResampleToCubemap(env, 16, angle);
  const prt::CubemapRgb by_matrix = prt::ResampleToCubemap(env, 16, m);
  double err = 0, scale = 0;
  for (int ch = 0; ch < 3; ++ch)
    for (std::size_t t = 0; t < by_angle.Channel(ch).size(); ++t) {
      err = std::max(err, std::abs(double(by_angle.Channel(ch)[t]) - by_matrix.Channel(ch)[t]));
      scale = std::max(scale, std::abs(double(by_angle.Channel(ch)[t])));
    }
  EXPECT_LE(err / scale, 1e-6);

  // A general rotation (about X) keeps the power of the map: Σ texel · solid angle.
  const double ax = 1.1;
  const std::array<double, 9> rx{1,           0, 0, 0, std::cos(ax), -std::sin(ax), 0, std::sin(ax),
                                 std::cos(ax)};
  const prt::CubemapRgb still = prt::ResampleToCubemap(env, 16, 0.0);
  const prt::CubemapRgb turned = prt::ResampleToCubemap(env, 16, rx);
  const prt::CubemapLayout layout(16);
  for (int ch = 0; ch < 3; ++ch) {
    double p0 = 0, p1 = 0;
    for (std::size_t t = 0; t < layout.texel_count(); ++t) {
      p0 += still.Channel(ch)[t] * layout.TexelSolidAngle(t);
      p1 += turned.Channel(ch)[t] * layout.TexelSolidAngle(t);
    }
    EXPECT_NEAR(p1, p0, 1e-4 * p0) << "channel " << ch;
  }
  // And it moves the light: the rotated lighting differs from the still one.
  double diff = 0;
  for (std::size_t t = 0; t < layout.texel_count(); ++t)
    diff += std::abs(double(still.Channel(0)[t]) - turned.Channel(0)[t]);
  EXPECT_GT(diff, 1e-3);
  const float rxf[9] = {1,
                        0,
                        0,
                        0,
                        float(std::cos(ax)),
                        float(-std::sin(ax)),
                        0,
                        float(std::sin(ax)),
                        float(std::cos(ax))};
  ASSERT_EQ(prt_runtime_set_rotation(b.rt, rxf), PRT_RUNTIME_OK) << prt_runtime_last_error();
  ASSERT_EQ(prt_runtime_relight(b.rt, 0, rb.data(), n), PRT_RUNTIME_OK);
  for (float v : rb) ASSERT_TRUE(std::isfinite(v));
}

// The preview lighting (a reduced map) keeps the map's power and stays close to the full map's
// lighting; switching it off gives the full map's numbers back exactly.
TEST(RuntimeRotation, PreviewIsCloseAndReversible) {
  const prt::EnvironmentImage env = prt::ReadEnvironment(kEnv);
  const std::vector<float> map = Interleaved(env);
  Handle h(Pack("adaptive4d"));
  ASSERT_NE(h.rt, nullptr);
  const std::size_t n = prt_runtime_sample_count(h.rt);
  std::vector<float> full(3 * n), preview(3 * n), back(3 * n);
  ASSERT_EQ(prt_runtime_set_environment_latlong(h.rt, map.data(), env.width, env.height),
            PRT_RUNTIME_OK);
  ASSERT_EQ(prt_runtime_set_rotation_y(h.rt, 0.4), PRT_RUNTIME_OK);
  ASSERT_EQ(prt_runtime_relight(h.rt, 0, full.data(), n), PRT_RUNTIME_OK);
  ASSERT_EQ(prt_runtime_set_preview(h.rt, 1), PRT_RUNTIME_OK);
  ASSERT_EQ(prt_runtime_relight(h.rt, 0, preview.data(), n), PRT_RUNTIME_OK);
  double num = 0, den = 0, sum_full = 0, sum_preview = 0;
  for (std::size_t i = 0; i < full.size(); ++i) {
    num += (double(preview[i]) - full[i]) * (double(preview[i]) - full[i]);
    den += double(full[i]) * full[i];
    sum_full += full[i];
    sum_preview += preview[i];
  }
  std::printf("preview (n = 8: a 128-pixel-wide map) vs full sunrise: relit rel. RMS %.4f\n",
              std::sqrt(num / den));
  EXPECT_LT(std::sqrt(num / den), 0.05);
  EXPECT_GT(std::sqrt(num / den), 0.0) << "the preview should be a different map";
  EXPECT_NEAR(sum_preview, sum_full, 0.02 * sum_full);
  ASSERT_EQ(prt_runtime_set_preview(h.rt, 0), PRT_RUNTIME_OK);
  ASSERT_EQ(prt_runtime_relight(h.rt, 0, back.data(), n), PRT_RUNTIME_OK);
  EXPECT_EQ(back, full);
  EXPECT_EQ(prt_runtime_set_preview(h.rt, 2), PRT_RUNTIME_ERROR_ARGUMENT);
  // Angles between whole cells of the periodic grid (blended), and a general rotation (the
  // reduced map): each close to its exact frame.
  const auto rel = [](const std::vector<float>& a, const std::vector<float>& b) {
    double nu = 0, de = 0;
    for (std::size_t i = 0; i < a.size(); ++i) {
      nu += (double(a[i]) - b[i]) * (double(a[i]) - b[i]);
      de += double(b[i]) * b[i];
    }
    return std::sqrt(nu / de);
  };
  const float tilt[9] = {1, 0, 0, 0, 0.8f, -0.6f, 0, 0.6f, 0.8f};
  for (int k = 0; k < 3; ++k) {
    ASSERT_EQ(prt_runtime_set_preview(h.rt, 0), PRT_RUNTIME_OK);
    if (k < 2) {
      ASSERT_EQ(prt_runtime_set_rotation_y(h.rt, k == 0 ? -1.234 : 2.0), PRT_RUNTIME_OK);
    } else {
      ASSERT_EQ(prt_runtime_set_rotation(h.rt, tilt), PRT_RUNTIME_OK);
    }
    ASSERT_EQ(prt_runtime_relight(h.rt, 0, full.data(), n), PRT_RUNTIME_OK);
    ASSERT_EQ(prt_runtime_set_preview(h.rt, 1), PRT_RUNTIME_OK);
    ASSERT_EQ(prt_runtime_relight(h.rt, 0, preview.data(), n), PRT_RUNTIME_OK);
    std::printf("preview, rotation %d: relit rel. RMS %.4f\n", k, rel(preview, full));
    EXPECT_LT(rel(preview, full), 0.01) << k;
  }
}

// Misuse and hostile input: a status and a message, never a crash.
TEST(RuntimeErrors, EveryMisuseIsAnErrorWithAMessage) {
  const auto message = [] { return std::string(prt_runtime_last_error()); };
  EXPECT_EQ(prt_runtime_open_file(nullptr), nullptr);
  EXPECT_FALSE(message().empty());
  EXPECT_EQ(prt_runtime_open_file("/nonexistent/x.prtpack"), nullptr);
  EXPECT_NE(message().find("/nonexistent/x.prtpack"), std::string::npos) << message();
  const char junk[64] = "PRTPACK but not really";
  EXPECT_EQ(prt_runtime_open_memory(junk, sizeof junk), nullptr);
  EXPECT_FALSE(message().empty());
  EXPECT_EQ(prt_runtime_open_memory(nullptr, 10), nullptr);
  EXPECT_EQ(prt_runtime_open_file((kCorpus + "/no_transport.prtpack").c_str()), nullptr);
  EXPECT_NE(message().find("transport"), std::string::npos) << message();
  // Every entry point on a NULL handle.
  float out[3];
  const float identity[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  EXPECT_EQ(prt_runtime_sample_count(nullptr), 0u);
  EXPECT_EQ(prt_runtime_relight(nullptr, 0, out, 1), PRT_RUNTIME_ERROR_ARGUMENT);
  EXPECT_EQ(prt_runtime_set_environment_latlong(nullptr, out, 2, 1), PRT_RUNTIME_ERROR_ARGUMENT);
  EXPECT_EQ(prt_runtime_set_rotation(nullptr, identity), PRT_RUNTIME_ERROR_ARGUMENT);
  EXPECT_EQ(prt_runtime_prepare(nullptr, 0), PRT_RUNTIME_ERROR_ARGUMENT);
  prt_runtime_close(nullptr);

  Handle h(Pack("adaptive4d"));
  ASSERT_NE(h.rt, nullptr) << message();
  const std::size_t n = prt_runtime_sample_count(h.rt);
  std::vector<float> rgb(3 * n);
  // Relighting before an environment: a state error.
  EXPECT_EQ(prt_runtime_relight(h.rt, 0, rgb.data(), n), PRT_RUNTIME_ERROR_STATE);
  EXPECT_NE(message().find("environment"), std::string::npos) << message();
  EXPECT_EQ(prt_runtime_relight_range(h.rt, 0, n, rgb.data(), n), PRT_RUNTIME_ERROR_STATE);
  // Zero-sized, wrongly shaped and non-finite maps.
  std::vector<float> map(3 * 32 * 16, 0.5f);
  EXPECT_EQ(prt_runtime_set_environment_latlong(h.rt, map.data(), 0, 0),
            PRT_RUNTIME_ERROR_ARGUMENT);
  EXPECT_EQ(prt_runtime_set_environment_latlong(h.rt, map.data(), 30, 16),
            PRT_RUNTIME_ERROR_ARGUMENT);
  EXPECT_EQ(prt_runtime_set_environment_latlong(h.rt, nullptr, 32, 16), PRT_RUNTIME_ERROR_ARGUMENT);
  map[3 * (5 * 32 + 7) + 1] = std::numeric_limits<float>::quiet_NaN();
  EXPECT_EQ(prt_runtime_set_environment_latlong(h.rt, map.data(), 32, 16), PRT_RUNTIME_ERROR_INPUT);
  EXPECT_NE(message().find("x=7, y=5"), std::string::npos) << message();
  map[3 * (5 * 32 + 7) + 1] = std::numeric_limits<float>::infinity();
  EXPECT_EQ(prt_runtime_set_environment_latlong(h.rt, map.data(), 32, 16), PRT_RUNTIME_ERROR_INPUT);
  EXPECT_EQ(prt_runtime_relight(h.rt, 0, rgb.data(), n), PRT_RUNTIME_ERROR_STATE)
      << "a refused map must not count as an environment";
  map[3 * (5 * 32 + 7) + 1] = 0.5f;
  ASSERT_EQ(prt_runtime_set_environment_latlong(h.rt, map.data(), 32, 16), PRT_RUNTIME_OK);
  // Wrong output sizes, ranges, rotations and modes.
  EXPECT_EQ(prt_runtime_relight(h.rt, 0, rgb.data(), n - 1), PRT_RUNTIME_ERROR_ARGUMENT);
  EXPECT_EQ(prt_runtime_relight(h.rt, 0, nullptr, n), PRT_RUNTIME_ERROR_ARGUMENT);
  ASSERT_EQ(prt_runtime_prepare(h.rt, 0), PRT_RUNTIME_OK);
  EXPECT_EQ(prt_runtime_relight_range(h.rt, n - 2, 5, rgb.data(), n), PRT_RUNTIME_ERROR_ARGUMENT);
  EXPECT_EQ(prt_runtime_relight_range(h.rt, SIZE_MAX, 2, rgb.data(), n),
            PRT_RUNTIME_ERROR_ARGUMENT);
  const float skew[9] = {1, 0.5f, 0, 0, 1, 0, 0, 0, 1};
  const float mirror[9] = {-1, 0, 0, 0, 1, 0, 0, 0, 1};
  const float nan9[9] = {std::numeric_limits<float>::quiet_NaN(), 0, 0, 0, 1, 0, 0, 0, 1};
  EXPECT_EQ(prt_runtime_set_rotation(h.rt, skew), PRT_RUNTIME_ERROR_ARGUMENT);
  EXPECT_EQ(prt_runtime_set_rotation(h.rt, mirror), PRT_RUNTIME_ERROR_ARGUMENT);
  EXPECT_NE(message().find("reflection"), std::string::npos) << message();
  EXPECT_EQ(prt_runtime_set_rotation(h.rt, nan9), PRT_RUNTIME_ERROR_ARGUMENT);
  EXPECT_EQ(prt_runtime_set_rotation_y(h.rt, std::nan("")), PRT_RUNTIME_ERROR_ARGUMENT);
  EXPECT_EQ(prt_runtime_set_lighting_mode(h.rt, 7), PRT_RUNTIME_ERROR_ARGUMENT);
  EXPECT_EQ(prt_runtime_set_sample_order(h.rt, -1), PRT_RUNTIME_ERROR_ARGUMENT);
  std::vector<float> xyz(3 * n + 3);
  EXPECT_EQ(prt_runtime_get_positions(h.rt, xyz.data(), n + 1), PRT_RUNTIME_ERROR_ARGUMENT);
  // A huge map value overflows float in the relight: a numeric error, not Inf in the output.
  std::vector<float> hot(3 * 32 * 16, 3e38f);
  ASSERT_EQ(prt_runtime_set_environment_latlong(h.rt, hot.data(), 32, 16), PRT_RUNTIME_OK)
      << message();
  const int s = prt_runtime_relight(h.rt, 0, rgb.data(), n);
  EXPECT_EQ(s, PRT_RUNTIME_ERROR_NUMERIC) << message();
  // And the handle still works after all of that.
  ASSERT_EQ(prt_runtime_set_environment_latlong(h.rt, map.data(), 32, 16), PRT_RUNTIME_OK);
  EXPECT_EQ(prt_runtime_relight(h.rt, 0, rgb.data(), n), PRT_RUNTIME_OK) << message();
  EXPECT_GT(prt_runtime_memory_bytes(h.rt), 0u);
}

// Geometry and order: positions and triangles in the pack's order, the runtime's order a
// permutation whose frames equal the pack order's frames permuted.
TEST(RuntimeGeometry, PositionsTrianglesAndOrders) {
  Handle h(Pack("adaptive4d"));
  ASSERT_NE(h.rt, nullptr);
  const std::size_t n = prt_runtime_sample_count(h.rt);
  EXPECT_EQ(prt_runtime_is_image(h.rt), 0);
  const std::size_t nt = prt_runtime_triangle_count(h.rt);
  ASSERT_GT(nt, 0u);
  std::vector<float> xyz(3 * n);
  std::vector<uint32_t> tri(3 * nt), order(n);
  ASSERT_EQ(prt_runtime_get_positions(h.rt, xyz.data(), n), PRT_RUNTIME_OK);
  ASSERT_EQ(prt_runtime_get_triangles(h.rt, tri.data(), nt), PRT_RUNTIME_OK);
  for (uint32_t v : tri) ASSERT_LT(v, n);
  ASSERT_EQ(prt_runtime_get_sample_order(h.rt, order.data(), n), PRT_RUNTIME_OK);
  std::vector<int> seen(n, 0);
  for (uint32_t v : order) ++seen[v];
  for (int k : seen) ASSERT_EQ(k, 1);
  std::vector<float> map(3 * 32 * 16, 1.0f), a(3 * n), b(3 * n);
  ASSERT_EQ(prt_runtime_set_environment_latlong(h.rt, map.data(), 32, 16), PRT_RUNTIME_OK);
  ASSERT_EQ(prt_runtime_relight(h.rt, 0, a.data(), n), PRT_RUNTIME_OK);
  ASSERT_EQ(prt_runtime_set_sample_order(h.rt, PRT_RUNTIME_ORDER_RUNTIME), PRT_RUNTIME_OK);
  ASSERT_EQ(prt_runtime_relight(h.rt, 0, b.data(), n), PRT_RUNTIME_OK);
  for (std::size_t p = 0; p < n; ++p)
    for (int c = 0; c < 3; ++c) ASSERT_EQ(b[3 * p + c], a[3 * order[p] + c]);
  float eye[3], fov = 0;
  int w = 0, hgt = 0;
  ASSERT_EQ(prt_runtime_get_camera(h.rt, eye, nullptr, nullptr, &fov, &w, &hgt), PRT_RUNTIME_OK);
  EXPECT_GT(fov, 0.0f);
  EXPECT_GT(w, 0);
  EXPECT_GT(hgt, 0);
}

// A glossy vertex pack (docs/glossy-transport.md; the committed seed glossy_terms.prtpack is
// tests/data/glossy_vertex_tiny.toml farmed and packed, 3 BRDF terms): the C API relights it for
// its eye and equals the session's Shade for that eye; a new eye changes the box's colours and
// not the diffuse ground's; ranges are refused with a state error.
TEST(RuntimeGlossyTerms, TheEyeMovesTheGlossyVerticesOnly) {
  using namespace prt;
  const auto message = [] { return std::string(prt_runtime_last_error()); };
  const std::string pack = kCorpus + "/glossy_terms.prtpack";
  Handle h(pack);
  ASSERT_NE(h.rt, nullptr) << message();
  EXPECT_EQ(prt_runtime_brdf_terms(h.rt), 3u);
  EXPECT_EQ(prt_runtime_is_glossy(h.rt), 0);
  const std::size_t n = prt_runtime_sample_count(h.rt);
  ASSERT_EQ(n, 72u);  // the box's 8 vertices, then the 8×8 ground
  std::vector<float> map(3 * 32 * 16, 0.5f), a(3 * n), b(3 * n);
  for (std::size_t i = 0; i < 40; ++i) map[3 * (i * 11 % 512)] = 8.0f;  // a few bright texels
  ASSERT_EQ(prt_runtime_set_environment_latlong(h.rt, map.data(), 32, 16), PRT_RUNTIME_OK);
  float eye[3];
  ASSERT_EQ(prt_runtime_get_eye(h.rt, eye), PRT_RUNTIME_OK);
  ASSERT_EQ(prt_runtime_relight(h.rt, 0, a.data(), n), PRT_RUNTIME_OK) << message();
  // The session, for the same eye, in the pack's order.
  const auto session = RelightSession::Open(pack);
  EnvironmentImage env;  // the interleaved map back into channels (Interleaved's inverse)
  env.width = 32;
  env.height = 16;
  for (int c = 0; c < 3; ++c)
    for (std::size_t i = 0; i < 512; ++i) env.Channel(c).push_back(map[3 * i + c]);
  const SampleRadiance r =
      session->RelightExact(ProjectLighting(ResampleToCubemap(env, session->cubemap_n())));
  const std::vector<float> ref =
      session->ToPackOrder(session->Shade(r, Vec3{eye[0], eye[1], eye[2]}));
  for (std::size_t k = 0; k < 3 * n; ++k) ASSERT_NEAR(a[k], ref[k], 1e-5f * (1 + std::abs(ref[k])));
  const float other[3] = {2.5f, 1.0f, -1.0f};
  ASSERT_EQ(prt_runtime_set_eye(h.rt, other), PRT_RUNTIME_OK);
  ASSERT_EQ(prt_runtime_relight(h.rt, 0, b.data(), n), PRT_RUNTIME_OK);
  int box_moved = 0;
  for (std::size_t v = 0; v < n; ++v)
    for (int c = 0; c < 3; ++c) {
      if (v >= 8) {
        ASSERT_EQ(a[3 * v + c], b[3 * v + c]) << v;
      }
      box_moved += v < 8 && std::abs(a[3 * v + c] - b[3 * v + c]) > 1e-6f ? 1 : 0;
    }
  EXPECT_GT(box_moved, 0);
  // Reshade: the last frame's terms for a new eye, without relighting, equal a relight there.
  std::vector<float> c(3 * n), d(3 * n);
  ASSERT_EQ(prt_runtime_set_eye(h.rt, eye), PRT_RUNTIME_OK);
  ASSERT_EQ(prt_runtime_reshade(h.rt, c.data(), n), PRT_RUNTIME_OK) << message();
  for (std::size_t k = 0; k < 3 * n; ++k) ASSERT_EQ(c[k], a[k]) << k;
  ASSERT_EQ(prt_runtime_set_eye(h.rt, other), PRT_RUNTIME_OK);
  ASSERT_EQ(prt_runtime_reshade(h.rt, d.data(), n), PRT_RUNTIME_OK);
  for (std::size_t k = 0; k < 3 * n; ++k) ASSERT_EQ(d[k], b[k]) << k;
  Handle diffuse(Pack("adaptive4d"));
  ASSERT_NE(diffuse.rt, nullptr);
  EXPECT_EQ(prt_runtime_brdf_terms(diffuse.rt), 1u);
  std::vector<float> e(3 * prt_runtime_sample_count(diffuse.rt));
  EXPECT_EQ(prt_runtime_reshade(diffuse.rt, e.data(), e.size() / 3), PRT_RUNTIME_ERROR_STATE);
  EXPECT_EQ(prt_runtime_prepare(h.rt, 100), PRT_RUNTIME_ERROR_STATE);
  EXPECT_NE(message().find("glossy vertex pack"), std::string::npos) << message();
}

// An image pack's background pixels: the ones its pixel_mesh marks, radiance 0 under any map;
// a vertex pack and a wrong size are argument errors.
TEST(RuntimeGeometry, ImageBackground) {
  Handle h(Pack("image"));
  ASSERT_NE(h.rt, nullptr) << prt_runtime_last_error();
  ASSERT_EQ(prt_runtime_is_image(h.rt), 1);
  const std::size_t n = prt_runtime_sample_count(h.rt);
  std::vector<uint8_t> bg(n, 7);
  ASSERT_EQ(prt_runtime_get_image_background(h.rt, bg.data(), n), PRT_RUNTIME_OK);
  const int w = 24;  // Pack("image"): rows y < 3 see the environment
  for (std::size_t p = 0; p < n; ++p) ASSERT_EQ(bg[p], p / w < 3 ? 1 : 0) << p;
  std::vector<float> map(3 * 32 * 16, 1.0f), rgb(3 * n);
  ASSERT_EQ(prt_runtime_set_environment_latlong(h.rt, map.data(), 32, 16), PRT_RUNTIME_OK);
  ASSERT_EQ(prt_runtime_relight(h.rt, 0, rgb.data(), n), PRT_RUNTIME_OK);
  for (std::size_t p = 0; p < n; ++p) {
    if (bg[p] == 1) {
      for (int c = 0; c < 3; ++c) EXPECT_EQ(rgb[3 * p + c], 0.0f);
    }
  }
  EXPECT_EQ(prt_runtime_get_image_background(h.rt, bg.data(), n + 1), PRT_RUNTIME_ERROR_ARGUMENT);
  EXPECT_EQ(prt_runtime_get_image_background(h.rt, nullptr, n), PRT_RUNTIME_ERROR_ARGUMENT);
  Handle v(Pack("adaptive4d"));
  const std::size_t nv = prt_runtime_sample_count(v.rt);
  std::vector<uint8_t> vb(nv);
  EXPECT_EQ(prt_runtime_get_image_background(v.rt, vb.data(), nv), PRT_RUNTIME_ERROR_ARGUMENT);
  EXPECT_NE(std::string(prt_runtime_last_error()).find("vertex pack"), std::string::npos);
}

// A supersampled image pack (docs/image-relighting.md, "Supersampling"): each pixel's coverage,
// and its radiance weighed by its own weight (the half-covered row at half the unsupersampled
// pack's radiance, the rest equal).
TEST(RuntimeGeometry, SupersampledImageCoverageAndWeights) {
  Handle a(Pack("image")), b(Pack("image-ss"));
  ASSERT_NE(b.rt, nullptr) << prt_runtime_last_error();
  const std::size_t n = prt_runtime_sample_count(b.rt);
  ASSERT_EQ(prt_runtime_sample_count(a.rt), n);
  std::vector<float> ca(n, 7.f), cb(n, 7.f);
  ASSERT_EQ(prt_runtime_get_image_coverage(a.rt, ca.data(), n), PRT_RUNTIME_OK);
  ASSERT_EQ(prt_runtime_get_image_coverage(b.rt, cb.data(), n), PRT_RUNTIME_OK);
  const std::size_t w = 24;
  for (std::size_t p = 0; p < n; ++p) {
    EXPECT_EQ(ca[p], p / w < 3 ? 0.f : 1.f) << p;
    EXPECT_EQ(cb[p], p / w < 3 ? 0.f : (p / w == 3 ? 0.5f : 1.f)) << p;
  }
  std::vector<float> map(3 * 32 * 16, 1.0f), ra(3 * n), rb(3 * n);
  for (prt_runtime* rt : {a.rt, b.rt}) {
    ASSERT_EQ(prt_runtime_set_environment_latlong(rt, map.data(), 32, 16), PRT_RUNTIME_OK);
  }
  ASSERT_EQ(prt_runtime_relight(a.rt, 0, ra.data(), n), PRT_RUNTIME_OK);
  ASSERT_EQ(prt_runtime_relight(b.rt, 0, rb.data(), n), PRT_RUNTIME_OK);
  for (std::size_t p = 3 * w; p < n; ++p)
    for (int c = 0; c < 3; ++c)
      EXPECT_NEAR(rb[3 * p + c], (p / w == 3 ? 0.5f : 1.f) * ra[3 * p + c],
                  1e-6f + 1e-5f * std::abs(ra[3 * p + c]))
          << p;
  EXPECT_EQ(prt_runtime_get_image_coverage(b.rt, cb.data(), n + 1), PRT_RUNTIME_ERROR_ARGUMENT);
  EXPECT_EQ(prt_runtime_get_image_coverage(b.rt, nullptr, n), PRT_RUNTIME_ERROR_ARGUMENT);
}

// A glossy pack through the C API: what it holds, prt-view's radiance towards the pack's camera
// and towards an orbited eye (terms and the lighting mode ignored), the glossy box's radiance
// following the eye while the Lambert ground's does not.
TEST(RuntimeGlossy, EqualsPrtViewAndFollowsTheEye) {
  if (!fs::exists(kEnv)) GTEST_SKIP() << kEnv << " missing (scripts/install-deps.sh)";
  const std::string pack = GlossyPack(32);
  Handle h(pack);
  ASSERT_NE(h.rt, nullptr) << prt_runtime_last_error();
  EXPECT_EQ(prt_runtime_is_glossy(h.rt), 1);
  EXPECT_EQ(prt_runtime_is_image(h.rt), 0);
  EXPECT_EQ(prt_runtime_transport_channels(h.rt), 0u);
  EXPECT_EQ(prt_runtime_cubemap_size(h.rt), 32u);
  const std::size_t n = prt_runtime_sample_count(h.rt);
  ASSERT_EQ(n, kGlossyBoxVertices + 64);
  float eye[3], target[3];
  ASSERT_EQ(prt_runtime_get_camera(h.rt, eye, target, nullptr, nullptr, nullptr, nullptr),
            PRT_RUNTIME_OK);
  EXPECT_FLOAT_EQ(eye[2], 3.0f);
  float current[3];
  ASSERT_EQ(prt_runtime_get_eye(h.rt, current), PRT_RUNTIME_OK);
  for (int k = 0; k < 3; ++k) EXPECT_EQ(current[k], eye[k]);

  const prt::EnvironmentImage env = prt::ReadEnvironment(kEnv);
  const std::vector<float> map = Interleaved(env);
  ASSERT_EQ(prt_runtime_set_environment_latlong(h.rt, map.data(), env.width, env.height),
            PRT_RUNTIME_OK)
      << prt_runtime_last_error();
  std::vector<float> rgb(3 * n), again(3 * n);
  const std::vector<float> view = PrtViewRadiance(pack, "", "glossy");
  ASSERT_EQ(view.size(), 3 * n) << "prt-view failed on " << pack;
  ASSERT_EQ(prt_runtime_relight(h.rt, 0, rgb.data(), n), PRT_RUNTIME_OK)
      << prt_runtime_last_error();
  EXPECT_LE(RelativeMaxError(rgb, view), 1e-5);
  double sum = 0;
  for (float v : rgb) sum += v;
  EXPECT_GT(sum, 0.0) << "a lit pack relit to black";
  // Terms and the lighting mode do not apply: the same frame.
  ASSERT_EQ(prt_runtime_set_lighting_mode(h.rt, PRT_RUNTIME_LIGHTING_NWA), PRT_RUNTIME_OK);
  ASSERT_EQ(prt_runtime_relight(h.rt, 40, again.data(), n), PRT_RUNTIME_OK);
  EXPECT_EQ(again, rgb);

  // An orbited eye: prt-view --camera with the same eye and target.
  const double a = 0.8;
  const float orbit[3] = {static_cast<float>(eye[0] * std::cos(a) + eye[2] * std::sin(a)), eye[1],
                          static_cast<float>(-eye[0] * std::sin(a) + eye[2] * std::cos(a))};
  ASSERT_EQ(prt_runtime_set_eye(h.rt, orbit), PRT_RUNTIME_OK);
  ASSERT_EQ(prt_runtime_relight(h.rt, 0, again.data(), n), PRT_RUNTIME_OK);
  char spec[256];
  std::snprintf(spec, sizeof spec, "--camera %.9g,%.9g,%.9g,%.9g,%.9g,%.9g", orbit[0], orbit[1],
                orbit[2], target[0], target[1], target[2]);
  const std::vector<float> view_orbit = PrtViewRadiance(pack, spec, "glossy_orbit");
  ASSERT_EQ(view_orbit.size(), 3 * n);
  EXPECT_LE(RelativeMaxError(again, view_orbit), 1e-5);
  // The glossy box's vertices change with the eye, the Lambert ground's do not.
  double box_change = 0, box_scale = 0;
  for (std::size_t i = 0; i < 3 * kGlossyBoxVertices; ++i) {
    box_change = std::max(box_change, std::abs(double(again[i]) - rgb[i]));
    box_scale = std::max(box_scale, std::abs(double(rgb[i])));
  }
  EXPECT_GT(box_change, 1e-2 * box_scale) << "an orbit step should move the box's highlights";
  for (std::size_t i = 3 * kGlossyBoxVertices; i < 3 * n; ++i)
    ASSERT_NEAR(again[i], rgb[i], 1e-6f * std::abs(rgb[i])) << "Lambert sample " << i / 3;
}

// A glossy pack's materials: read from its metadata, editable between frames (a box made Lambert
// no longer follows the eye; a sharper lobe changes the frame), every bad field refused.
TEST(RuntimeGlossy, MaterialsAreEditable) {
  const auto message = [] { return std::string(prt_runtime_last_error()); };
  Handle h(GlossyPack(32));
  ASSERT_NE(h.rt, nullptr) << message();
  ASSERT_EQ(prt_runtime_material_count(h.rt), 2u);
  prt_runtime_material box{}, ground{};
  ASSERT_EQ(prt_runtime_get_material(h.rt, 0, &box), PRT_RUNTIME_OK) << message();
  ASSERT_EQ(prt_runtime_get_material(h.rt, 1, &ground), PRT_RUNTIME_OK);
  EXPECT_EQ(box.brdf, PRT_RUNTIME_BRDF_ASHIKHMIN_SHIRLEY);
  EXPECT_DOUBLE_EQ(box.exponent, 30.0);
  EXPECT_DOUBLE_EQ(box.exponent_v, 150.0);
  EXPECT_FLOAT_EQ(box.specular[1], 0.5f);
  EXPECT_EQ(ground.brdf, PRT_RUNTIME_BRDF_LAMBERT);

  const std::size_t n = prt_runtime_sample_count(h.rt);
  std::vector<float> map(3 * 32 * 16, 1.0f), a(3 * n), b(3 * n), c(3 * n);
  for (std::size_t i = 0; i < 32 * 8; ++i) map[3 * i] = map[3 * i + 1] = 4.0f;  // bright sky
  ASSERT_EQ(prt_runtime_set_environment_latlong(h.rt, map.data(), 32, 16), PRT_RUNTIME_OK);
  const float e1[3] = {3, 1, 0}, e2[3] = {0, 2, 3};
  const auto box_change = [&](const std::vector<float>& x, const std::vector<float>& y) {
    double d = 0;
    for (std::size_t i = 0; i < 3 * kGlossyBoxVertices; ++i)
      d = std::max(d, std::abs(double(x[i]) - y[i]) / std::max(1e-12, std::abs(double(y[i]))));
    return d;
  };
  ASSERT_EQ(prt_runtime_set_eye(h.rt, e1), PRT_RUNTIME_OK);
  ASSERT_EQ(prt_runtime_relight(h.rt, 0, a.data(), n), PRT_RUNTIME_OK);
  prt_runtime_material sharp = box;
  sharp.exponent = sharp.exponent_v = 400;
  ASSERT_EQ(prt_runtime_set_material(h.rt, 0, &sharp), PRT_RUNTIME_OK) << message();
  ASSERT_EQ(prt_runtime_relight(h.rt, 0, b.data(), n), PRT_RUNTIME_OK);
  EXPECT_GT(box_change(b, a), 1e-3) << "a sharper lobe should change the box";
  prt_runtime_material lambert = box;
  lambert.brdf = PRT_RUNTIME_BRDF_LAMBERT;
  ASSERT_EQ(prt_runtime_set_material(h.rt, 0, &lambert), PRT_RUNTIME_OK);
  ASSERT_EQ(prt_runtime_relight(h.rt, 0, b.data(), n), PRT_RUNTIME_OK);
  ASSERT_EQ(prt_runtime_set_eye(h.rt, e2), PRT_RUNTIME_OK);
  ASSERT_EQ(prt_runtime_relight(h.rt, 0, c.data(), n), PRT_RUNTIME_OK);
  EXPECT_LE(box_change(c, b), 1e-6) << "a Lambert box should not follow the eye";

  // Refused: a bad index, model, colour or exponent, NULL; the old material stays.
  prt_runtime_material bad = box;
  EXPECT_EQ(prt_runtime_set_material(h.rt, 2, &box), PRT_RUNTIME_ERROR_ARGUMENT);
  EXPECT_NE(message().find("mesh 2 of 2"), std::string::npos) << message();
  bad.brdf = 9;
  EXPECT_EQ(prt_runtime_set_material(h.rt, 0, &bad), PRT_RUNTIME_ERROR_ARGUMENT);
  bad = box;
  bad.specular[2] = 1.5f;
  EXPECT_EQ(prt_runtime_set_material(h.rt, 0, &bad), PRT_RUNTIME_ERROR_ARGUMENT);
  EXPECT_NE(message().find("specular[2]"), std::string::npos) << message();
  bad = box;
  bad.diffuse[0] = std::numeric_limits<float>::quiet_NaN();
  EXPECT_EQ(prt_runtime_set_material(h.rt, 0, &bad), PRT_RUNTIME_ERROR_ARGUMENT);
  bad = box;
  bad.exponent_v = 0;
  EXPECT_EQ(prt_runtime_set_material(h.rt, 0, &bad), PRT_RUNTIME_ERROR_ARGUMENT);
  EXPECT_EQ(prt_runtime_set_material(h.rt, 0, nullptr), PRT_RUNTIME_ERROR_ARGUMENT);
  EXPECT_EQ(prt_runtime_get_material(h.rt, 0, nullptr), PRT_RUNTIME_ERROR_ARGUMENT);
  prt_runtime_material now{};
  ASSERT_EQ(prt_runtime_get_material(h.rt, 0, &now), PRT_RUNTIME_OK);
  EXPECT_EQ(now.brdf, PRT_RUNTIME_BRDF_LAMBERT);
  // A vertex pack has no editable materials.
  Handle v(Pack("adaptive4d"));
  EXPECT_EQ(prt_runtime_material_count(v.rt), 0u);
  EXPECT_EQ(prt_runtime_get_material(v.rt, 0, &now), PRT_RUNTIME_ERROR_ARGUMENT);
  EXPECT_NE(message().find("not a glossy pack"), std::string::npos) << message();
}

// A glossy frame split into ranges (3 threads at once) writes what the whole frame writes, under
// a rotated map, in preview and at an orbited eye; the runtime's order is the pack's.
TEST(RuntimeGlossy, RangesEqualTheWholeFrame) {
  const prt::EnvironmentImage env = prt::ReadEnvironment(kEnv);
  const std::vector<float> map = Interleaved(env);
  Handle h(GlossyPack(32));
  ASSERT_NE(h.rt, nullptr) << prt_runtime_last_error();
  const std::size_t n = prt_runtime_sample_count(h.rt);
  std::vector<uint32_t> order(n);
  ASSERT_EQ(prt_runtime_get_sample_order(h.rt, order.data(), n), PRT_RUNTIME_OK);
  for (std::size_t i = 0; i < n; ++i) ASSERT_EQ(order[i], i);
  ASSERT_EQ(prt_runtime_set_environment_latlong(h.rt, map.data(), env.width, env.height),
            PRT_RUNTIME_OK);
  std::vector<float> whole(3 * n), split(3 * n), first(3 * n);
  for (int frame = 0; frame < 3; ++frame) {
    ASSERT_EQ(prt_runtime_set_preview(h.rt, frame == 1 ? 1 : 0), PRT_RUNTIME_OK);
    ASSERT_EQ(prt_runtime_set_rotation_y(h.rt, 0.7 * frame), PRT_RUNTIME_OK);
    const float e[3] = {3.0f * static_cast<float>(std::sin(0.5 * frame)), 1.5f,
                        3.0f * static_cast<float>(std::cos(0.5 * frame))};
    ASSERT_EQ(prt_runtime_set_eye(h.rt, e), PRT_RUNTIME_OK);
    ASSERT_EQ(prt_runtime_set_sample_order(
                  h.rt, frame == 2 ? PRT_RUNTIME_ORDER_RUNTIME : PRT_RUNTIME_ORDER_PACK),
              PRT_RUNTIME_OK);
    ASSERT_EQ(prt_runtime_relight(h.rt, 0, whole.data(), n), PRT_RUNTIME_OK);
    if (frame == 0) first = whole;
    std::fill(split.begin(), split.end(), -1.0f);
    ASSERT_EQ(prt_runtime_prepare(h.rt, 30), PRT_RUNTIME_OK) << prt_runtime_last_error();
    std::vector<std::thread> threads;
    std::array<int, 3> status{};
    for (std::size_t r = 0; r < 3; ++r)
      threads.emplace_back([&, r] {
        const std::size_t lo = n * r / 3, hi = n * (r + 1) / 3;
        status[r] = prt_runtime_relight_range(h.rt, lo, hi - lo, split.data(), n);
      });
    for (std::thread& t : threads) t.join();
    for (int s : status) ASSERT_EQ(s, PRT_RUNTIME_OK) << prt_runtime_last_error();
    EXPECT_LE(RelativeMaxError(split, whole), 1e-6) << "frame " << frame;
  }
  EXPECT_GT(RelativeMaxError(whole, first), 1e-3) << "rotation and eye should change the frame";
}

// A vertex pack takes an eye too (a viewer orbits every pack the same way) and its radiance does
// not depend on it.
TEST(RuntimeGlossy, AnEyeDoesNotChangeADiffusePack) {
  Handle h(Pack("adaptive4d"));
  ASSERT_NE(h.rt, nullptr);
  EXPECT_EQ(prt_runtime_is_glossy(h.rt), 0);
  const std::size_t n = prt_runtime_sample_count(h.rt);
  std::vector<float> map(3 * 32 * 16, 1.0f), a(3 * n), b(3 * n);
  ASSERT_EQ(prt_runtime_set_environment_latlong(h.rt, map.data(), 32, 16), PRT_RUNTIME_OK);
  ASSERT_EQ(prt_runtime_relight(h.rt, 0, a.data(), n), PRT_RUNTIME_OK);
  const float e[3] = {-3, 1, 0.5f};
  ASSERT_EQ(prt_runtime_set_eye(h.rt, e), PRT_RUNTIME_OK);
  ASSERT_EQ(prt_runtime_relight(h.rt, 0, b.data(), n), PRT_RUNTIME_OK);
  EXPECT_EQ(a, b);
}

// A glossy pack's misuse: a status and a message, the handle usable afterwards; its geometry in
// the pack's order; the fuzz seed (GlossyPack(16)) opens and relights.
TEST(RuntimeGlossy, MisuseGeometryAndTheFuzzSeed) {
  const auto message = [] { return std::string(prt_runtime_last_error()); };
  Handle h(GlossyPack(32));
  ASSERT_NE(h.rt, nullptr) << message();
  const std::size_t n = prt_runtime_sample_count(h.rt);
  std::vector<float> rgb(3 * n);
  EXPECT_EQ(prt_runtime_relight(h.rt, 0, rgb.data(), n), PRT_RUNTIME_ERROR_STATE);
  EXPECT_NE(message().find("environment"), std::string::npos) << message();
  EXPECT_EQ(prt_runtime_prepare(h.rt, 0), PRT_RUNTIME_ERROR_STATE);
  EXPECT_EQ(prt_runtime_relight_range(h.rt, 0, n, rgb.data(), n), PRT_RUNTIME_ERROR_STATE);
  const float nan3[3] = {0, std::numeric_limits<float>::quiet_NaN(), 0};
  EXPECT_EQ(prt_runtime_set_eye(h.rt, nan3), PRT_RUNTIME_ERROR_ARGUMENT);
  EXPECT_NE(message().find("eye[1]"), std::string::npos) << message();
  EXPECT_EQ(prt_runtime_set_eye(h.rt, nullptr), PRT_RUNTIME_ERROR_ARGUMENT);
  EXPECT_EQ(prt_runtime_set_eye(nullptr, nan3), PRT_RUNTIME_ERROR_ARGUMENT);
  EXPECT_EQ(prt_runtime_get_eye(h.rt, nullptr), PRT_RUNTIME_ERROR_ARGUMENT);
  EXPECT_EQ(prt_runtime_is_glossy(nullptr), 0);
  std::vector<uint8_t> bg(n);
  EXPECT_EQ(prt_runtime_get_image_background(h.rt, bg.data(), n), PRT_RUNTIME_ERROR_ARGUMENT);
  std::vector<float> map(3 * 32 * 16, 0.5f);
  map[3 * (2 * 32 + 3)] = std::numeric_limits<float>::infinity();
  EXPECT_EQ(prt_runtime_set_environment_latlong(h.rt, map.data(), 32, 16), PRT_RUNTIME_ERROR_INPUT);
  EXPECT_EQ(prt_runtime_relight(h.rt, 0, rgb.data(), n), PRT_RUNTIME_ERROR_STATE)
      << "a refused map must not count as an environment";
  map[3 * (2 * 32 + 3)] = 0.5f;
  ASSERT_EQ(prt_runtime_set_environment_latlong(h.rt, map.data(), 32, 16), PRT_RUNTIME_OK);
  EXPECT_EQ(prt_runtime_relight(h.rt, 0, rgb.data(), n - 1), PRT_RUNTIME_ERROR_ARGUMENT);
  EXPECT_EQ(prt_runtime_relight_range(h.rt, 0, n, rgb.data(), n), PRT_RUNTIME_ERROR_STATE)
      << "a range before prepare";
  ASSERT_EQ(prt_runtime_prepare(h.rt, 0), PRT_RUNTIME_OK);
  EXPECT_EQ(prt_runtime_relight_range(h.rt, n - 2, 5, rgb.data(), n), PRT_RUNTIME_ERROR_ARGUMENT);
  const float mirror[9] = {-1, 0, 0, 0, 1, 0, 0, 0, 1};
  EXPECT_EQ(prt_runtime_set_rotation(h.rt, mirror), PRT_RUNTIME_ERROR_ARGUMENT);
  // A map whose block sums overflow float: a numeric error, never Inf in an OK frame.
  std::vector<float> hot(3 * 32 * 16, 3e38f);
  if (prt_runtime_set_environment_latlong(h.rt, hot.data(), 32, 16) == PRT_RUNTIME_OK) {
    const int s = prt_runtime_relight(h.rt, 0, rgb.data(), n);
    if (s == PRT_RUNTIME_OK) {
      for (float v : rgb) ASSERT_TRUE(std::isfinite(v));
    } else {
      EXPECT_EQ(s, PRT_RUNTIME_ERROR_NUMERIC) << message();
    }
  }
  ASSERT_EQ(prt_runtime_set_environment_latlong(h.rt, map.data(), 32, 16), PRT_RUNTIME_OK);
  ASSERT_EQ(prt_runtime_relight(h.rt, 0, rgb.data(), n), PRT_RUNTIME_OK) << message();
  for (float v : rgb) ASSERT_TRUE(std::isfinite(v) && v >= 0);
  EXPECT_GT(prt_runtime_memory_bytes(h.rt), 0u);

  // Geometry: the pack's meshes in order (the box's 8 vertices first), triangles into them.
  const std::size_t nt = prt_runtime_triangle_count(h.rt);
  ASSERT_GT(nt, 0u);
  std::vector<float> xyz(3 * n);
  std::vector<uint32_t> tri(3 * nt);
  ASSERT_EQ(prt_runtime_get_positions(h.rt, xyz.data(), n), PRT_RUNTIME_OK);
  ASSERT_EQ(prt_runtime_get_triangles(h.rt, tri.data(), nt), PRT_RUNTIME_OK);
  for (uint32_t v : tri) ASSERT_LT(v, n);
  for (std::size_t v = kGlossyBoxVertices; v < n; ++v) EXPECT_EQ(xyz[3 * v + 1], 0.0f) << v;
  EXPECT_EQ(prt_runtime_get_positions(h.rt, xyz.data(), n + 1), PRT_RUNTIME_ERROR_ARGUMENT);
  // The eye on a vertex (no view direction there): finite radiance or an error, never NaN.
  ASSERT_EQ(prt_runtime_set_eye(h.rt, &xyz[3 * 5]), PRT_RUNTIME_OK);
  if (prt_runtime_relight(h.rt, 0, rgb.data(), n) == PRT_RUNTIME_OK) {
    for (float v : rgb) ASSERT_TRUE(std::isfinite(v));
  } else {
    std::printf("eye on a vertex: %s\n", message().c_str());
  }

  // The committed fuzz seed is GlossyPack(16); PRT_WRITE_RUNTIME_FUZZ_SEED=DIR writes it again.
  const std::string seed = GlossyPack(16);
  if (const char* dir = std::getenv("PRT_WRITE_RUNTIME_FUZZ_SEED"))
    fs::copy_file(seed, fs::path(dir) / "glossy.prtpack", fs::copy_options::overwrite_existing);
  const std::string committed = std::string(PRT_SOURCE_DIR) + "/runtime/fuzz_corpus/glossy.prtpack";
  Handle f(committed);
  ASSERT_NE(f.rt, nullptr) << message();
  EXPECT_EQ(prt_runtime_is_glossy(f.rt), 1);
  EXPECT_EQ(prt_runtime_cubemap_size(f.rt), 16u);
  const std::size_t nf = prt_runtime_sample_count(f.rt);
  std::vector<float> out(3 * nf);
  ASSERT_EQ(prt_runtime_set_environment_latlong(f.rt, map.data(), 32, 16), PRT_RUNTIME_OK);
  EXPECT_EQ(prt_runtime_relight(f.rt, 0, out.data(), nf), PRT_RUNTIME_OK) << message();
}

}  // namespace
