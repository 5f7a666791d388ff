// prt-bench: what each setting buys, run time against error (issue 9, docs/benchmarks.md).
//
// For each scene (the default scene and real meshes on its ground plane, bench/bench_scenes.h)
// at cubemap resolution n it traces the brute-force transport T (the exact reference) and sweeps
//   - sparse precomputation (Huang & Ramamoorthi 2010) at several dense budgets, feature counts
//     and radii (worker/sparse_precomputation.h);
//   - 2D (Ng et al. 2003), full 4D and adaptive 4D (Cheslack-Postava et al. 2008) compression of
//     the brute-force T at several keep budgets and bit depths (worker/transport_compressor.h),
//     relit by Eq. 8 from the compressed columns;
//   - NWA and PBI lighting (Overbeck et al. 2006) at several term counts, through T compressed
//     with the scene's [compression] settings as prt-view relights it, while each environment
//     rotates about +Y;
// and records for each point: wall and CPU time of the stage, rays traced, bytes stored, one
// relighting's time, the relative Frobenius error of T against the brute-force T, and the relative
// RMS error of relit radiance B = albedo ⊙ (T·L) against the brute-force exact result under each
// real environment (all samples, model and ground).
//
// Outputs in --out: prt_bench.csv (one row per point), prt_bench.md (every point, the Pareto
// fronts per scene: precomputation time, bytes and relighting time against error, the cheapest
// setting under error targets, and the papers' operating points next to ours) and, with gnuplot,
// plots/<scene>_{time,size,relight}_error.png with the papers' operating points marked.
//
// Under `mpirun -np K prt-bench` the ranks trace the brute-force rows in K slices (gathered on
// every rank), then split the sweep points round-robin; rank 0 gathers the rows and writes the
// outputs. Every number but the timings is identical to a 1-rank run (--compare checks that).
//
// Usage: prt-bench [--scenes default,armadillo,dragon] [--envs sunrise,city,studio,interior]
//                  [--n 16] [--rays 0] [--ground 0] [--out bench-out/prt-bench] [--quick]
//                  [--self-check]
//                  [--threads 0] [--dense-budgets ..] [--feature-scales ..] [--radius-scales ..]
//                  [--schemes ..] [--keeps ..] [--bits ..] [--terms ..] [--frames 24] [--deg 1]
//        prt-bench --check DIR           (sanity checks on DIR's CSV and summary, exit 1 if not)
//        prt-bench --compare DIR1 DIR2   (every non-timing column equal, exit 1 if not)
#include <tbb/global_control.h>

#include <CLI/CLI.hpp>
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
#include "farm/mpi_session.h"
#include "viewer/compressed_relight.h"
#include "viewer/lighting.h"
#include "viewer/per_band_incremental.h"
#include "viewer/relight.h"
#include "worker/column_order.h"
#include "worker/embree_scene.h"
#include "worker/sparse_precomputation.h"
#include "worker/transport_compressor.h"
#include "worker/transport_sampler.h"
#include "vocabulary/environment_io.h"
#include "vocabulary/cubemap_resample.h"

namespace {

using namespace prt;
namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

double Seconds(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}
// Process CPU seconds, all threads.
double CpuSeconds() {
  return static_cast<double>(std::clock()) / CLOCKS_PER_SEC;
}

std::vector<std::string> SplitList(const std::string& s, char sep = ',') {
  std::vector<std::string> out;
  std::stringstream ss(s);
  for (std::string item; std::getline(ss, item, sep);) out.push_back(item);
  return out;
}
std::vector<double> Numbers(const std::string& s) {
  std::vector<double> v;
  for (const std::string& x : SplitList(s))
    if (!x.empty()) v.push_back(std::stod(x));
  return v;
}
std::string Fmt(double v) {
  char buf[48];
  std::snprintf(buf, sizeof buf, "%.9g", v);
  return buf;
}
std::string Fmt3(double v) {
  char buf[48];
  std::snprintf(buf, sizeof buf, "%.3g", v);
  return buf;
}
std::string Percent(double v) {
  char buf[48];
  std::snprintf(buf, sizeof buf, "%.3g%%", 100 * v);
  return buf;
}

// ---- Sweep points and their results ----

// One setting of the sweep. family: brute | sparse | 2d | 4d | adaptive4d | nwa | pbi.
struct Point {
  std::string family;
  double dense_budget = 0, feature_scale = 0, radius_scale = 0;  // sparse
  double keep = 0;                                               // compression
  int bits = 0;
  std::size_t terms = 0;  // lighting
};

// One row of the CSV. Parameters that do not apply are 0.
struct Record {
  std::string scene;
  int n = 0;
  std::size_t samples = 0;
  std::string family, label;
  double dense_budget = 0;
  int features = 0;
  double radius = 0, keep = 0;
  int bits = 0;
  std::size_t terms = 0;
  double wall_s = 0, cpu_s = 0;
  uint64_t rays = 0;
  double sampled_fraction = 0;
  uint64_t bytes = 0;
  double relight_ms = 0, err_t = 0, err_mean = 0, err_max = 0;
  std::vector<double> err_env;  // one per environment, in --envs order
};

const char* kCsvColumns =
    "scene,n,samples,family,label,dense_budget,features,radius,keep,bits,terms,wall_s,cpu_s,rays,"
    "sampled_fraction,bytes,relight_ms,err_T,err_mean,err_max";
// Columns that hold timings (left out by --compare).
bool IsTimingColumn(const std::string& c) {
  return c == "wall_s" || c == "cpu_s" || c == "relight_ms";
}

std::string CsvHeader(const std::vector<std::string>& envs) {
  std::string h = kCsvColumns;
  for (const std::string& e : envs) h += ",err_" + e;
  return h;
}

std::string ToCsv(const Record& r) {
  std::ostringstream os;
  os << r.scene << ',' << r.n << ',' << r.samples << ',' << r.family << ',' << r.label << ','
     << Fmt(r.dense_budget) << ',' << r.features << ',' << Fmt(r.radius) << ',' << Fmt(r.keep)
     << ',' << r.bits << ',' << r.terms << ',' << Fmt(r.wall_s) << ',' << Fmt(r.cpu_s) << ','
     << r.rays << ',' << Fmt(r.sampled_fraction) << ',' << r.bytes << ',' << Fmt(r.relight_ms)
     << ',' << Fmt(r.err_t) << ',' << Fmt(r.err_mean) << ',' << Fmt(r.err_max);
  for (double e : r.err_env) os << ',' << Fmt(e);
  return os.str();
}

// Parses a row written by ToCsv; throws std::runtime_error naming `where` on a malformed row.
Record FromCsv(const std::string& line, std::size_t env_count, const std::string& where) {
  const std::vector<std::string> f = SplitList(line);
  if (f.size() != 20 + env_count)
    throw std::runtime_error(where + ": " + std::to_string(f.size()) + " fields, expected " +
                             std::to_string(20 + env_count));
  try {
    Record r;
    r.scene = f[0];
    r.n = std::stoi(f[1]);
    r.samples = std::stoull(f[2]);
    r.family = f[3];
    r.label = f[4];
    r.dense_budget = std::stod(f[5]);
    r.features = std::stoi(f[6]);
    r.radius = std::stod(f[7]);
    r.keep = std::stod(f[8]);
    r.bits = std::stoi(f[9]);
    r.terms = std::stoull(f[10]);
    r.wall_s = std::stod(f[11]);
    r.cpu_s = std::stod(f[12]);
    r.rays = std::stoull(f[13]);
    r.sampled_fraction = std::stod(f[14]);
    r.bytes = std::stoull(f[15]);
    r.relight_ms = std::stod(f[16]);
    r.err_t = std::stod(f[17]);
    r.err_mean = std::stod(f[18]);
    r.err_max = std::stod(f[19]);
    for (std::size_t e = 0; e < env_count; ++e) r.err_env.push_back(std::stod(f[20 + e]));
    return r;
  } catch (const std::logic_error& e) {
    throw std::runtime_error(where + ": malformed number (" + e.what() + ")");
  }
}

struct CsvFile {
  std::vector<std::string> columns, envs;
  std::vector<std::string> lines;
  std::vector<Record> records;
};

CsvFile ReadCsv(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error(path + ": cannot open");
  CsvFile c;
  std::string header;
  if (!std::getline(in, header)) throw std::runtime_error(path + ": empty");
  c.columns = SplitList(header);
  if (header.rfind(kCsvColumns, 0) != 0)
    throw std::runtime_error(path + ": header is not prt-bench's: " + header);
  for (std::size_t i = 20; i < c.columns.size(); ++i) c.envs.push_back(c.columns[i].substr(4));
  std::size_t line_no = 1;
  for (std::string line; std::getline(in, line);) {
    ++line_no;
    if (line.empty()) continue;
    c.lines.push_back(line);
    c.records.push_back(FromCsv(line, c.envs.size(), path + ":" + std::to_string(line_no)));
  }
  return c;
}

// ---- Per-scene state ----

struct Options {
  std::vector<std::string> scenes, envs;
  int n = 16, rays = 0, ground = 0, frames = 24, eval_every = 4;
  double deg = 1.0;
  std::vector<double> dense_budgets, feature_scales, radius_scales, keeps, bits, terms;
  std::vector<std::string> schemes;
};

// Per-sample albedo, meshes in order.
std::vector<Rgb> SampleAlbedo(const SceneGeometry& g) {
  std::vector<Rgb> a;
  for (const SceneMesh& m : g.meshes) a.insert(a.end(), m.mesh.positions.size(), m.albedo);
  return a;
}

// Interleaved albedo ⊙ radiance from channel-major float radiance (3 × S).
std::vector<float> ShadeChannelMajor(std::span<const float> radiance, const std::vector<Rgb>& a) {
  const std::size_t S = a.size();
  std::vector<float> out(3 * S);
  for (std::size_t s = 0; s < S; ++s)
    for (int c = 0; c < 3; ++c) out[3 * s + c] = a[s][c] * radiance[c * S + s];
  return out;
}

std::vector<float> ChannelMajor(const CubemapRgb& cube) {
  std::vector<float> L;
  for (int c = 0; c < 3; ++c) L.insert(L.end(), cube.Channel(c).begin(), cube.Channel(c).end());
  return L;
}

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

void Finish(Record& r) {
  r.err_mean = 0;
  r.err_max = 0;
  for (double e : r.err_env) {
    r.err_mean += e / static_cast<double>(r.err_env.size());
    r.err_max = std::max(r.err_max, e);
  }
}

// The sweep, one axis at a time around the first value of each list (the cost of a full grid is
// the product of the list lengths): sparse at every dense budget (first feature and radius
// scale), then every other feature scale and radius scale at the first budget; compression at
// every scheme × keep at the first bit depth, then every other bit depth at the middle keep;
// NWA and PBI at every term count.
std::vector<Point> SweepPoints(const Options& o) {
  std::vector<Point> pts;
  const auto sparse = [&](double b, double f, double rs) {
    Point p;
    p.family = "sparse";
    p.dense_budget = b;
    p.feature_scale = f;
    p.radius_scale = rs;
    pts.push_back(p);
  };
  if (!o.dense_budgets.empty() && !o.feature_scales.empty() && !o.radius_scales.empty()) {
    const double b0 = o.dense_budgets[0], f0 = o.feature_scales[0], r0 = o.radius_scales[0];
    for (double b : o.dense_budgets) sparse(b, f0, r0);
    for (std::size_t i = 1; i < o.feature_scales.size(); ++i) sparse(b0, o.feature_scales[i], r0);
    for (std::size_t i = 1; i < o.radius_scales.size(); ++i) sparse(b0, f0, o.radius_scales[i]);
  }
  const auto compression = [&](const std::string& s, double k, double bits) {
    Point p;
    p.family = s;
    p.keep = k;
    p.bits = static_cast<int>(bits);
    pts.push_back(p);
  };
  if (!o.bits.empty() && !o.keeps.empty()) {
    for (const std::string& s : o.schemes)
      for (double k : o.keeps) compression(s, k, o.bits[0]);
    for (std::size_t i = 1; i < o.bits.size(); ++i)
      for (const std::string& s : o.schemes) compression(s, o.keeps[o.keeps.size() / 2], o.bits[i]);
  }
  for (const char* mode : {"nwa", "pbi"})
    for (double t : o.terms) {
      Point p;
      p.family = mode;
      p.terms = static_cast<std::size_t>(t);
      pts.push_back(p);
    }
  return pts;
}

// ---- Summary: Pareto fronts, targets, the papers' operating points ----

using Getter = double (*)(const Record&);
double CpuOf(const Record& r) {
  return r.cpu_s;
}
double BytesOf(const Record& r) {
  return static_cast<double>(r.bytes);
}
double RelightOf(const Record& r) {
  return r.relight_ms;
}

// Points not dominated in (cost, err_mean): sorted by cost, each with less error than every
// cheaper one.
std::vector<const Record*> Pareto(std::vector<const Record*> pts, Getter cost) {
  std::sort(pts.begin(), pts.end(), [&](const Record* a, const Record* b) {
    return cost(*a) != cost(*b) ? cost(*a) < cost(*b) : a->err_mean < b->err_mean;
  });
  std::vector<const Record*> front;
  double best = INFINITY;
  for (const Record* p : pts)
    if (p->err_mean < best) {
      front.push_back(p);
      best = p->err_mean;
    }
  return front;
}

std::string Row(const Record& r, double brute_cpu) {
  std::ostringstream os;
  os << "| " << r.label << " | " << Fmt3(r.wall_s) << " | " << Fmt3(r.cpu_s) << " | "
     << (r.family == "brute" || r.family == "sparse" ? Fmt3(brute_cpu / r.cpu_s) + "×" : "")
     << " | " << Fmt3(static_cast<double>(r.rays)) << " | "
     << (r.sampled_fraction > 0 ? Percent(r.sampled_fraction) : "") << " | "
     << Fmt3(static_cast<double>(r.bytes)) << " | " << Fmt3(r.relight_ms) << " | "
     << Percent(r.err_t) << " | " << Percent(r.err_mean) << " | " << Percent(r.err_max) << " |\n";
  return os.str();
}
const char* kRowHeader =
    "| setting | wall s | CPU s | speed-up vs brute (CPU) | rays | sampled | bytes | relight ms "
    "| T rel. Frobenius | relit rel. RMS (mean) | (max over envs) |\n"
    "|---|---|---|---|---|---|---|---|---|---|---|\n";

// Bytes of the 2D points at error e, interpolated log-log between the two bracketing points.
std::optional<double> Interpolate(std::vector<const Record*> pts, double e, Getter cost) {
  std::sort(pts.begin(), pts.end(),
            [](const Record* a, const Record* b) { return a->err_mean < b->err_mean; });
  for (std::size_t k = 0; k + 1 < pts.size(); ++k) {
    const double e0 = pts[k]->err_mean, e1 = pts[k + 1]->err_mean;
    if (e0 > 0 && e >= e0 && e <= e1 && e1 > e0) {
      const double u = std::log(e / e0) / std::log(e1 / e0);
      return std::exp(std::log(cost(*pts[k])) + u * std::log(cost(*pts[k + 1]) / cost(*pts[k])));
    }
  }
  return std::nullopt;
}

std::string Summary(const std::vector<Record>& all, const std::vector<std::string>& scenes,
                    const std::vector<std::string>& envs, const std::string& command) {
  std::ostringstream md;
  md << "# prt-bench: run time against error\n\n"
     << "Command: `" << command << "`\n\n"
     << "Error = relative RMS of relit radiance (albedo ⊙ T·L, all samples) against the "
        "brute-force T under each environment (";
  for (std::size_t e = 0; e < envs.size(); ++e) md << (e ? ", " : "") << envs[e];
  md << "), mean over the environments; NWA/PBI: mean over frames of a rotation about +Y, "
        "through T compressed with the scene's default settings. Wall and CPU seconds (all threads "
        "and ranks) are those of the stage (tracing, compressing, or all rotation frames) in this "
        "run on this machine; the precomputation front uses CPU seconds, which a shared machine "
        "disturbs less. relight ms is one relighting, the fastest over the environments "
        "(brute/sparse: dense T·L in double on one thread; compression: Eq. 8 with dense "
        "lighting) or the median frame (NWA/PBI: one frame's update).\n";
  for (const std::string& scene : scenes) {
    std::vector<const Record*> rs;
    for (const Record& r : all)
      if (r.scene == scene) rs.push_back(&r);
    if (rs.empty()) continue;
    const Record* brute = nullptr;
    for (const Record* r : rs)
      if (r->family == "brute") brute = r;
    const double bw = brute != nullptr ? brute->wall_s : 0;
    const double bc = brute != nullptr ? brute->cpu_s : 0;
    auto family = [&](std::initializer_list<const char*> fams) {
      std::vector<const Record*> out;
      for (const Record* r : rs)
        for (const char* f : fams)
          if (r->family == f) out.push_back(r);
      return out;
    };
    md << "\n## " << scene << " (" << rs[0]->samples << " samples, n = " << rs[0]->n << ")\n";
    const auto pre = family({"brute", "sparse"});
    const auto size = family({"brute", "2d", "4d", "adaptive4d"});
    const auto relight = family({"brute", "2d", "4d", "adaptive4d", "nwa", "pbi"});
    const std::vector<std::pair<std::string, std::vector<const Record*>>> fronts = {
        {"precomputation CPU time vs error (brute force, sparse)", Pareto(pre, CpuOf)},
        {"bytes stored vs error (raw T, 2D, 4D, adaptive 4D)", Pareto(size, BytesOf)},
        {"relighting time vs error (compressed T with dense lighting, NWA, PBI)",
         Pareto(relight, RelightOf)}};
    for (const auto& [title, front] : fronts) {
      md << "\n### Pareto front: " << title << "\n\n" << kRowHeader;
      for (const Record* r : front) md << Row(*r, bc);
    }
    md << "\n### Cheapest setting under an error target\n\n"
          "| mean error ≤ | fastest precomputation | smallest storage | fastest relighting |\n"
          "|---|---|---|---|\n";
    for (double target : {0.005, 0.01, 0.02, 0.05, 0.1}) {
      md << "| " << Percent(target) << " |";
      const std::pair<const std::vector<const Record*>*, Getter> cols[] = {
          {&pre, CpuOf}, {&size, BytesOf}, {&relight, RelightOf}};
      for (const auto& [pts, cost] : cols) {
        const Record* best = nullptr;
        for (const Record* r : *pts)
          if (r->err_mean <= target && (best == nullptr || cost(*r) < cost(*best))) best = r;
        md << " " << (best != nullptr ? best->label + " (" + Fmt3(cost(*best)) + ")" : "none")
           << " |";
      }
      md << "\n";
    }
    // The papers' operating points, measured here.
    md << "\n### The papers' operating points, measured here\n\n";
    if (brute != nullptr) {
      const Record* near11 = nullptr;
      for (const Record* r : family({"sparse"}))
        if (near11 == nullptr ||
            std::abs(r->sampled_fraction - 0.11) < std::abs(near11->sampled_fraction - 0.11))
          near11 = r;
      if (near11 != nullptr)
        md << "- Huang & Ramamoorthi 2010 (~11% of T sampled, 4–5× faster, small error): closest "
              "here "
           << near11->label << ": " << Percent(near11->sampled_fraction) << " sampled, "
           << Fmt3(bw / near11->wall_s) << "× faster (wall), " << Fmt3(brute->cpu_s / near11->cpu_s)
           << "× (CPU), error " << Percent(near11->err_mean) << ".\n";
    }
    for (int b : {9}) {
      std::vector<const Record*> two, ad;
      for (const Record* r : family({"2d"}))
        if (r->bits == b) two.push_back(r);
      for (const Record* r : family({"adaptive4d"}))
        if (r->bits == b) ad.push_back(r);
      md << "- Cheslack-Postava et al. 2008 (adaptive 4D 2–3× smaller than 2D at equal error, " << b
         << " bits): ";
      bool any = false;
      for (const Record* a : ad) {
        if (const auto bytes2d = Interpolate(two, a->err_mean, BytesOf)) {
          md << (any ? "; " : "") << "at " << Percent(a->err_mean) << " 2D/adaptive size "
             << Fmt3(*bytes2d / static_cast<double>(a->bytes)) << "×";
          any = true;
        }
      }
      md << (any ? ".\n" : "no adaptive point within the 2D points' error range.\n");
    }
    const Record *pbi30 = nullptr, *nwa90 = nullptr;
    for (const Record* r : rs) {
      if (r->family == "pbi" && r->terms == 30) pbi30 = r;
      if (r->family == "nwa" && r->terms == 90) nwa90 = r;
    }
    if (pbi30 != nullptr && nwa90 != nullptr)
      md << "- Overbeck et al. 2006 (PBI-30 beats NWA-90 under a rotating environment): PBI-30 "
         << Percent(pbi30->err_mean) << " (" << Fmt3(pbi30->relight_ms) << " ms/frame) against "
         << "NWA-90 " << Percent(nwa90->err_mean) << " (" << Fmt3(nwa90->relight_ms)
         << " ms/frame).\n";
    md << "\n### Every point\n\n" << kRowHeader;
    for (const Record* r : rs) md << Row(*r, bc);
  }
  return md.str();
}

// ---- Plots (gnuplot) ----

void WriteDat(const std::string& path, const std::vector<const Record*>& pts, Getter cost) {
  std::ofstream f(path);
  for (const Record* r : pts)
    if (r->err_mean > 0) f << Fmt(cost(*r)) << ' ' << Fmt(r->err_mean) << ' ' << r->terms << '\n';
}

bool Plot(const std::vector<Record>& all, const std::string& scene, const std::string& dir) {
  std::vector<const Record*> rs;
  for (const Record& r : all)
    if (r.scene == scene) rs.push_back(&r);
  const Record* brute = nullptr;
  for (const Record* r : rs)
    if (r->family == "brute") brute = r;
  if (brute == nullptr) return false;
  auto of = [&](const std::string& fam, int bits = -1) {
    std::vector<const Record*> out;
    for (const Record* r : rs)
      if (r->family == fam && (bits < 0 || r->bits == bits)) out.push_back(r);
    return out;
  };
  std::set<int> bit_set;
  for (const Record* r : rs)
    if (r->bits > 0) bit_set.insert(r->bits);
  const std::string base = dir + "/" + scene;
  std::ostringstream gp;
  gp << "set terminal pngcairo size 900,700 noenhanced\nset logscale xy\nset grid\nset key below "
        "maxrows 4 font ',10'\nset ylabel 'relit relative RMS error (mean over environments)'\n";
  // 1. Precomputation time (only with sparse points: gnuplot stops the whole script at a plot
  // of an empty file, which lost the size and relighting plots of a compression-only sweep).
  WriteDat(base + "_sparse_time.dat", of("sparse"), CpuOf);
  double max_cpu = brute->cpu_s;
  for (const Record* r : of("sparse")) max_cpu = std::max(max_cpu, r->cpu_s);
  if (!of("sparse").empty())
    gp << "set output '" << base << "_time_error.png'\nset title '" << scene
       << ": precomputation time vs error (n = " << brute->n << ")'\n"
       << "set xrange [" << Fmt(brute->cpu_s / 6) << ":" << Fmt(max_cpu * 1.5) << "]\n"
       << "set xlabel 'CPU seconds, all threads (brute force " << Fmt3(brute->cpu_s) << " s)'\n"
       << "set arrow 1 from " << Fmt(brute->cpu_s) << ", graph 0 to " << Fmt(brute->cpu_s)
       << ", graph 1 nohead lw 2 lc rgb 'black'\n"
       << "set label 1 'brute force (exact)' at " << Fmt(brute->cpu_s) << ", graph 0.95 right "
       << "offset -0.5,0\n"
       << "set arrow 2 from " << Fmt(brute->cpu_s / 5) << ", graph 0 to " << Fmt(brute->cpu_s / 4)
       << ", graph 0 nohead lw 8 lc rgb '#cc0000'\n"
       << "set label 2 'Huang 2010: 4-5x faster at ~11% sampled' at " << Fmt(brute->cpu_s / 5)
       << ", graph 0.06 tc rgb '#cc0000'\n"
       << "plot '" << base << "_sparse_time.dat' u 1:2 w p pt 7 ps 1.3 t 'sparse (budget, "
       << "features, radius sweep)'\nunset arrow\nunset label\nset autoscale x\n";
  // 2. Size.
  gp << "set output '" << base << "_size_error.png'\nset title '" << scene
     << ": bytes stored vs error'\nset format x '%.0s%c'\nset xlabel 'bytes (raw float T = "
     << Fmt3(static_cast<double>(brute->bytes)) << ")'\nplot ";
  bool first = true;
  int pt = 4;
  for (const char* fam : {"2d", "4d", "adaptive4d"}) {
    for (int b : bit_set) {
      const std::string dat = base + "_" + fam + "_" + std::to_string(b) + "_size.dat";
      WriteDat(dat, of(fam, b), BytesOf);
      gp << (first ? "" : ", ") << "'" << dat << "' u 1:2 w lp pt " << pt << " t '" << fam << " "
         << b << " bits'";
      first = false;
      ++pt;
    }
  }
  // Cheslack-Postava 2008: adaptive 4D 2-3x smaller than 2D at equal error (9 bits).
  if (!of("2d", 9).empty()) {
    const std::string dat = base + "_cp2008.dat";
    std::ofstream f(dat);
    std::vector<const Record*> two = of("2d", 9);
    std::sort(two.begin(), two.end(),
              [](const Record* a, const Record* b) { return a->bytes < b->bytes; });
    for (const Record* r : two)
      if (r->err_mean > 0)
        f << Fmt(static_cast<double>(r->bytes) / 2.5) << ' ' << Fmt(r->err_mean) << '\n';
    gp << ", '" << dat << "' u 1:2 w l dt 2 lw 2 lc rgb '#cc0000' t 'Cheslack-Postava 2008: 2D "
       << "9 bits / 2.5 (adaptive 4D 2-3x smaller)'";
  }
  gp << "\n";
  // 3. Relighting time.
  gp << "set output '" << base << "_relight_error.png'\nset title '" << scene
     << ": relighting time vs error'\nset format x '%g'\nset xlabel 'ms per relighting'\nplot ";
  first = true;
  pt = 4;
  for (const char* fam : {"2d", "4d", "adaptive4d"}) {
    const std::string dat = base + "_" + fam + "_relight.dat";
    WriteDat(dat, of(fam, 9), RelightOf);
    gp << (first ? "" : ", ") << "'" << dat << "' u 1:2 w p pt " << pt++ << " t '" << fam
       << " 9 bits, dense lighting'";
    first = false;
  }
  for (const char* fam : {"nwa", "pbi"}) {
    const std::string dat = base + "_" + fam + "_relight.dat";
    WriteDat(dat, of(fam), RelightOf);
    gp << ", '" << dat << "' u 1:2 w lp pt " << pt++ << " t '" << fam
       << "-N, rotating', '' u 1:2:3 w labels offset 1.2,0.6 notitle";
  }
  // Overbeck 2006: PBI-30 beats NWA-90.
  {
    const std::string dat = base + "_overbeck.dat";
    std::ofstream f(dat);
    for (const Record* r : rs)
      if ((r->family == "pbi" && r->terms == 30) || (r->family == "nwa" && r->terms == 90))
        f << Fmt(r->relight_ms) << ' ' << Fmt(r->err_mean) << '\n';
    gp << ", '" << dat << "' u 1:2 w p pt 6 ps 3 lw 2 lc rgb '#cc0000' t 'Overbeck 2006: PBI-30 "
       << "below NWA-90'";
  }
  gp << "\n";
  const std::string script = base + "_plots.gp";
  std::ofstream(script) << gp.str();
  if (std::system("command -v gnuplot >/dev/null 2>&1") != 0) return false;
  if (std::system(("gnuplot '" + script + "' 2>/dev/null").c_str()) == 0) return true;
  // pngcairo may be missing from a minimal gnuplot: the plain png terminal.
  std::string s = gp.str();
  s.replace(s.find("pngcairo"), 8, "png");
  std::ofstream(script) << s;
  return std::system(("gnuplot '" + script + "' 2>/dev/null").c_str()) == 0;
}

// ---- --check and --compare ----

// Sanity of an output folder; returns the problems found (empty: fine).
std::vector<std::string> CheckOutputs(const std::string& dir) {
  std::vector<std::string> bad;
  const std::string csv_path = dir + "/prt_bench.csv";
  CsvFile csv;
  try {
    csv = ReadCsv(csv_path);
  } catch (const std::exception& e) {
    return {e.what()};
  }
  std::ifstream md(dir + "/prt_bench.md");
  std::stringstream mds;
  mds << md.rdbuf();
  if (!md || mds.str().find("### Pareto front") == std::string::npos)
    bad.push_back(dir + "/prt_bench.md: missing or without a Pareto front");
  if (csv.records.empty()) bad.push_back(csv_path + ": no rows");
  std::map<std::string, int> brutes;
  std::map<std::string, std::vector<const Record*>> curves;  // scene/scheme/bits → points
  for (const Record& r : csv.records) {
    const std::string where = csv_path + ": " + r.scene + " '" + r.label + "'";
    std::vector<double> errs = r.err_env;
    errs.insert(errs.end(), {r.err_t, r.err_mean, r.err_max});
    for (double e : errs)
      if (!std::isfinite(e) || e < 0) bad.push_back(where + ": error " + Fmt(e));
    if (!std::isfinite(r.wall_s) || r.wall_s < 0 || !std::isfinite(r.relight_ms) ||
        r.relight_ms < 0)
      bad.push_back(where + ": bad timing");
    if (r.bytes == 0) bad.push_back(where + ": 0 bytes stored");
    if (r.family == "brute") {
      ++brutes[r.scene];
      if (r.err_mean != 0 || r.err_max != 0 || r.err_t != 0)
        bad.push_back(where + ": brute-force error is not 0");
      if (r.rays == 0) bad.push_back(where + ": brute force traced no ray");
    }
    if (r.family == "sparse" &&
        (r.rays == 0 || r.sampled_fraction <= 0 || r.sampled_fraction > 1.0 + 1e-9))
      bad.push_back(where + ": sparse rays/sampled fraction out of range");
    if (r.family == "2d" || r.family == "4d" || r.family == "adaptive4d") {
      curves[r.scene + " " + r.family + " " + std::to_string(r.bits) + " bits"].push_back(&r);
      if (r.err_mean >= 1) bad.push_back(where + ": compression error ≥ 100%");
    }
  }
  for (const auto& [scene, count] : brutes)
    if (count != 1)
      bad.push_back(csv_path + ": " + scene + " has " + std::to_string(count) +
                    " brute-force rows");
  // More budget → not more error (a 1% relative allowance for the dithered quantisation).
  for (auto& [name, pts] : curves) {
    std::sort(pts.begin(), pts.end(),
              [](const Record* a, const Record* b) { return a->keep < b->keep; });
    for (std::size_t k = 1; k < pts.size(); ++k)
      if (pts[k]->err_mean > pts[k - 1]->err_mean * 1.01 + 1e-7)
        bad.push_back(csv_path + ": " + name + ": keep " + Fmt(pts[k]->keep) + " has error " +
                      Fmt(pts[k]->err_mean) + " > keep " + Fmt(pts[k - 1]->keep) + "'s " +
                      Fmt(pts[k - 1]->err_mean));
  }
  return bad;
}

// Every non-timing column of two outputs equal; returns the differences.
std::vector<std::string> CompareOutputs(const std::string& a, const std::string& b) {
  const CsvFile ca = ReadCsv(a + "/prt_bench.csv"), cb = ReadCsv(b + "/prt_bench.csv");
  std::vector<std::string> bad;
  if (ca.columns != cb.columns) return {"different CSV columns"};
  if (ca.lines.size() != cb.lines.size()) return {"different row counts"};
  for (std::size_t i = 0; i < ca.lines.size(); ++i) {
    const auto fa = SplitList(ca.lines[i]), fb = SplitList(cb.lines[i]);
    for (std::size_t c = 0; c < ca.columns.size(); ++c)
      if (!IsTimingColumn(ca.columns[c]) && fa[c] != fb[c])
        bad.push_back("row " + std::to_string(i + 2) + " (" + fa[4] + ") " + ca.columns[c] + ": " +
                      fa[c] + " vs " + fb[c]);
  }
  return bad;
}

int Report(const std::vector<std::string>& bad, const std::string& what) {
  for (const std::string& s : bad) std::fprintf(stderr, "prt-bench: %s\n", s.c_str());
  std::printf("%s: %s\n", what.c_str(),
              bad.empty() ? "ok" : (std::to_string(bad.size()) + " problem(s)").c_str());
  return bad.empty() ? 0 : 1;
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  std::string scenes = "default,armadillo,dragon", envs = "sunrise,city,studio,interior";
  std::string out_dir = "bench-out/prt-bench", check_dir;
  std::vector<std::string> compare_dirs, merge_dirs;
  std::string budgets = "0.25,0.1", fscales = "1,0.5", rscales = "1,2";
  std::string schemes = "2d,4d,adaptive4d", keeps = "0.01,0.03,0.1", bits = "9,6,12";
  std::string terms = "10,30,90,300";
  bool quick = false, self_check = false;
  int threads = 0;
  CLI::App app{"prt-bench: run time against error for every setting (docs/benchmarks.md)"};
  app.add_option("--scenes", scenes, "comma-separated: default, armadillo, dragon, camel");
  app.add_option("--envs", envs, "environment maps (data folder envmaps/NAME.exr)");
  app.add_option("--n", o.n, "cubemap resolution");
  app.add_option("--rays", o.rays, "rays per texel (0: the scene's)");
  app.add_option("--ground", o.ground, "ground grid vertices per side (0: the scene's 64)");
  app.add_option("--out", out_dir, "output folder (CSV, summary, plots)");
  app.add_option("--threads", threads, "TBB threads per rank (0: cores / ranks)");
  app.add_option("--dense-budgets", budgets, "sparse: dense-vertex fractions (first: the centre)");
  app.add_option("--feature-scales", fscales, "sparse: feature counts × the scene's");
  app.add_option("--radius-scales", rscales, "sparse: radius × the scene's");
  app.add_option("--schemes", schemes, "compression schemes: 2d, 4d, adaptive4d");
  app.add_option("--keeps", keeps, "compression keep fractions");
  app.add_option("--bits", bits, "quantisation bit depths (first: the centre)");
  app.add_option("--terms", terms, "NWA/PBI terms per frame");
  app.add_option("--frames", o.frames, "NWA/PBI: rotating frames");
  app.add_option("--deg", o.deg, "NWA/PBI: rotation per frame, degrees");
  app.add_flag("--quick", quick,
               "CI size: the dragon on a 16×16 ground, n = 8, 1 ray/texel, sunrise and city, one "
               "sparse point, 2D/4D/adaptive 4D at three budgets, NWA and PBI at 30 and 90 terms");
  app.add_flag("--self-check", self_check, "check the outputs after writing them (as --check)");
  app.add_option("--check", check_dir, "only check an output folder");
  app.add_option("--compare", compare_dirs, "only compare two output folders")->expected(2);
  app.add_option("--merge", merge_dirs,
                 "only merge output folders' CSVs (same environments) into --out: CSV, summary, "
                 "plots")
      ->expected(1, 64);
  CLI11_PARSE(app, argc, argv);
  if (!check_dir.empty()) return Report(CheckOutputs(check_dir), "check " + check_dir);
  if (!compare_dirs.empty()) {
    try {
      return Report(CompareOutputs(compare_dirs[0], compare_dirs[1]),
                    "compare " + compare_dirs[0] + " " + compare_dirs[1]);
    } catch (const std::exception& e) {
      return Report({e.what()}, "compare");
    }
  }
  if (!merge_dirs.empty()) {
    try {
      std::vector<std::string> merged_envs, merged_scenes, lines;
      std::vector<Record> merged;
      for (const std::string& d : merge_dirs) {
        const CsvFile c = ReadCsv(d + "/prt_bench.csv");
        if (!merged_envs.empty() && c.envs != merged_envs)
          throw std::runtime_error(d + "/prt_bench.csv: other environments than " + merge_dirs[0]);
        merged_envs = c.envs;
        merged.insert(merged.end(), c.records.begin(), c.records.end());
        lines.insert(lines.end(), c.lines.begin(), c.lines.end());
        for (const Record& r : c.records)
          if (std::find(merged_scenes.begin(), merged_scenes.end(), r.scene) == merged_scenes.end())
            merged_scenes.push_back(r.scene);
      }
      fs::create_directories(out_dir + "/plots");
      std::ofstream csv(out_dir + "/prt_bench.csv");
      csv << CsvHeader(merged_envs) << '\n';
      for (const std::string& l : lines) csv << l << '\n';
      csv.close();
      std::string command = "prt-bench";
      for (int i = 1; i < argc; ++i) command += std::string(" ") + argv[i];
      std::ofstream(out_dir + "/prt_bench.md")
          << Summary(merged, merged_scenes, merged_envs, command);
      for (const std::string& sc : merged_scenes) Plot(merged, sc, out_dir + "/plots");
      return Report(CheckOutputs(out_dir), "merge into " + out_dir);
    } catch (const std::exception& e) {
      return Report({e.what()}, "merge");
    }
  }
  if (quick) {
    const auto set = [&](const char* opt, std::string& var, const char* value) {
      if (app.count(opt) == 0) var = value;
    };
    set("--scenes", scenes, "dragon");
    if (app.count("--ground") == 0) o.ground = 16;
    set("--envs", envs, "sunrise,city");
    if (app.count("--n") == 0) o.n = 8;
    if (app.count("--rays") == 0) o.rays = 1;
    if (app.count("--frames") == 0) o.frames = 8;
    if (app.count("--deg") == 0) o.deg = 2;
    set("--dense-budgets", budgets, "0.25");
    set("--feature-scales", fscales, "1");
    set("--radius-scales", rscales, "1");
    set("--keeps", keeps, "0.01,0.03,0.1");
    set("--bits", bits, "9");
    set("--terms", terms, "30,90");
  }
  o.scenes = SplitList(scenes);
  o.envs = SplitList(envs);
  o.dense_budgets = Numbers(budgets);
  o.feature_scales = Numbers(fscales);
  o.radius_scales = Numbers(rscales);
  o.schemes = SplitList(schemes);
  o.keeps = Numbers(keeps);
  o.bits = Numbers(bits);
  o.terms = Numbers(terms);
  o.eval_every = std::max(1, o.frames / 6);

  std::optional<MpiSession> session;
  try {
    session.emplace(&argc, &argv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "prt-bench: %s\n", e.what());
    return 2;
  }
  const MpiSession& mpi = *session;
  const int rank = mpi.rank(), size = mpi.size();
  if (threads <= 0)
    threads = std::max(1, static_cast<int>(std::thread::hardware_concurrency()) / size);
  const tbb::global_control gc(tbb::global_control::max_allowed_parallelism, threads);
  std::string command = "prt-bench";
  for (int i = 1; i < argc; ++i) command += std::string(" ") + argv[i];
  if (size > 1) command = "mpirun -np " + std::to_string(size) + " " + command;

  int rc = 0;
  std::vector<Record> records;
  try {
    const std::vector<bench::NamedEnvironment> env_cubes = bench::BenchEnvironments(o.n, o.envs);
    const std::vector<Point> points = SweepPoints(o);
    // Outputs are rewritten after every scene, so that a long sweep cut short keeps its scenes.
    std::vector<std::pair<std::pair<std::size_t, std::size_t>, std::string>> rows;
    for (std::size_t si = 0; si < o.scenes.size(); ++si) {
      std::ostringstream mine;  // "scene index<TAB>csv" lines of this rank
      SceneBench sb(o.scenes[si], o, env_cubes);
      if (rank == 0)
        std::printf("== %s: %zu samples, n = %d, %d ray(s)/texel, %zu points on %d rank(s) ==\n",
                    o.scenes[si].c_str(), sb.samples(), o.n, sb.rays_per_texel(), points.size() + 1,
                    size);
      Record brute = sb.TraceBrute(mpi);
      Finish(brute);
      if (rank == 0) {
        mine << si << ' ' << 0 << '\t' << ToCsv(brute) << '\n';
        std::printf("  brute force: %.2f s wall, %.2f s CPU, %.3g rays\n", brute.wall_s,
                    brute.cpu_s, static_cast<double>(brute.rays));
        std::fflush(stdout);
      }
      for (std::size_t i = 0; i < points.size(); ++i) {
        if (static_cast<int>(i % static_cast<std::size_t>(size)) != rank) continue;
        Record r = sb.Run(points[i]);
        Finish(r);
        std::printf("  [rank %d] %-44s %8.2f s wall %8.2f s CPU %10.4g B %8.3f ms  err %.4g%%\n",
                    rank, r.label.c_str(), r.wall_s, r.cpu_s, static_cast<double>(r.bytes),
                    r.relight_ms, 100 * r.err_mean);
        std::fflush(stdout);
        mine << si << ' ' << i + 1 << '\t' << ToCsv(r) << '\n';
      }
      const std::string all = mpi.GatherText(mine.str());
      if (rank != 0) continue;
      for (const std::string& line : SplitList(all, '\n')) {
        if (line.empty()) continue;
        const auto tab = line.find('\t');
        std::size_t gsi = 0, pi = 0;
        std::sscanf(line.c_str(), "%zu %zu", &gsi, &pi);
        rows.push_back({{gsi, pi}, line.substr(tab + 1)});
      }
      std::sort(rows.begin(), rows.end());
      fs::create_directories(out_dir + "/plots");
      std::ofstream csv(out_dir + "/prt_bench.csv");
      csv << CsvHeader(o.envs) << '\n';
      records.clear();
      for (const auto& [key, line] : rows) {
        csv << line << '\n';
        records.push_back(FromCsv(line, o.envs.size(), "gathered row"));
      }
      csv.close();
      std::ofstream(out_dir + "/prt_bench.md") << Summary(records, o.scenes, o.envs, command);
      const bool plotted = Plot(records, o.scenes[si], out_dir + "/plots");
      std::printf("wrote %s/prt_bench.csv, %s/prt_bench.md%s\n", out_dir.c_str(), out_dir.c_str(),
                  plotted ? " and plots" : " (no plots: gnuplot failed)");
      std::fflush(stdout);
    }
    if (rank == 0 && self_check) rc = Report(CheckOutputs(out_dir), "check " + out_dir);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "prt-bench (rank %d): %s\n", rank, e.what());
    mpi.Abort(1);
  }
  return mpi.Broadcast(rc);
}
