// BI and PBI (Overbeck et al. 2006 §3, §5): exact convergence under static lighting within the
// ⌈non-zeros / N⌉ bound, the §5.2.2 reset test, no drift after 10,000 rotating frames, and PBI
// with 30 terms against NWA with 90 terms over a rotation of a real environment.
#include "runtime/per_band_incremental.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <numbers>
#include <random>

#include "runtime/lighting.h"
#include "runtime/relight.h"
#include "vocabulary/cubemap.h"
#include "vocabulary/cubemap_resample.h"
#include "vocabulary/environment_io.h"
#include "vocabulary/envmap.h"
#include "vocabulary/wavelets.h"

namespace prt {
namespace {

// A synthetic diffuse transport with sharp shadows: sample s has a normal on a Fibonacci sphere
// and a few occluding spherical caps above its horizon; row j = (1/π)·Ω_j·max(0, n·ω_j)·V(ω_j) at
// the texel centre, then Haar-transformed (the same basis as the lighting).
DenseTransport ShadowedTransport(int n, int samples, uint32_t seed) {
  const CubemapLayout layout(n);
  const std::size_t m = layout.texel_count();
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<float> rows(static_cast<std::size_t>(samples) * m);
  for (int s = 0; s < samples; ++s) {
    const double y = 1.0 - 2.0 * (s + 0.5) / samples;
    const double r = std::sqrt(std::max(0.0, 1.0 - y * y));
    const double phi = s * std::numbers::pi * (3.0 - std::sqrt(5.0));
    const Vec3 nrm{r * std::cos(phi), y, r * std::sin(phi)};
    std::vector<std::pair<Vec3, double>> caps;  // axis, cos(angular radius)
    for (int k = 0; k < 3; ++k) {
      Vec3 a{u(rng) - 0.5, u(rng) - 0.5, u(rng) - 0.5};
      a = Normalize(a + nrm * 0.6);
      caps.push_back({a, std::cos((10.0 + 25.0 * u(rng)) * std::numbers::pi / 180.0)});
    }
    float* row = rows.data() + static_cast<std::size_t>(s) * m;
    for (std::size_t j = 0; j < m; ++j) {
      const Vec3 d = layout.TexelCenter(j);
      bool visible = true;
      for (const auto& [axis, cos_r] : caps) visible = visible && Dot(axis, d) < cos_r;
      const double c = visible ? std::max(0.0, Dot(nrm, d)) : 0.0;
      row[j] = static_cast<float>(layout.TexelSolidAngle(j) * c / std::numbers::pi);
    }
    ForwardHaarCubemap(row, n, WaveletMaxDepth2D(WaveletFilter::kHaar, n, n));
  }
  return DenseTransport(rows, static_cast<std::size_t>(samples), m);
}

// Analytic sky with a small bright lobe, rotated by `angle` about +Y, at texel centres.
WaveletLighting AnalyticSky(int n, double angle) {
  static thread_local std::vector<Vec3> centres;  // texel centres, computed once per n
  if (centres.size() != static_cast<std::size_t>(6) * n * n) {
    const CubemapLayout layout(n);
    centres.resize(layout.texel_count());
    for (std::size_t j = 0; j < centres.size(); ++j) centres[j] = layout.TexelCenter(j);
  }
  CubemapRgb cube;
  cube.n = n;
  for (int c = 0; c < 3; ++c) cube.Channel(c).resize(centres.size());
  // L'(d) = L(R⁻¹d): rotate the texel direction by −angle about +Y (as RotateAboutY).
  const double cs = std::cos(angle), sn = std::sin(angle);
  const Vec3 sun = Normalize(Vec3{0.6, 0.35, 0.7});
  for (std::size_t j = 0; j < centres.size(); ++j) {
    const Vec3& e = centres[j];
    const Vec3 d{e.x * cs - e.z * sn, e.y, e.x * sn + e.z * cs};
    const double cos_sun = Dot(d, sun);
    const double lobe = cos_sun > 0.95 ? 40.0 * std::exp(300.0 * (cos_sun - 1.0)) : 0.0;
    const double sky = d.y > 0 ? 0.4 + 0.6 * d.y : 0.15;
    const double stripe = d.x > 0.2 && d.x < 0.3 ? 0.5 : 0.0;  // a sharp vertical band
    cube.r[j] = static_cast<float>(sky * 0.8 + lobe + stripe);
    cube.g[j] = static_cast<float>(sky * 0.9 + 0.9 * lobe + stripe);
    cube.b[j] = static_cast<float>(sky * 1.2 + 0.7 * lobe);
  }
  return ProjectLighting(cube);
}

const EnvironmentImage& Sunrise() {
  static const EnvironmentImage env = ReadEnvironment(PRT_DATA_DIR "/envmaps/sunrise.exr");
  return env;
}

// A fast stand-in for ResampleToCubemap(sunrise, n, angle) for the 120-frame sequence (the real
// resampler integrates exact overlaps and costs ~60 ms of CPU per n = 32 frame): sunrise averaged
// over 2×2 pixel blocks (0.7° cells, solid-angle weighted), each cell's radiance × solid angle
// splatted into the texel its rotated centre falls in, divided by the solid angle received.
// Power-preserving (the sun's power always lands somewhere); checked against ResampleToCubemap
// in FastRotationAgreesWithResampler.
struct SplatCell {
  Vec3 direction;
  double omega;
  float rgb[3];
};

const std::vector<SplatCell>& SunriseCells() {
  static const std::vector<SplatCell> cells = [] {
    const EnvironmentImage& env = Sunrise();
    const int f = 2, w = env.width / f, h = env.height / f;
    std::vector<SplatCell> out;
    out.reserve(static_cast<std::size_t>(w) * h);
    for (int y = 0; y < h; ++y) {
      for (int x = 0; x < w; ++x) {
        double sum[3] = {0, 0, 0}, omega = 0;
        Vec3 dir{0, 0, 0};
        for (int dy = 0; dy < f; ++dy) {
          for (int dx = 0; dx < f; ++dx) {
            const int sx = x * f + dx, sy = y * f + dy;
            const double o = PixelSolidAngle(env, sx, sy);
            omega += o;
            dir += LatLongDirection(env.width, env.height, sx, sy) * o;
            for (int c = 0; c < 3; ++c) sum[c] += o * env.Channel(c)[env.Index(sx, sy)];
          }
        }
        if (omega <= 0) continue;
        SplatCell cell{Normalize(dir), omega, {}};
        for (int c = 0; c < 3; ++c) cell.rgb[c] = static_cast<float>(sum[c] / omega);
        out.push_back(cell);
      }
    }
    return out;
  }();
  return cells;
}

WaveletLighting FastRotatedSunrise(int n, double angle) {
  const CubemapLayout layout(n);
  std::vector<double> acc(4 * layout.texel_count(), 0.0);
  for (const SplatCell& cell : SunriseCells()) {
    const std::size_t t = layout.TexelOf(RotateAboutY(cell.direction, angle));
    for (int c = 0; c < 3; ++c) acc[4 * t + c] += cell.omega * cell.rgb[c];
    acc[4 * t + 3] += cell.omega;
  }
  CubemapRgb cube;
  cube.n = n;
  for (int c = 0; c < 3; ++c) {
    cube.Channel(c).resize(layout.texel_count());
    for (std::size_t t = 0; t < layout.texel_count(); ++t) {
      const double o = acc[4 * t + 3];
      cube.Channel(c)[t] = static_cast<float>(o > 0 ? acc[4 * t + c] / o : 0.0);
    }
  }
  return ProjectLighting(cube);
}

double RelativeRms(const SampleRadiance& a, const SampleRadiance& ref) {
  double num = 0.0, den = 0.0;
  for (int c = 0; c < 3; ++c) {
    for (std::size_t s = 0; s < ref.size(); ++s) {
      const double d = a.channel[c][s] - ref.channel[c][s];
      num += d * d;
      den += ref.channel[c][s] * ref.channel[c][s];
    }
  }
  return den > 0 ? std::sqrt(num / den) : std::sqrt(num);
}

// max |a − ref| / max |ref|.
double RelativeMax(const SampleRadiance& a, const SampleRadiance& ref) {
  double num = 0.0, den = 0.0;
  for (int c = 0; c < 3; ++c) {
    for (std::size_t s = 0; s < ref.size(); ++s) {
      num = std::max(num, std::abs(a.channel[c][s] - ref.channel[c][s]));
      den = std::max(den, std::abs(ref.channel[c][s]));
    }
  }
  return num / den;
}

std::size_t NonZeros(const WaveletLighting& l) {
  return ExactLightingTerms(l).size();
}

template <class Relighter>
const SampleRadiance& RadianceOf(Relighter& r) {
  return r.Radiance();
}

// Static lighting: from zero (Clear) and from another lighting (Initialize), BI and PBI reach
// L̃ = L exactly within ⌈non-zeros / N⌉ (+1 for a first-frame reset) frames, and B = T·L.
template <class Relighter>
void ExpectConvergesUnderStaticLighting(const char* name) {
  const int n = 32;
  const DenseTransport t = ShadowedTransport(n, 40, 7);
  const WaveletLighting target = ProjectLighting(ResampleToCubemap(Sunrise(), n, 0.0));
  const WaveletLighting other = ProjectLighting(ResampleToCubemap(Sunrise(), n, 2.0));
  const SampleRadiance exact = t.Apply(ExactLightingTerms(target));
  const std::size_t budget = 30;
  const std::size_t bound = (NonZeros(target) + budget - 1) / budget + 1;
  for (bool from_zero : {true, false}) {
    Relighter r(t, n, budget);
    if (!from_zero) r.Initialize(other);
    std::size_t frames = 0;
    bool exact_now = false;
    double error_after_5 = 0.0, error_after_25 = 0.0;
    while (!exact_now && frames < bound + 10) {
      exact_now = r.Update(target).exact;
      ++frames;
      if (frames == 5) error_after_5 = RelativeRms(RadianceOf(r), exact);
      if (frames == 25) error_after_25 = RelativeRms(RadianceOf(r), exact);
    }
    std::printf(
        "%s from %s: exact after %zu frames (bound %zu); rel. RMS after 5: %.2e, 25: "
        "%.2e\n",
        name, from_zero ? "zero" : "other lighting", frames, bound, error_after_5, error_after_25);
    EXPECT_TRUE(exact_now);
    EXPECT_LE(frames, bound);
    EXPECT_LT(RelativeMax(RadianceOf(r), exact), 1e-9);
    // Once exact, a frame applies nothing.
    EXPECT_EQ(r.Update(target).terms, 0u);
  }
}

TEST(PerBandIncrementalTest, BiConvergesUnderStaticLighting) {
  ExpectConvergesUnderStaticLighting<BasicIncrementalRelighter>("BI");
}

TEST(PerBandIncrementalTest, PbiConvergesUnderStaticLighting) {
  ExpectConvergesUnderStaticLighting<PerBandIncrementalRelighter>("PBI");
}

// §5.2.2: a band whose new lighting is closer to zero than to L̃ is reset (Fig. 6 line 14).
TEST(PerBandIncrementalTest, L1TestResetsBandsThatDriftedTooFar) {
  const int n = 8;
  const DenseTransport t = ShadowedTransport(n, 10, 3);
  const WaveletLighting a = AnalyticSky(n, 0.3);
  PerBandIncrementalRelighter pbi(t, n, 5);
  pbi.Initialize(a);
  IncrementalFrame f = pbi.Update(a);  // nothing changed: no reset, no terms
  EXPECT_EQ(f.terms, 0u);
  EXPECT_TRUE(f.exact);
  for (uint8_t reset : f.band_reset) EXPECT_EQ(reset, 0);

  WaveletLighting zero = a;
  for (auto& c : zero.coefficient) std::fill(c.begin(), c.end(), 0.0);
  f = pbi.Update(zero);  // ‖0 − L̃‖₁ > ‖0‖₁ = 0 in every band: all reset, to exactly zero
  ASSERT_EQ(f.band_reset.size(), 3u);
  for (uint8_t reset : f.band_reset) EXPECT_EQ(reset, 1);
  EXPECT_EQ(f.terms, 0u);
  EXPECT_TRUE(f.exact);
  for (int c = 0; c < 3; ++c) {
    for (double v : pbi.Radiance().channel[c]) EXPECT_EQ(v, 0.0);
  }

  // Only the changed band is touched: L̃ differs from L^new in one coarse coefficient.
  pbi.Initialize(a);
  WaveletLighting b = a;
  b.coefficient[0][1] += 0.25;  // face 0, coarsest detail → band 0
  f = pbi.Update(b);
  EXPECT_EQ(f.terms, 1u);
  EXPECT_TRUE(f.exact);
  EXPECT_LT(RelativeMax(pbi.Radiance(), t.Apply(ExactLightingTerms(b))), 1e-12);
}

// No drift: 10,000 frames of a rotating environment, then static lighting; once L̃ = L, the
// incrementally accumulated image equals a freshly computed T·L to 1e-4 relative (in fact to
// rounding, since L̃ is tracked exactly and B accumulates in double). PRT_STRESS_FRAMES sets
// another frame count: `scripts/bench.sh stress` runs 100,000 (issue 9's long version).
int StressFrames() {
  const char* env = std::getenv("PRT_STRESS_FRAMES");
  const int frames = env != nullptr && *env != '\0' ? std::atoi(env) : 10000;
  return frames > 0 ? frames : 10000;
}

template <class Relighter>
void ExpectNoDriftAfterTenThousandFrames(const char* name) {
  const int n = 16;
  const int rotating_frames = StressFrames();
  const DenseTransport t = ShadowedTransport(n, 48, 11);
  Relighter r(t, n, 30);
  const double step = 0.5 * std::numbers::pi / 180.0;
  WaveletLighting l = AnalyticSky(n, 0.0);
  r.Initialize(l);
  for (int frame = 1; frame <= rotating_frames; ++frame) {
    l = AnalyticSky(n, frame * step);
    r.Update(l);
  }
  const double rotating_error = RelativeRms(RadianceOf(r), t.Apply(ExactLightingTerms(l)));
  const std::size_t bound = (NonZeros(l) + 29) / 30 + 1;
  std::size_t frames = 0;
  bool exact_now = false;
  while (!exact_now && frames < bound + 10) {
    exact_now = r.Update(l).exact;
    ++frames;
  }
  const SampleRadiance fresh = t.Apply(ExactLightingTerms(l));
  const double drift = RelativeMax(RadianceOf(r), fresh);
  std::printf(
      "%s: rel. RMS error while rotating (frame %d) %.3e; static again: exact after "
      "%zu frames, max relative difference to fresh T·L %.3e\n",
      name, rotating_frames, rotating_error, frames, drift);
  EXPECT_TRUE(exact_now);
  EXPECT_LE(frames, bound);
  EXPECT_EQ(r.Represented().coefficient, l.coefficient);
  EXPECT_LT(drift, 1e-4);
  r.Rederive();
  EXPECT_LT(RelativeMax(RadianceOf(r), fresh), 1e-12);
}

TEST(PerBandIncrementalTest, BiDoesNotDriftOverTenThousandFrames) {
  ExpectNoDriftAfterTenThousandFrames<BasicIncrementalRelighter>("BI");
}

TEST(PerBandIncrementalTest, PbiDoesNotDriftOverTenThousandFrames) {
  ExpectNoDriftAfterTenThousandFrames<PerBandIncrementalRelighter>("PBI");
}

TEST(PerBandIncrementalTest, FastRotationAgreesWithResampler) {
  const DenseTransport t = ShadowedTransport(32, 64, 5);
  for (double angle : {0.0, 0.7, 2.0}) {
    const WaveletLighting exact = ProjectLighting(ResampleToCubemap(Sunrise(), 32, angle));
    const WaveletLighting fast = FastRotatedSunrise(32, angle);
    const double lighting = RelativeLightingError(exact, ExactLightingTerms(fast));
    const double relit =
        RelativeRms(t.Apply(ExactLightingTerms(fast)), t.Apply(ExactLightingTerms(exact)));
    std::printf(
        "fast rotated sunrise vs ResampleToCubemap at %.1f rad: lighting rel. L2 %.4f, "
        "relit rel. RMS %.4f\n",
        angle, lighting, relit);
    EXPECT_LT(relit, 0.1);  // the sun snaps to one texel here, shared exactly there
  }
}

// Overbeck et al. §5.3 / §6.1: during a rotation PBI with 30 terms beats NWA with 3× the terms.
// Sunrise (a low sun holding 61% of the energy) rotating 0.5° per frame for 120 frames (a full
// turn in 24 s at 30 frames/s; at ≥ 1°/frame NWA-90 wins on this diffuse transport), relit
// through the synthetic shadowed transport; the error is the relative RMS image error against
// the exact T·L of the same frame, averaged over the frames.
TEST(PerBandIncrementalTest, Pbi30BeatsNwa90OverSunriseRotation) {
  const int n = 32;
  const DenseTransport t = ShadowedTransport(n, 64, 5);
  const HaarLightingBasis basis(n);
  const double step = 0.5 * std::numbers::pi / 180.0;
  WaveletLighting l0 = FastRotatedSunrise(n, 0.0);
  PerBandIncrementalRelighter pbi(t, n, 30);
  PerBandIncrementalRelighter pbi_cold(t, n, 30);  // started from zero instead of T·L⁰
  BasicIncrementalRelighter bi(t, n, 30);
  pbi.Initialize(l0);
  bi.Initialize(l0);
  double e_pbi = 0, e_cold = 0, e_bi = 0, e_nwa30 = 0, e_nwa90 = 0;
  int resets = 0;
  const int frames = 120;
  for (int frame = 1; frame <= frames; ++frame) {
    const WaveletLighting l = FastRotatedSunrise(n, frame * step);
    const SampleRadiance exact = t.Apply(ExactLightingTerms(l));
    for (uint8_t r : pbi.Update(l).band_reset) resets += r;
    pbi_cold.Update(l);
    bi.Update(l);
    e_pbi += RelativeRms(pbi.Radiance(), exact);
    e_cold += RelativeRms(pbi_cold.Radiance(), exact);
    e_bi += RelativeRms(bi.Radiance(), exact);
    e_nwa30 += RelativeRms(t.Apply(NonlinearLightingApproximation(l, basis, 30)), exact);
    e_nwa90 += RelativeRms(t.Apply(NonlinearLightingApproximation(l, basis, 90)), exact);
  }
  std::printf(
      "sunrise (fast rotation), 0.5°/frame, 120 frames, mean rel. RMS image error: PBI-30 %.4f "
      "(from zero %.4f), BI-30 %.4f, NWA-30 %.4f, NWA-90 %.4f; PBI band resets %d\n",
      e_pbi / frames, e_cold / frames, e_bi / frames, e_nwa30 / frames, e_nwa90 / frames, resets);
  EXPECT_LT(e_pbi, e_nwa90);
  EXPECT_LT(e_cold, e_nwa90);
  EXPECT_LT(e_pbi, e_nwa30);
}

}  // namespace
}  // namespace prt
