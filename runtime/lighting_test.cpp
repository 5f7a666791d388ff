// Wavelet lighting and NWA (Ng et al. 2003): projection identities, band/area bookkeeping, NWA
// with all terms = exact, monotone error on a real environment, area-weighted vs magnitude.
#include "runtime/lighting.h"

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <limits>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include "runtime/relight.h"
#include "vocabulary/cubemap.h"
#include "vocabulary/cubemap_resample.h"
#include "vocabulary/environment_io.h"
#include "vocabulary/envmap.h"
#include "vocabulary/errors.h"
#include "vocabulary/wavelets.h"

namespace prt {
namespace {

CubemapRgb RandomCubemap(int n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 2.0f);
  CubemapRgb c;
  c.n = n;
  for (int ch = 0; ch < 3; ++ch) {
    c.Channel(ch).resize(c.TexelCount());
    for (float& v : c.Channel(ch)) v = u(rng);
  }
  return c;
}

const CubemapRgb& Sunrise32() {
  static const CubemapRgb cube = [] {
    const EnvironmentImage env = ReadEnvironment(PRT_DATA_DIR "/envmaps/sunrise.exr");
    return ResampleToCubemap(env, 32);
  }();
  return cube;
}

// Diffuse transport rows for unit normals, in the Haar basis: texel j gets
// (1/π)·Ω_j·max(0, n·ω_j) at the texel centre (DESIGN.md "Conventions", unoccluded, white).
std::vector<float> CosineTransportRows(int n, const std::vector<Vec3>& normals) {
  const CubemapLayout layout(n);
  const std::size_t m = layout.texel_count();
  std::vector<float> rows(normals.size() * m);
  for (std::size_t s = 0; s < normals.size(); ++s) {
    float* row = rows.data() + s * m;
    for (std::size_t j = 0; j < m; ++j) {
      const double c = std::max(0.0, Dot(normals[s], layout.TexelCenter(j)));
      row[j] = static_cast<float>(layout.TexelSolidAngle(j) * c / std::numbers::pi);
    }
    ForwardHaarCubemap(row, n, WaveletMaxDepth2D(WaveletFilter::kHaar, n, n));
  }
  return rows;
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
  return std::sqrt(num / den);
}

TEST(LightingTest, ProjectionRoundTripsAndPreservesEnergy) {
  const CubemapRgb cube = RandomCubemap(8, 3);
  const WaveletLighting l = ProjectLighting(cube);
  ASSERT_EQ(l.size(), cube.TexelCount());
  const CubemapRgb back = ReconstructLighting(l);
  for (int c = 0; c < 3; ++c) {
    double e_tex = 0.0, e_coef = 0.0;
    for (std::size_t j = 0; j < cube.TexelCount(); ++j) {
      EXPECT_NEAR(back.Channel(c)[j], cube.Channel(c)[j], 1e-5);
      e_tex += double(cube.Channel(c)[j]) * cube.Channel(c)[j];
      e_coef += l.coefficient[c][j] * l.coefficient[c][j];
    }
    EXPECT_NEAR(e_coef, e_tex, 1e-5 * e_tex);  // orthonormal: Parseval
  }
  // The scaling coefficient of each face is n·(mean of the face) for the orthonormal Haar basis.
  double mean = 0.0;
  for (int j = 0; j < 64; ++j) mean += cube.r[j];
  EXPECT_NEAR(l.coefficient[0][0], mean / 64.0 * 8.0, 1e-4);
}

// ProjectLighting is the Haar transform of vocabulary/wavelets.h computed in double without its
// final rounding to float: it equals ForwardHaarCubemap to float rounding, keeps coefficients the
// float transform would overflow (a face's scaling coefficient is n × its mean), and refuses a
// NaN/Inf texel by name instead of zeroing it.
TEST(LightingTest, ProjectionIsDoubleHaarAndRefusesNonFiniteTexels) {
  const int n = 8;
  const CubemapRgb cube = RandomCubemap(n, 11);
  const WaveletLighting l = ProjectLighting(cube);
  for (int c = 0; c < 3; ++c) {
    std::vector<float> f = cube.Channel(c);
    ForwardHaarCubemap(f.data(), n, WaveletMaxDepth2D(WaveletFilter::kHaar, n, n));
    for (std::size_t j = 0; j < f.size(); ++j) {
      // The float transform is the same double arithmetic rounded once at the end.
      EXPECT_EQ(f[j], static_cast<float>(l.coefficient[c][j])) << c << " " << j;
    }
  }
  // Texels of 1e38: each face's scaling coefficient is 8 × 1e38, past FLT_MAX (3.4e38).
  CubemapRgb huge = cube;
  for (int c = 0; c < 3; ++c)
    for (float& v : huge.Channel(c)) v *= 5e37f;
  const WaveletLighting h = ProjectLighting(huge);
  for (int c = 0; c < 3; ++c)
    for (double v : h.coefficient[c]) ASSERT_TRUE(std::isfinite(v));
  EXPECT_GT(std::abs(h.coefficient[0][0]), 3.4e38);
  std::vector<float> overflowing = huge.r;
  ForwardHaarCubemap(overflowing.data(), n, WaveletMaxDepth2D(WaveletFilter::kHaar, n, n));
  EXPECT_TRUE(std::isinf(overflowing[0]));  // what the float transform would have stored
  // The round trip comes back to the texels (double inverse), relative 1e-7.
  const CubemapRgb back = ReconstructLighting(h);
  for (std::size_t j = 0; j < huge.TexelCount(); ++j)
    ASSERT_NEAR(back.g[j], huge.g[j], 1e-6 * huge.g[j]) << j;
  // A term list whose texels leave the float range is an error, not an Inf texel.
  EXPECT_THROW(ReconstructLighting(n, std::vector<LightingTerm>{{0, {1e40, 1.0, 1.0}}}),
               NumericalError);
  CubemapRgb bad = cube;
  bad.b[6 * n * n - 1] = std::numeric_limits<float>::infinity();
  try {
    ProjectLighting(bad);
    FAIL() << "an Inf texel was projected";
  } catch (const NumericalError& e) {
    EXPECT_EQ(std::string(e.what()),
              "ProjectLighting: lighting texel 383 (face 5) channel B is Inf");
  }
  bad.b[6 * n * n - 1] = std::nanf("");
  EXPECT_THROW(ProjectLighting(bad), NumericalError);
}

TEST(LightingTest, BasisBandsGroupByArea) {
  const HaarLightingBasis basis(32);
  ASSERT_EQ(basis.band_count(), 5);
  std::size_t total = 0;
  for (int b = 0; b < basis.band_count(); ++b) {
    const auto& members = basis.BandMembers(b);
    total += members.size();
    // Band 0 = scaling + coarsest level: 4 per face; band b ≥ 1: 3·4^b per face.
    const std::size_t per_face = b == 0 ? 4 : 3u << (2 * b);
    EXPECT_EQ(members.size(), 6 * per_face) << "band " << b;
    for (uint32_t j : members) {
      EXPECT_EQ(basis.Band(j), b);
      EXPECT_EQ(basis.Area(j), 1024.0 / double(1 << (2 * b)));
    }
  }
  EXPECT_EQ(total, basis.size());
  EXPECT_EQ(basis.Level(0), 0);
  EXPECT_EQ(basis.Level(31 * 32 + 31), 5);  // finest HH of face 0
  EXPECT_EQ(basis.Area(31 * 32 + 31), 4.0);
}

TEST(LightingTest, NwaWithAllTermsIsExact) {
  const CubemapRgb cube = RandomCubemap(8, 5);
  const WaveletLighting l = ProjectLighting(cube);
  const HaarLightingBasis basis(8);
  const auto exact = ExactLightingTerms(l);
  for (TermRanking r : {TermRanking::kAreaWeighted, TermRanking::kMagnitude}) {
    const auto nwa = NonlinearLightingApproximation(l, basis, l.size(), r);
    ASSERT_EQ(nwa.size(), exact.size());
    for (std::size_t k = 0; k < nwa.size(); ++k) {
      EXPECT_EQ(nwa[k].index, exact[k].index);
      EXPECT_EQ(nwa[k].value, exact[k].value);
    }
    EXPECT_EQ(RelativeLightingError(l, nwa), 0.0);
  }
  // And relit through a transport: identical images.
  const std::vector<Vec3> normals = {{0, 1, 0}, Normalize(Vec3{1, 1, 0.3})};
  const DenseTransport t(CosineTransportRows(8, normals), normals.size(), l.size());
  const SampleRadiance a = t.Apply(exact);
  const SampleRadiance b = t.Apply(NonlinearLightingApproximation(l, basis, 100000));
  for (int c = 0; c < 3; ++c) EXPECT_EQ(a.channel[c], b.channel[c]);
}

TEST(LightingTest, NwaRanksByAreaWeightedMagnitude) {
  // Face 0 of n = 2: coefficient 0 is the scaling (area 4), 1..3 the details (area 4 too at
  // n = 2), so use n = 4 where the finest details have area 4 and the coarse ones 16.
  const HaarLightingBasis basis(4);
  WaveletLighting l;
  l.n = 4;
  for (auto& c : l.coefficient) c.assign(basis.size(), 0.0);
  const uint32_t fine = 3 * 4 + 3;  // finest HH, area 4
  const uint32_t coarse = 1;        // coarsest HL, area 16
  l.coefficient[0][fine] = 3.0;     // weight 12 area-weighted, 3 by magnitude
  l.coefficient[1][coarse] = 1.0;   // weight 16 area-weighted, 1 by magnitude
  auto aw = NonlinearLightingApproximation(l, basis, 1, TermRanking::kAreaWeighted);
  auto mg = NonlinearLightingApproximation(l, basis, 1, TermRanking::kMagnitude);
  ASSERT_EQ(aw.size(), 1u);
  ASSERT_EQ(mg.size(), 1u);
  EXPECT_EQ(aw[0].index, coarse);
  EXPECT_EQ(mg[0].index, fine);
  // Zero coefficients are never chosen.
  EXPECT_EQ(NonlinearLightingApproximation(l, basis, 10).size(), 2u);
}

TEST(LightingTest, NwaErrorDecreasesMonotonicallyOnSunrise) {
  const WaveletLighting l = ProjectLighting(Sunrise32());
  const HaarLightingBasis basis(32);
  double previous = 1.0 + 1e-12;
  for (std::size_t terms : {1, 3, 10, 30, 100, 300, 1000, 3000, 6144}) {
    const double e = RelativeLightingError(l, NonlinearLightingApproximation(l, basis, terms));
    EXPECT_LT(e, previous) << terms << " terms";
    previous = e;
  }
  EXPECT_EQ(previous, 0.0);
}

TEST(LightingTest, AreaWeightedBeatsMagnitudeInRelitErrorOnSunrise) {
  const WaveletLighting l = ProjectLighting(Sunrise32());
  const HaarLightingBasis basis(32);
  std::vector<Vec3> normals;
  for (int i = 0; i < 64; ++i) {  // a spread of normals (Fibonacci sphere)
    const double y = 1.0 - (i + 0.5) / 32.0;
    const double r = std::sqrt(std::max(0.0, 1.0 - y * y));
    const double phi = i * std::numbers::pi * (3.0 - std::sqrt(5.0));
    normals.push_back({r * std::cos(phi), y, r * std::sin(phi)});
  }
  const DenseTransport t(CosineTransportRows(32, normals), normals.size(), l.size());
  const SampleRadiance ref = t.Apply(ExactLightingTerms(l));
  for (std::size_t terms : {10, 30, 100}) {
    const double aw = RelativeRms(
        t.Apply(NonlinearLightingApproximation(l, basis, terms, TermRanking::kAreaWeighted)), ref);
    const double mg = RelativeRms(
        t.Apply(NonlinearLightingApproximation(l, basis, terms, TermRanking::kMagnitude)), ref);
    std::printf(
        "NWA %3zu terms, diffuse relit rel. RMS error: area-weighted %.4f, magnitude %.4f\n", terms,
        aw, mg);
    EXPECT_LT(aw, mg) << terms << " terms";
  }
}

}  // namespace
}  // namespace prt
