// High dynamic range end to end (issue 27; docs/viewer.md, "High dynamic range"): a sky of
// radiance 1 with a sun 10⁶ and 10⁷ times brighter, and a half-float EXR whose sun sits at the
// half maximum 65504, through what prt-view does — resampling to the lighting cubemap
// (cubemap_resample.h), the Haar lighting (lighting.h), NWA and PBI (per_band_incremental.h), the
// pack's quantised transport relit by Eq. 8 in float (compressed_relight.h) and shading — against
// double-precision references B = albedo·T·L.
#include <ImfEnvmapAttribute.h>
#include <ImfHeader.h>
#include <ImfRgbaFile.h>
#include <ImfStandardAttributes.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <numbers>
#include <string>
#include <vector>

#include "formats/column_coding.h"
#include "packager/prtpack_reader.h"
#include "packager/prtpack_transport.h"
#include "runtime/lighting.h"
#include "runtime/per_band_incremental.h"
#include "viewer/tiny_scene_test_support.h"
#include "viewer/viewer_session.h"
#include "vocabulary/cubemap_resample.h"
#include "vocabulary/environment_io.h"
#include "vocabulary/envmap.h"

namespace prt {
namespace {

namespace fs = std::filesystem;

fs::path WorkDir() {
  const fs::path d = fs::path(::testing::TempDir()) / ("hdr_test_" + std::to_string(::getpid()));
  fs::create_directories(d);
  return d;
}

// The tiny scene at n = 32 (6,144 texels: the 2° sun is smaller than a texel, 2–3°), 16 rays per
// texel, traced once and packed three ways:
//  - kPack16: adaptive 4D, every coefficient at 16 bits (the tests' usual pack);
//  - kPack9: the same at 9 bits, the scene files' default depth (docs/scene-format.md);
//  - kPack2D: the 2D scheme at 16 bits: no column transform, so T̂ is exactly the dequantised
//    terms (doubles) and B = albedo·Σ T̂·L̂ has an exact double reference, which isolates the
//    relighter's float arithmetic (its weights and its accumulation X).
enum PackKind { kPack16 = 0, kPack9 = 1, kPack2D = 2 };

struct HdrPacks {
  testing::TinyScene scene;
  std::array<std::string, 3> pack;
  std::array<std::vector<float>, 2> pack_rows;  // kPack16/kPack9's T, texel basis, pack order
  CompressedTransport t2d;                      // kPack2D's columns
  std::vector<Rgb> albedo;                      // per sample, pack order
};

const HdrPacks& Packs() {
  static const HdrPacks p = [] {
    HdrPacks h;
    h.scene = testing::TraceTinyScene(32, 16);
    CompressionOptions o = testing::KeepAllCompression(16);
    h.pack[kPack16] =
        testing::PackTinyRows(h.scene, h.scene.rows, (WorkDir() / "hdr16.prtpack").string(), o);
    o.bits = 9;
    h.pack[kPack9] =
        testing::PackTinyRows(h.scene, h.scene.rows, (WorkDir() / "hdr9.prtpack").string(), o);
    o.bits = 16;
    o.scheme = CompressionScheme::k2D;
    h.pack[kPack2D] =
        testing::PackTinyRows(h.scene, h.scene.rows, (WorkDir() / "hdr2d.prtpack").string(), o);
    h.scene.pack = h.pack[kPack16];
    for (int k : {kPack16, kPack9})
      h.pack_rows[k] =
          DecompressTransport(pack::ReadCompressedTransport(pack::PackReader::OpenFile(h.pack[k])));
    h.t2d = pack::ReadCompressedTransport(pack::PackReader::OpenFile(h.pack[kPack2D]));
    for (const SceneMesh& m : h.scene.geometry.meshes)
      h.albedo.insert(h.albedo.end(), m.mesh.positions.size(), m.albedo);
    return h;
  }();
  return p;
}

// The sun: elevation 35°, azimuth 45° (towards +X+Z); the box's shadow falls on the ground's
// −X−Z corner.
Vec3 SunDirection() {
  const double el = 35 * std::numbers::pi / 180, az = 45 * std::numbers::pi / 180;
  return {std::sin(az) * std::cos(el), std::sin(el), std::cos(az) * std::cos(el)};
}

// A 1024×512 lat-long sky of radiance about 1 — a smooth gradient from 0.5 to 1.5, slightly
// blue, so that the lighting has detail at every wavelet level and NWA has something to choose
// — with a sun disc of angular radius 1° (the pixels whose centre lies within it, 0.35° apart)
// of radiance `sun` in every channel.
EnvironmentImage SunAndSky(float sun) {
  const int w = 1024, h = 512;
  EnvironmentImage e = EnvironmentImage::Zero(EnvmapLayout::kLatLong, w, h);
  const Vec3 s = SunDirection();
  const double cos_radius = std::cos(1.0 * std::numbers::pi / 180);
  const double tint[3] = {0.85, 0.95, 1.2};
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const Vec3 d = LatLongDirection(w, h, x, y);
      const bool in_sun = Dot(d, s) >= cos_radius;
      const double sky = 1.0 + 0.3 * d.y + 0.2 * d.x;
      for (int c = 0; c < 3; ++c)
        e.Channel(c)[e.Index(x, y)] = in_sun ? sun : static_cast<float>(tint[c] * sky);
    }
  return e;
}

// Writes an environment as RGBA half OpenEXR (the envmap attribute lat-long): what a file made
// with half channels holds, 65504 at most.
void WriteHalfExr(const EnvironmentImage& e, const std::string& path) {
  Imf::Header header(e.width, e.height);
  Imf::addEnvmap(header, Imf::ENVMAP_LATLONG);
  Imf::RgbaOutputFile file(path.c_str(), header, Imf::WRITE_RGBA);
  std::vector<Imf::Rgba> px(e.PixelCount());
  for (std::size_t i = 0; i < px.size(); ++i) px[i] = Imf::Rgba(e.r[i], e.g[i], e.b[i], 1.0f);
  file.setFrameBuffer(px.data(), 1, static_cast<std::size_t>(e.width));
  file.writePixels(e.height);
}

bool AllFinite(std::span<const float> v) {
  return std::all_of(v.begin(), v.end(), [](float x) { return std::isfinite(x); });
}

bool AllFinite(const SampleRadiance& r) {
  for (const auto& c : r.channel)
    for (double v : c)
      if (!std::isfinite(v)) return false;
  return true;
}

// B = albedo·T·L in double from texel-basis rows (pack order), interleaved RGB.
std::vector<double> Reference(const std::vector<float>& rows, const std::vector<Rgb>& albedo,
                              const CubemapRgb& cube) {
  const std::size_t m = cube.TexelCount(), ns = albedo.size();
  std::vector<double> b(3 * ns);
  for (std::size_t v = 0; v < ns; ++v)
    for (int c = 0; c < 3; ++c) {
      double sum = 0;
      for (std::size_t j = 0; j < m; ++j) sum += double(rows[v * m + j]) * cube.Channel(c)[j];
      b[3 * v + c] = albedo[v][c] * sum;
    }
  return b;
}

// The exact B = albedo·T̂·L̂ of a 2D-scheme pack in the session's order (the coefficient layout
// at depth 0, which is what a depth-0 column indexes): every stored term dequantised in double,
// L̂ in double, the sums in double.
std::vector<double> Reference2D(const CompressedTransport& t, const ViewerSession& s,
                                const WaveletLighting& l) {
  const std::size_t ns = t.header.sample_count;
  std::vector<uint8_t> levels(ns);
  ColumnScaleMap(t.header.domain, 0, levels.data());
  std::vector<double> b(3 * ns, 0.0);
  for (const CompressedColumn& c : t.columns) {
    EXPECT_EQ(c.depth, 0);
    for (std::size_t k = 0; k < c.index.size(); ++k) {
      const uint32_t i = c.index[k];
      const double v = DequantiseTerm(c.q[k], DitherOffset(t.header.dither_seed, c.column, i),
                                      c.scale, t.header.bits, levels[i]);
      for (int ch = 0; ch < 3; ++ch) b[3 * i + ch] += v * l.coefficient[ch][c.column];
    }
  }
  for (std::size_t p = 0; p < ns; ++p)
    for (int ch = 0; ch < 3; ++ch) b[3 * p + ch] *= s.albedo()[p][ch];
  return b;
}

// Relative RMS ‖b − ref‖/‖ref‖ over `samples` (all when empty), and the worst per-sample error
// relative to that sample's own radiance.
struct Error {
  double rms = 0, worst = 0;
};
Error Compare(std::span<const float> b, const std::vector<double>& ref,
              const std::vector<std::size_t>& samples = {}) {
  double num = 0, den = 0;
  Error e;
  const std::size_t ns = ref.size() / 3;
  for (std::size_t k = 0; k < (samples.empty() ? ns : samples.size()); ++k) {
    const std::size_t v = samples.empty() ? k : samples[k];
    for (int c = 0; c < 3; ++c) {
      const double d = b[3 * v + c] - ref[3 * v + c];
      num += d * d;
      den += ref[3 * v + c] * ref[3 * v + c];
      if (ref[3 * v + c] > 0) e.worst = std::max(e.worst, std::abs(d) / ref[3 * v + c]);
    }
  }
  e.rms = den > 0 ? std::sqrt(num / den) : 0;
  return e;
}

// The ground samples the sun does not reach: radiance below 1/10 of the brightest ground
// sample's (channel R of `ref`; `ground` lists them in its order). The sun is 1° wide: a
// vertex sees all of it or none.
std::vector<std::size_t> Shadowed(const std::vector<double>& ref,
                                  const std::vector<std::size_t>& ground) {
  double top = 0;
  for (std::size_t v : ground) top = std::max(top, ref[3 * v]);
  std::vector<std::size_t> out;
  for (std::size_t v : ground)
    if (ref[3 * v] > 0 && ref[3 * v] < 0.1 * top) out.push_back(v);
  return out;
}

struct Measured {
  double power_error = 0;  // the lighting cubemap's power against the image's (channel R)
  double sun_share = 0;    // the sun's share of the environment's power
  Error exact_vs_ref, exact_vs_ref_shadow;        // exact relighting vs the pack's own T
  Error exact_vs_traced, exact_vs_traced_shadow;  // … vs the traced, uncompressed T
  std::array<Error, 3> nwa, pbi;                  // N = kTerms[k], against exact relighting
  std::array<Error, 3> nwa_shadow;
  int pbi_still_frames = -1;  // PBI-64 frames from L̃ = 0 until it represents L exactly
  Error pbi_converged;        // PBI-64 then, against the pack's T in double
  std::size_t shadowed = 0;
};

constexpr std::array<std::size_t, 3> kTerms = {16, 64, 256};

Measured Measure(const EnvironmentImage& env, PackKind kind) {
  const HdrPacks& p = Packs();
  const int n = p.scene.n;
  Measured m;
  // Resampling: finite, power kept.
  const CubemapRgb cube = ResampleToCubemap(env, n);
  for (int c = 0; c < 3; ++c) EXPECT_TRUE(AllFinite(cube.Channel(c)));
  const double env_power = EnvironmentPower(env)[0];
  m.power_error = CubemapPower(cube)[0] / env_power - 1;
  EnvironmentImage sky_only = env;
  const float top = *std::max_element(env.r.begin(), env.r.end());
  for (float& v : sky_only.r)
    if (v == top) v = 0;
  m.sun_share = 1 - EnvironmentPower(sky_only)[0] / env_power;
  // The lighting: finite (in double).
  const WaveletLighting l = ProjectLighting(cube);
  for (int c = 0; c < 3; ++c)
    for (double v : l.coefficient[c]) EXPECT_TRUE(std::isfinite(v));

  // Exact relighting through the pack, as prt-view --exact does (the session's order).
  const auto s = ViewerSession::Open(p.pack[kind]);
  const std::vector<float> exact = s->Shade(s->RelightExact(l));
  EXPECT_TRUE(AllFinite(exact));
  // References in the session's order.
  const auto to_session = [&](const std::vector<double>& pack_order) {
    std::vector<double> out(pack_order.size());
    for (std::size_t q = 0; q < s->sample_count(); ++q)
      for (int c = 0; c < 3; ++c) out[3 * q + c] = pack_order[3 * s->pack_sample()[q] + c];
    return out;
  };
  const std::vector<double> traced = to_session(Reference(p.scene.rows, p.albedo, cube));
  const std::vector<double> ref = kind == kPack2D
                                      ? Reference2D(p.t2d, *s, l)
                                      : to_session(Reference(p.pack_rows[kind], p.albedo, cube));
  std::vector<std::size_t> ground;
  const std::size_t box = p.scene.geometry.meshes[0].mesh.positions.size();
  for (std::size_t q = 0; q < s->sample_count(); ++q)
    if (s->pack_sample()[q] >= box) ground.push_back(q);
  const std::vector<std::size_t> shadow = Shadowed(traced, ground);
  m.shadowed = shadow.size();
  m.exact_vs_ref = Compare(exact, ref);
  m.exact_vs_ref_shadow = Compare(exact, ref, shadow);
  m.exact_vs_traced = Compare(exact, traced);
  m.exact_vs_traced_shadow = Compare(exact, traced, shadow);

  // NWA and PBI (from L̃ = 0, one frame: prt-view --lighting nwa|pbi --terms N) against exact
  // relighting through the same T: the lighting approximation's error alone.
  const std::vector<double> exact_d(exact.begin(), exact.end());
  for (std::size_t k = 0; k < kTerms.size(); ++k) {
    const std::vector<float> nwa =
        s->Shade(RelightApproximate(s->transport(), l, LightingMode::kNwa, kTerms[k]));
    const std::vector<float> pbi =
        s->Shade(RelightApproximate(s->transport(), l, LightingMode::kPbi, kTerms[k]));
    EXPECT_TRUE(AllFinite(nwa));
    EXPECT_TRUE(AllFinite(pbi));
    m.nwa[k] = Compare(nwa, exact_d);
    m.nwa_shadow[k] = Compare(nwa, exact_d, shadow);
    m.pbi[k] = Compare(pbi, exact_d);
  }
  // PBI-64 under the still environment from L̃ = 0: once it represents L exactly its image,
  // accumulated frame by frame in double (per_band_incremental.h), is T·L to the same float
  // rounding as the exact relight: nothing is lost to a sun of 10⁷ next to a sky of 1.
  PerBandIncrementalRelighter pbi(s->transport(), n, 64);
  pbi.Clear();
  for (int f = 1; f <= 6144 / 64 + 1 && m.pbi_still_frames < 0; ++f) {
    const bool done = pbi.Update(l).exact;
    EXPECT_TRUE(AllFinite(pbi.Radiance()));
    if (done) m.pbi_still_frames = f;
  }
  m.pbi_converged = Compare(s->Shade(pbi.Radiance()), ref);
  return m;
}

void Print(const std::string& label, const Measured& m) {
  std::printf(
      "HDR %s: sun %.4f of the power, cubemap power %+.1e; exact vs the pack's T in double: rel "
      "RMS %.1e, shadow (%zu samples) %.1e, worst %.1e; vs traced T: %.1e, shadow %.1e, worst "
      "%.1e\n",
      label.c_str(), m.sun_share, m.power_error, m.exact_vs_ref.rms, m.shadowed,
      m.exact_vs_ref_shadow.rms, m.exact_vs_ref_shadow.worst, m.exact_vs_traced.rms,
      m.exact_vs_traced_shadow.rms, m.exact_vs_traced_shadow.worst);
  for (std::size_t k = 0; k < kTerms.size(); ++k)
    std::printf("  N = %3zu: NWA rel RMS %.2e (shadow %.2e), PBI %.2e\n", kTerms[k], m.nwa[k].rms,
                m.nwa_shadow[k].rms, m.pbi[k].rms);
  std::printf(
      "  PBI-64 from zero represents L exactly after %d still frames: rel RMS %.1e vs "
      "the pack's T in double\n",
      m.pbi_still_frames, m.pbi_converged.rms);
}

// The bounds, each about twice the figure measured when this was written (docs/viewer.md, "High
// dynamic range", has the measured table). Errors in the sun's shadow scale with the sun: the
// float rounding and the quantisation are both relative to the sun's wavelet terms, which cancel
// there.
struct Bounds {
  double sun;                      // the sun's radiance
  double nwa16_lo, nwa64, nwa256;  // NWA/PBI against exact: N = 16 is above nwa16_lo
  double exact_rms, shadow_float;  // float arithmetic: over all samples, worst shadowed sample
};

void ExpectBounds(const Measured& m, PackKind kind, const Bounds& b) {
  EXPECT_LT(std::abs(m.power_error), 1e-3);  // resampling: 3.0e-4 measured
  // Exact relighting against the pack's own T in double: the float arithmetic of the relighter
  // (its weights and its accumulation X), exactly so for kPack2D; for 4D the reference is T
  // decompressed to float texels, which carries rounding of the same size.
  EXPECT_LT(m.exact_vs_ref.rms, b.exact_rms);
  if (m.shadowed > 0) {
    EXPECT_LT(m.exact_vs_ref_shadow.worst, b.shadow_float);
  }
  // Against the traced T: the quantisation of the pack (every coefficient kept).
  EXPECT_LT(m.exact_vs_traced.rms, kind == kPack9 ? 5e-3 : 5e-5);  // 2.6e-3, 1.9e-5
  if (m.shadowed > 0) {  // 16 bits: 2.0e-9·sun; 9 bits: 2.5e-7·sun
    EXPECT_LT(m.exact_vs_traced_shadow.rms, (kind == kPack9 ? 5e-7 : 5e-9) * b.sun);
  }
  // NWA (and PBI from zero, the same terms) against exact relighting.
  EXPECT_GT(m.nwa[0].rms, b.nwa16_lo);
  EXPECT_LT(m.nwa[1].rms, b.nwa64);
  EXPECT_LT(m.nwa[2].rms, b.nwa256);
  for (std::size_t k = 0; k < kTerms.size(); ++k) {
    EXPECT_GT(m.nwa[k].rms, 0.0);  // 6,144 non-zero coefficients
    EXPECT_NEAR(m.pbi[k].rms, m.nwa[k].rms, 0.05 * m.nwa[k].rms + 2e-7);
  }
  // PBI-64 represents L exactly within ⌈6144/64⌉ still frames and is then as exact as the
  // exact relight.
  EXPECT_GT(m.pbi_still_frames, 0);
  EXPECT_LE(m.pbi_still_frames, 6144 / 64);
  EXPECT_LT(m.pbi_converged.rms, b.exact_rms);
}

TEST(HighDynamicRange, SunOfTenToTheSixAndSevenStaysFiniteAndAccurate) {
  const std::array<Bounds, 2> bounds = {
      Bounds{1e6, 0.9, 1.5e-4, 1.5e-5, 5e-6, 1e-4},  // measured 1.08, 7.1e-5, 6.9e-6
      Bounds{1e7, 0.9, 1.5e-5, 1e-6, 2e-6, 1e-3}};   // measured 1.09, 6.6e-6, 3.3e-7
  for (const Bounds& b : bounds) {
    const EnvironmentImage env = SunAndSky(static_cast<float>(b.sun));
    for (PackKind kind : {kPack16, kPack2D, kPack9}) {
      const Measured m = Measure(env, kind);
      const char* pack =
          kind == kPack16 ? "4D 16 bits" : (kind == kPack9 ? "4D 9 bits" : "2D 16 bits");
      Print((b.sun == 1e6 ? "sun 1e6, " : "sun 1e7, ") + std::string(pack), m);
      EXPECT_GT(m.sun_share, 0.98);  // 0.988 and 0.9988: the sky is a sliver of the light
      EXPECT_GT(m.shadowed, 3u);
      ExpectBounds(m, kind, b);
    }
  }
}

// A half-float EXR at the half maximum (65504 in the sun), read by the EXR reader, relit by the
// library and by prt-view end to end: finite, and the same bounds.
TEST(HighDynamicRange, HalfFloatMaximumThroughTheReaderAndPrtView) {
  const std::string path = (WorkDir() / "half_sun.exr").string();
  WriteHalfExr(SunAndSky(65504.0f), path);
  const EnvironmentImage env = ReadEnvironment(path);
  EXPECT_EQ(*std::max_element(env.r.begin(), env.r.end()), 65504.0f);
  const Bounds b{65504, 0.9, 2.5e-3, 2.5e-4, 5e-6, 2e-5};  // measured 0.96, 1.23e-3, 1.21e-4
  for (PackKind kind : {kPack16, kPack2D}) {
    const Measured m = Measure(env, kind);
    Print(std::string("half max 65504, ") + (kind == kPack16 ? "4D 16 bits" : "2D 16 bits"), m);
    EXPECT_GT(m.shadowed, 3u);
    ExpectBounds(m, kind, b);
  }
  // prt-view on the file: exit 0, the radiance it writes is finite and the library's.
  const std::string npy = (WorkDir() / "half_sun.npy").string();
  const std::string cmd = std::string("'") + PRT_VIEW_EXE + "' '" + Packs().pack[kPack16] +
                          "' --env '" + path + "' --exact --quiet --radiance-out '" + npy +
                          "' --out '" + (WorkDir() / "half_sun.png").string() + "'";
  ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd;
  std::ifstream f(npy, std::ios::binary);
  const std::vector<char> bytes((std::istreambuf_iterator<char>(f)),
                                std::istreambuf_iterator<char>());
  ASSERT_GT(bytes.size(), 10u);
  const std::size_t header =
      10 + (static_cast<unsigned char>(bytes[8]) | (static_cast<unsigned char>(bytes[9]) << 8));
  std::vector<float> radiance((bytes.size() - header) / 4);
  std::memcpy(radiance.data(), bytes.data() + header, 4 * radiance.size());
  EXPECT_TRUE(AllFinite(radiance));
  const auto s = ViewerSession::Open(Packs().pack[kPack16]);
  const std::vector<float> expected = s->ToPackOrder(
      s->Shade(s->RelightExact(ProjectLighting(ResampleToCubemap(env, Packs().scene.n)))));
  ASSERT_EQ(radiance.size(), expected.size());
  EXPECT_EQ(radiance, expected);
}

}  // namespace
}  // namespace prt
