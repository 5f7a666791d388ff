// prt-bench's sweep (docs/benchmarks.md): the points of a run and one scene's measurements —
// brute force (the reference, traced in slices over the MPI ranks), sparse precomputation, 2D/4D
// compression and NWA/PBI lighting, each against the brute-force T.
#pragma once

#include <tbb/global_control.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <numbers>
#include <optional>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "bench/bench_scenes.h"
#include "bench/prt_bench_records.h"
#include "farm/mpi_session.h"
#include "runtime/compressed_relight.h"
#include "runtime/lighting.h"
#include "runtime/per_band_incremental.h"
#include "runtime/relight.h"
#include "vocabulary/cubemap_resample.h"
#include "vocabulary/environment_io.h"
#include "worker/column_order.h"
#include "worker/embree_scene.h"
#include "worker/sparse_precomputation.h"
#include "worker/transport_compressor.h"
#include "worker/transport_sampler.h"

namespace prt::bench {

// ---- Per-scene state ----

struct Options {
  std::vector<std::string> scenes, envs;
  int n = 16, rays = 0, ground = 0, frames = 24, eval_every = 4;
  double deg = 1.0;
  std::vector<double> dense_budgets, feature_scales, radius_scales, keeps, bits, terms;
  std::vector<std::string> schemes;
};

// Per-sample albedo, meshes in order.
std::vector<Rgb> SampleAlbedo(const SceneGeometry& g);

// Interleaved albedo ⊙ radiance from channel-major float radiance (3 × S).
std::vector<float> ShadeChannelMajor(std::span<const float> radiance, const std::vector<Rgb>& a);

std::vector<float> ChannelMajor(const CubemapRgb& cube);

class SceneBench {
 public:
  SceneBench(const std::string& name, const Options& o,
             const std::vector<bench::NamedEnvironment>& envs)
      : name_(name), o_(o), envs_(envs) {
    scene_ = bench::BenchScene(name, o.n);
    if (o.ground > 0) scene_.ground.resolution = o.ground;
    geometry_ = BuildSceneGeometry(scene_);
    embree_ = std::make_unique<EmbreeScene>(geometry_);
    TransportSamplerOptions so;
    so.rays_per_texel = o.rays > 0 ? o.rays : scene_.sampling.rays_per_texel;
    so.seed = scene_.sampling.seed;
    sampler_ = std::make_unique<TransportSampler>(*embree_, o.n, so);
    samples_ = SpatialSamplesOf(geometry_);
    S_ = samples_.size();
    M_ = sampler_->layout().texel_count();
    albedo_ = SampleAlbedo(geometry_);
    base_plan_ = PlanFromSettings(scene_.sparse, geometry_.diagonal(), o.n);
  }

  std::size_t samples() const { return S_; }
  std::size_t texels() const { return M_; }
  int rays_per_texel() const { return sampler_->options().rays_per_texel; }
  const SparsePlan& base_plan() const { return base_plan_; }

  // Brute force over this rank's slice of the samples, gathered on every rank.
  Record TraceBrute(const MpiSession& mpi) {
    brute_.assign(S_ * M_, 0.0f);
    mpi.Barrier();
    const auto t0 = Clock::now();
    const double c0 = CpuSeconds();
    const std::size_t first = MpiSession::SliceBegin(S_, mpi.rank(), mpi.size());
    const std::size_t count = MpiSession::SliceBegin(S_, mpi.rank() + 1, mpi.size()) - first;
    const SampleStats st = sampler_->ComputeRows(std::span(samples_).subspan(first, count), first,
                                                 brute_.data() + first * M_);
    const double cpu = mpi.SumOverRanks(CpuSeconds() - c0);
    mpi.AllGatherRowSlices(brute_.data(), S_, M_);
    const double wall = Seconds(t0);
    const uint64_t rays = mpi.SumOverRanks(static_cast<uint64_t>(st.rays_traced));
    for (float v : brute_) t_energy_ += static_cast<double>(v) * v;
    // References: relit radiance of the brute-force T under each environment.
    Record r = NewRecord("brute", "brute force");
    r.wall_s = wall;
    r.cpu_s = cpu;
    r.rays = rays;
    r.sampled_fraction = 1.0;
    r.bytes = S_ * M_ * sizeof(float);
    for (std::size_t e = 0; e < envs_.size(); ++e) {
      const auto r0 = Clock::now();
      ref_.push_back(bench::RelitRadiance(geometry_, brute_, envs_[e].cube));
      r.relight_ms = e == 0 ? 1e3 * Seconds(r0) : std::min(r.relight_ms, 1e3 * Seconds(r0));
    }
    r.err_env.assign(envs_.size(), 0.0);
    return r;
  }

  Record Run(const Point& p) {
    if (p.family == "sparse") return RunSparse(p);
    if (p.family == "nwa" || p.family == "pbi") return RunLighting(p);
    return RunCompression(p);
  }

 private:
  Record NewRecord(const std::string& family, const std::string& label) const {
    Record r;
    r.scene = name_;
    r.n = o_.n;
    r.samples = S_;
    r.family = family;
    r.label = label;
    return r;
  }

  // Relit error per environment of T given as texel-basis rows; relight_ms = the first one.
  void ErrorsOfRows(const std::vector<float>& rows, Record& r) const {
    double num = 0;
    for (std::size_t i = 0; i < rows.size(); ++i) {
      const double d = static_cast<double>(rows[i]) - brute_[i];
      num += d * d;
    }
    r.err_t = std::sqrt(num / t_energy_);
    for (std::size_t e = 0; e < envs_.size(); ++e) {
      const auto r0 = Clock::now();
      const std::vector<float> b = bench::RelitRadiance(geometry_, rows, envs_[e].cube);
      r.relight_ms = e == 0 ? 1e3 * Seconds(r0) : std::min(r.relight_ms, 1e3 * Seconds(r0));
      r.err_env.push_back(bench::RelativeRmsError(b, ref_[e], 0, S_));
    }
  }

  Record RunSparse(const Point& p) {
    SparsePlan plan = base_plan_;
    plan.dense_budget = p.dense_budget;
    plan.sparse.features =
        std::max(1, static_cast<int>(std::lround(base_plan_.sparse.features * p.feature_scale)));
    plan.radius = base_plan_.radius * p.radius_scale;
    char label[96];
    std::snprintf(label, sizeof label, "sparse dense %.3g features %d radius x%.3g", p.dense_budget,
                  plan.sparse.features, p.radius_scale);
    Record r = NewRecord("sparse", label);
    r.dense_budget = plan.dense_budget;
    r.features = plan.sparse.features;
    r.radius = plan.radius;
    SparseReport rep;
    std::vector<float> rows(S_ * M_, 0.0f);  // allocated before the clock, as brute force's
    const auto t0 = Clock::now();
    const double c0 = CpuSeconds();
    RunSparsePrecomputation(*sampler_, samples_, plan, rep, rows.data());
    r.wall_s = Seconds(t0);
    r.cpu_s = CpuSeconds() - c0;
    r.rays = rep.dense_angular.trace.rays_traced + rep.sparse_stats.trace.rays_traced;
    r.sampled_fraction = rep.SampledFraction();
    r.bytes = S_ * M_ * sizeof(float);
    ErrorsOfRows(rows, r);
    return r;
  }

  Record RunCompression(const Point& p) {
    CompressionOptions co = CompressionOptionsFrom(scene_.compression, "<bench scene>");
    co.scheme = ParseCompressionScheme(p.family, "--schemes");
    co.keep_fraction = p.keep;
    co.bits = p.bits;
    char label[96];
    std::snprintf(label, sizeof label, "%s keep %.3g %d bits", p.family.c_str(), p.keep, p.bits);
    Record r = NewRecord(p.family, label);
    r.keep = p.keep;
    r.bits = p.bits;
    const auto t0 = Clock::now();
    const double c0 = CpuSeconds();
    const CompressedTransport ct =
        CompressTransport(brute_.data(), o_.n, SpatialDomainOf(geometry_), co);
    r.wall_s = Seconds(t0);
    r.cpu_s = CpuSeconds() - c0;
    r.bytes = EncodeCompressedTransport(ct).size();
    r.sampled_fraction = 0;
    CompressedErrors(ct, r);
    return r;
  }

  // Eq. 8 relighting from compressed columns under each environment, and T's error.
  void CompressedErrors(const CompressedTransport& ct, Record& r) const {
    const CompressedRelighter relighter(ct);
    std::vector<float> B(3 * S_);
    double relight_s = INFINITY;
    for (std::size_t e = 0; e < envs_.size(); ++e) {
      const std::vector<float> Lhat =
          LightingToRowWaveletBasis(ct.header.row_wavelet, o_.n, ChannelMajor(envs_[e].cube), 3);
      const auto r0 = Clock::now();
      relighter.Relight(Lhat, 3, B);
      relight_s = std::min(relight_s, Seconds(r0));
      r.err_env.push_back(bench::RelativeRmsError(ShadeChannelMajor(B, albedo_), ref_[e], 0, S_));
    }
    r.relight_ms = 1e3 * relight_s;
    const std::vector<float> back = DecompressTransport(ct);
    double num = 0;
    for (std::size_t i = 0; i < back.size(); ++i) {
      const double d = static_cast<double>(back[i]) - brute_[i];
      num += d * d;
    }
    r.err_t = std::sqrt(num / t_energy_);
  }

  // The scene's default compression, as prt-view relights it (built on first use).
  void EnsureViewerTransport() {
    if (viewer_ct_) return;
    const CompressionOptions co = CompressionOptionsFrom(scene_.compression, "<bench scene>");
    viewer_ct_ = std::make_unique<CompressedTransport>(
        CompressTransport(brute_.data(), o_.n, SpatialDomainOf(geometry_), co));
    viewer_relighter_ = std::make_unique<CompressedRelighter>(*viewer_ct_);
    viewer_op_ = std::make_unique<CompressedTransportOperator>(*viewer_relighter_);
    Record tmp;
    viewer_bytes_ = EncodeCompressedTransport(*viewer_ct_).size();
    CompressedErrors(*viewer_ct_, tmp);
    viewer_err_t_ = tmp.err_t;
  }

  // Rotated lighting per environment and frame, and the brute-force exact radiance at the
  // frames where errors are measured (built on first use).
  struct Rotation {
    std::vector<WaveletLighting> lighting;  // frames 0..K
    std::map<int, std::vector<float>> ref;  // frame → albedo ⊙ (T_brute · L_frame)
  };
  void EnsureRotations() {
    if (!rotations_.empty()) return;
    for (const bench::NamedEnvironment& e : envs_) {
      const EnvironmentImage img =
          ReadEnvironment(bench::DataDir() + "/envmaps/" + e.name + ".exr");
      Rotation rot;
      for (int f = 0; f <= o_.frames; ++f) {
        const CubemapRgb cube = ResampleToCubemap(img, o_.n, f * o_.deg * std::numbers::pi / 180.0);
        rot.lighting.push_back(ProjectLighting(cube));
        if (f > 0 && (f % o_.eval_every == 0 || f == o_.frames))
          rot.ref[f] = bench::RelitRadiance(geometry_, brute_, cube);
      }
      rotations_.push_back(std::move(rot));
    }
  }

  // NWA or PBI with `terms` terms per frame while each environment rotates by deg per frame:
  // error = mean over the measured frames of the relit error against the brute-force exact
  // radiance of that frame; relight_ms = mean time of one frame's lighting update and T·L̂.
  Record RunLighting(const Point& p) {
    EnsureViewerTransport();
    EnsureRotations();
    const bool pbi = p.family == "pbi";
    Record r = NewRecord(p.family, (pbi ? "PBI-" : "NWA-") + std::to_string(p.terms));
    r.terms = p.terms;
    r.bytes = viewer_bytes_;
    r.err_t = viewer_err_t_;
    const HaarLightingBasis basis(o_.n);
    std::vector<double> frame_s;
    const auto t0 = Clock::now();
    const double c0 = CpuSeconds();
    for (const Rotation& rot : rotations_) {
      std::optional<PerBandIncrementalRelighter> inc;
      if (pbi) {
        inc.emplace(*viewer_op_, o_.n, p.terms);
        inc->Initialize(rot.lighting[0]);  // the paper's exact frame 0
      }
      double err = 0;
      for (int f = 1; f <= o_.frames; ++f) {
        const auto f0 = Clock::now();
        SampleRadiance radiance;
        if (pbi) {
          inc->Update(rot.lighting[f]);
          radiance = inc->Radiance();
        } else {
          radiance =
              viewer_op_->Apply(NonlinearLightingApproximation(rot.lighting[f], basis, p.terms));
        }
        frame_s.push_back(Seconds(f0));
        const auto it = rot.ref.find(f);
        if (it != rot.ref.end())
          err += bench::RelativeRmsError(ShadeSamples(radiance, albedo_), it->second, 0, S_);
      }
      r.err_env.push_back(err / static_cast<double>(rot.ref.size()));
    }
    r.wall_s = Seconds(t0);
    r.cpu_s = CpuSeconds() - c0;
    std::nth_element(frame_s.begin(), frame_s.begin() + frame_s.size() / 2, frame_s.end());
    r.relight_ms = frame_s.empty() ? 0 : 1e3 * frame_s[frame_s.size() / 2];
    return r;
  }

  std::string name_;
  const Options& o_;
  const std::vector<bench::NamedEnvironment>& envs_;
  SceneDescription scene_;
  SceneGeometry geometry_;
  std::unique_ptr<EmbreeScene> embree_;
  std::unique_ptr<TransportSampler> sampler_;
  std::vector<SpatialSample> samples_;
  std::size_t S_ = 0, M_ = 0;
  std::vector<Rgb> albedo_;
  SparsePlan base_plan_;
  std::vector<float> brute_;
  double t_energy_ = 0;
  std::vector<std::vector<float>> ref_;
  std::unique_ptr<CompressedTransport> viewer_ct_;
  std::unique_ptr<CompressedRelighter> viewer_relighter_;
  std::unique_ptr<CompressedTransportOperator> viewer_op_;
  uint64_t viewer_bytes_ = 0;
  double viewer_err_t_ = 0;
  std::vector<Rotation> rotations_;
};

// The sweep, one axis at a time around the first value of each list (the cost of a full grid is
// the product of the list lengths): sparse at every dense budget (first feature and radius
// scale), then every other feature scale and radius scale at the first budget; compression at
// every scheme × keep at the first bit depth, then every other bit depth at the middle keep;
// NWA and PBI at every term count.
std::vector<Point> SweepPoints(const Options& o);

}  // namespace prt::bench
