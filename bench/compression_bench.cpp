// compression_bench: storage against relit-radiance error for 2D (Ng et al. 2003), full 4D and
// adaptive 4D compression of real transport matrices (Cheslack-Postava et al. 2008 §5.2, Fig. 7
// and Fig. 8), all through the same code (worker/transport_compressor.h).
//
// For each benchmark scene (the default scene, i.e. the bunny on a 64×64 ground grid, and real
// meshes in its place on the same ground: dragon, armadillo, camel, lion from the data folder;
// horse and teapot from ../shared/data, PRT_SHARED_DATA_DIR) and cubemap size n, T is traced here
// with TransportSampler (or read from a cache file written by an earlier run, or from a farm run
// folder). For each scheme, budget (column: the paper's N terms per column, 2D per row; global:
// one magnitude threshold over the matrix) and keep fraction it prints the stored terms, the
// encoded bytes of transport.prtc (and % of raw float32 T), the relative Frobenius error of T, and
// the relative RMS error of relit radiance B = albedo ⊙ (T·L) over the real environment maps
// (every channel of every environment together), B computed from the compressed columns by Eq. 8
// and the reference from the uncompressed T in double. Then, per scene and n:
//   * the matched-error table: bytes of each curve at relit errors 1%, 2%, 5% (log-log
//     interpolation between measured points; "-" outside the measured range) and the ratio
//     best 2D / adaptive 4D, plus the smallest such ratio over the errors both reach;
//   * the average chosen column depth per row-transform level (Fig. 8);
//   * with --out DIR: DIR/<scene>_n<n>.csv, a gnuplot script and its PNG (Fig. 7-like curves).
//
// Usage: compression_bench [--scenes default,dragon,armadillo,horse,teapot] [--n 32,64] [--rays K]
//          [--cache DIR] [--run DIR] [--bits B] [--keep f1,f2,...] [--budget column|global|both]
//          [--column-keep f1,...] [--schemes 2d,4d,adaptive4d] [--light-weight W] [--t-error]
//          [--order-normal-weight W] [--column-wavelet legall53|cdf97] [--row-wavelet haar|d4]
//          [--out DIR]
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "bench/bench_scene.h"
#include "bench/bench_transport.h"
#include "formats/compressed_transport.h"
#include "runtime/compressed_relight.h"
#include "vocabulary/cubemap_resample.h"
#include "vocabulary/environment_io.h"
#include "vocabulary/envmap.h"
#include "vocabulary/errors.h"
#include "vocabulary/scene.h"
#include "vocabulary/tbb_parallel.h"
#include "worker/row_transform.h"
#include "worker/transport_compressor.h"

namespace {

using Clock = std::chrono::steady_clock;
double Seconds(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

using prt::bench::DataDir;

using Transport = prt::bench::BenchTransport;

template <class T>
std::vector<T> SplitList(const std::string& s) {
  std::vector<T> v;
  std::stringstream ss(s);
  std::string item;
  while (std::getline(ss, item, ',')) {
    if (item.empty()) continue;
    if constexpr (std::is_same_v<T, std::string>)
      v.push_back(item);
    else
      v.push_back(static_cast<T>(std::atof(item.c_str())));
  }
  return v;
}

struct Point {
  prt::CompressionScheme scheme;
  prt::CompressionBudget budget;
  double keep = 0;
  std::size_t terms = 0, bytes = 0;
  double pct_raw = 0, t_err = 0, b_err = 0, secs = 0;
};

std::string CurveName(prt::CompressionScheme s, prt::CompressionBudget b) {
  return std::string(prt::ToString(s)) + "/" + prt::ToString(b);
}

// Bytes of a curve at relit error e: log-log interpolation between the two measured points
// around e (points sorted by error); < 0 outside the measured range.
double BytesAtError(std::vector<Point> pts, double e) {
  std::sort(pts.begin(), pts.end(),
            [](const Point& a, const Point& b) { return a.b_err < b.b_err; });
  // The lower envelope: for each error, the fewest bytes reaching it.
  double best = -1;
  for (std::size_t i = 0; i + 1 < pts.size(); ++i) {
    const Point &a = pts[i], &b = pts[i + 1];
    if (e < a.b_err || e > b.b_err || a.b_err <= 0) continue;
    const double t = b.b_err > a.b_err ? std::log(e / a.b_err) / std::log(b.b_err / a.b_err) : 0;
    const double v =
        std::exp(std::log(static_cast<double>(a.bytes)) +
                 t * std::log(static_cast<double>(b.bytes) / static_cast<double>(a.bytes)));
    if (best < 0 || v < best) best = v;
  }
  if (pts.size() == 1 && std::fabs(pts[0].b_err - e) < 1e-12)
    best = static_cast<double>(pts[0].bytes);
  return best;
}

void RunOne(const Transport& tr, const std::vector<prt::CompressionScheme>& schemes,
            const std::vector<prt::CompressionBudget>& budgets, const std::vector<double>& keeps,
            const std::vector<double>& column_keeps, int bits, int light_weight, bool t_error,
            prt::ColumnWavelet column_wavelet, prt::RowWavelet row_wavelet,
            const std::string& out_dir) {
  const int n = tr.n;
  const std::size_t S = tr.S, M = static_cast<std::size_t>(6) * n * n;
  const double raw_bytes = static_cast<double>(S * M) * 4.0;
  std::printf(
      "\n=== %s, n = %d: %zu samples x %zu texels, %zu segments (mesh order normal weight %g), "
      "row wavelet %s, column wavelet %s, raw %.1f MB\n",
      tr.source.c_str(), n, S, M, tr.domain.segments.size(), tr.order_normal_weight,
      prt::ToString(row_wavelet), prt::ToString(column_wavelet), raw_bytes / 1e6);
  // The real environment maps (Blender's), resampled to the cubemap.
  std::vector<std::vector<float>> lights;
  std::printf("environments:");
  for (const char* e : {"sunrise", "city", "studio", "interior"}) {
    const prt::CubemapRgb cube =
        prt::ResampleToCubemap(prt::ReadEnvironment(DataDir() + "/envmaps/" + e + ".exr"), n);
    std::printf(" %s", e);
    std::vector<float> L;
    for (int c = 0; c < 3; ++c) L.insert(L.end(), cube.Channel(c).begin(), cube.Channel(c).end());
    lights.push_back(std::move(L));
  }
  std::printf("\n");
  // Reference B = albedo ⊙ (T·L) from the uncompressed T, in double.
  std::vector<std::vector<double>> ref(lights.size(), std::vector<double>(3 * S));
  double ref_energy = 0;
  for (std::size_t e = 0; e < lights.size(); ++e)
    for (int c = 0; c < 3; ++c)
      for (std::size_t s = 0; s < S; ++s) {
        double a = 0;
        const float* row = tr.T.data() + s * M;
        const float* L = lights[e].data() + c * M;
        for (std::size_t j = 0; j < M; ++j) a += static_cast<double>(row[j]) * L[j];
        a *= tr.albedo[3 * s + c];
        ref[e][c * S + s] = a;
        ref_energy += a * a;
      }
  double t_energy = 0;
  for (float v : tr.T) t_energy += static_cast<double>(v) * v;

  const std::vector<uint8_t> row_levels = prt::RowCoefficientLevels(n);
  const int row_depth = prt::RowTransformDepth(n);
  std::printf("%-11s %-7s %7s %10s %10s %7s %9s %9s %7s\n", "scheme", "budget", "keep", "terms",
              "bytes", "%raw", "T_relF", "B_relRMS", "time_s");
  std::vector<Point> points;
  std::vector<std::string> depth_lines, level_lines;
  // The stages of CompressTransport (transport_compressor.h), run so that what does not depend on
  // the keep fraction is done once: the row transform, the transpose, and the column transforms
  // of 2D and full 4D (adaptive depths depend on the per-column budget, so adaptive 4D and the
  // per-row 2D truncation are redone per keep). Same functions, same bytes as CompressTransport.
  std::vector<float> rows_hat(tr.T);
  {
    prt::CompressionOptions o;
    o.budget = prt::CompressionBudget::kGlobal;  // no per-row truncation here
    o.row_wavelet = row_wavelet;
    prt::PrepareRows(prt::MakeCompressedHeader(o, n, tr.domain), o, rows_hat.data(), S);
  }
  const std::vector<float> cols_hat = prt::bench::TransposeRows(rows_hat, S, M);
  for (prt::CompressionBudget budget : budgets)
    for (prt::CompressionScheme scheme : schemes) {
      prt::bench::FixedColumns fixed;  // 2D / 4D columns transformed once
      for (double keep : budget == prt::CompressionBudget::kColumn ? column_keeps : keeps) {
        prt::CompressionOptions o;
        o.scheme = scheme;
        o.keep_fraction = keep;
        o.bits = bits;
        o.budget = budget;
        o.light_weight = light_weight;
        o.column_wavelet = column_wavelet;
        o.row_wavelet = row_wavelet;
        const prt::CompressedTransportHeader h = prt::MakeCompressedHeader(o, n, tr.domain);
        std::vector<prt::ColumnStats> stats;
        const auto t0 = Clock::now();
        const prt::CompressedTransport ct =
            prt::bench::CompressPreparedColumns(h, o, rows_hat, cols_hat, fixed, &stats);
        Point p;
        p.secs = Seconds(t0);
        p.scheme = scheme;
        p.budget = budget;
        p.keep = keep;
        p.terms = ct.term_count();
        p.bytes = prt::EncodeCompressedTransport(ct).size();
        p.pct_raw = 100.0 * static_cast<double>(p.bytes) / raw_bytes;
        const prt::CompressedRelighter relighter(ct);
        double err = 0;
        std::vector<float> B(3 * S);
        for (std::size_t e = 0; e < lights.size(); ++e) {
          relighter.Relight(prt::LightingToRowWaveletBasis(o.row_wavelet, n, lights[e], 3), 3, B);
          for (int c = 0; c < 3; ++c)
            for (std::size_t s = 0; s < S; ++s) {
              const double d = B[c * S + s] * tr.albedo[3 * s + c] - ref[e][c * S + s];
              err += d * d;
            }
        }
        p.b_err = std::sqrt(err / ref_energy);
        if (t_error) {
          const std::vector<float> back = prt::DecompressTransport(ct);
          double terr = 0;
          for (std::size_t i = 0; i < back.size(); ++i) {
            const double d = static_cast<double>(back[i]) - tr.T[i];
            terr += d * d;
          }
          p.t_err = std::sqrt(terr / t_energy);
        }
        std::printf("%-11s %-7s %7.4f %10zu %10zu %7.3f %9.5f %9.5f %7.1f\n", prt::ToString(scheme),
                    prt::ToString(budget), keep, p.terms, p.bytes, p.pct_raw, p.t_err, p.b_err,
                    p.secs);
        std::fflush(stdout);
        points.push_back(p);
        {
          // Where the stored terms go: share by row-transform level.
          std::vector<double> per_level(row_depth + 1, 0.0);
          for (const auto& st : stats) per_level[row_levels[st.column]] += st.stored_terms;
          std::ostringstream os;
          char buf[64];
          std::snprintf(buf, sizeof buf, "%-11s %-7s keep %7.4f:", prt::ToString(scheme),
                        prt::ToString(budget), keep);
          os << buf;
          for (int l = 0; l <= row_depth; ++l) {
            std::snprintf(buf, sizeof buf, " %5.1f%%",
                          p.terms > 0 ? 100.0 * per_level[l] / static_cast<double>(p.terms) : 0.0);
            os << buf;
          }
          level_lines.push_back(os.str());
        }
        if (scheme == prt::CompressionScheme::kAdaptive4D) {
          std::vector<double> sum(row_depth + 1, 0.0), cnt(row_depth + 1, 0.0);
          for (const auto& st : stats) {
            sum[row_levels[st.column]] += st.depth;
            cnt[row_levels[st.column]] += 1;
          }
          std::ostringstream os;
          char buf[64];
          std::snprintf(buf, sizeof buf, "%-7s keep %7.4f:", prt::ToString(budget), keep);
          os << buf;
          for (int l = 0; l <= row_depth; ++l) {
            std::snprintf(buf, sizeof buf, " %6.2f", cnt[l] > 0 ? sum[l] / cnt[l] : 0.0);
            os << buf;
          }
          depth_lines.push_back(os.str());
        }
      }
    }

  // Matched-error table.
  std::map<std::string, std::vector<Point>> curves;
  for (const Point& p : points) curves[CurveName(p.scheme, p.budget)].push_back(p);
  auto best_of = [&](prt::CompressionScheme s, double e) {
    double best = -1;
    for (prt::CompressionBudget b : budgets) {
      const auto it = curves.find(CurveName(s, b));
      if (it == curves.end()) continue;
      const double v = BytesAtError(it->second, e);
      if (v > 0 && (best < 0 || v < best)) best = v;
    }
    return best;
  };
  const double targets[] = {0.01, 0.02, 0.05};
  std::printf("\nmatched relit error (%s, n = %d): bytes (%% of raw) by curve\n", tr.name.c_str(),
              n);
  std::printf("%-20s", "curve");
  for (double e : targets) std::printf("   %18.0f%%", 100 * e);
  std::printf("\n");
  for (const auto& [name, pts] : curves) {
    std::printf("%-20s", name.c_str());
    for (double e : targets) {
      const double v = BytesAtError(pts, e);
      if (v > 0)
        std::printf("   %10.0f (%5.3f%%)", v, 100 * v / raw_bytes);
      else
        std::printf("   %18s", "-");
    }
    std::printf("\n");
  }
  std::printf("%-20s", "best 2D / adaptive4d");
  for (double e : targets) {
    const double a = best_of(prt::CompressionScheme::kAdaptive4D, e);
    const double d = best_of(prt::CompressionScheme::k2D, e);
    if (a > 0 && d > 0)
      std::printf("   %17.2fx", d / a);
    else
      std::printf("   %18s", "-");
  }
  std::printf("\n");
  // Smallest ratio over the errors both curves reach (50 log-spaced errors).
  double lo = 1e30, hi = 0, lo2 = 1e30, hi2 = 0;
  for (const Point& p : points) {
    if (p.scheme == prt::CompressionScheme::kAdaptive4D)
      lo = std::min(lo, p.b_err), hi = std::max(hi, p.b_err);
    if (p.scheme == prt::CompressionScheme::k2D)
      lo2 = std::min(lo2, p.b_err), hi2 = std::max(hi2, p.b_err);
  }
  lo = std::max(lo, lo2);
  hi = std::min(hi, hi2);
  if (lo < hi) {
    double min_ratio = 1e30, at = 0;
    for (int i = 0; i <= 50; ++i) {
      const double e = lo * std::pow(hi / lo, i / 50.0);
      const double a = best_of(prt::CompressionScheme::kAdaptive4D, e);
      const double d = best_of(prt::CompressionScheme::k2D, e);
      if (a > 0 && d > 0 && d / a < min_ratio) min_ratio = d / a, at = e;
    }
    std::printf(
        "smallest best-2D / adaptive4d ratio over relit errors %.4f..%.4f: %.2fx (at %.4f)\n", lo,
        hi, min_ratio, at);
  }
  std::printf("\nstored terms by row-transform level (0 = scaling … %d = finest):\n", row_depth);
  for (const auto& l : level_lines) std::printf("  %s\n", l.c_str());
  std::printf(
      "\naverage adaptive column depth by row-transform level (Fig. 8; 0 = scaling … %d ="
      " finest; max depth %d):\n",
      row_depth, prt::MaxColumnDepth(tr.domain));
  for (const auto& l : depth_lines) std::printf("  %s\n", l.c_str());
  std::fflush(stdout);

  if (out_dir.empty()) return;
  std::filesystem::create_directories(out_dir);
  const std::string base = out_dir + "/" + tr.name + "_n" + std::to_string(n);
  {
    std::ofstream csv(base + ".csv");
    csv << "scheme,budget,keep,terms,bytes,pct_raw,T_relF,B_relRMS,seconds\n";
    for (const Point& p : points)
      csv << prt::ToString(p.scheme) << ',' << prt::ToString(p.budget) << ',' << p.keep << ','
          << p.terms << ',' << p.bytes << ',' << p.pct_raw << ',' << p.t_err << ',' << p.b_err
          << ',' << p.secs << '\n';
  }
  {
    std::ofstream gp(base + ".gp");
    gp << "set terminal pngcairo size 900,600\nset output '" << base << ".png'\n"
       << "set datafile separator ','\nset logscale xy\nset grid\n"
       << "set xlabel 'storage (% of raw float32 T)'\nset ylabel 'relative RMS error of relit "
          "radiance'\n"
       << "set title '" << tr.name << ", n = " << n << ", " << S << " samples (Fig. 7)'\n"
       << "set key top right\nplot ";
    bool first = true;
    for (const auto& [name, pts] : curves) {
      const std::string s = prt::ToString(pts[0].scheme), b = prt::ToString(pts[0].budget);
      gp << (first ? "" : ", ") << "'" << base << ".csv' using (strcol(1) eq '" << s
         << "' && strcol(2) eq '" << b << "' ? $6 : NaN):8 with linespoints title '" << name << "'";
      first = false;
    }
    gp << "\n";
  }
  const std::string cmd = "gnuplot '" + base + ".gp' 2>/dev/null";
  if (std::system(cmd.c_str()) == 0)
    std::printf("wrote %s.csv, %s.gp, %s.png\n", base.c_str(), base.c_str(), base.c_str());
  else
    std::printf("wrote %s.csv, %s.gp (gnuplot failed: no PNG)\n", base.c_str(), base.c_str());
}

}  // namespace

int main(int argc, char** argv) {
  prt::UseTbbParallelism();  // the core vocabulary's and the runtime's loops on TBB
  std::string run, scenes_arg = "default,dragon,armadillo", n_arg = "32", cache, out_dir;
  std::string keep_arg = "0.0025,0.005,0.01,0.02,0.04,0.08", budget = "both";
  std::string schemes_arg = "2d,4d,adaptive4d", column_keep_arg;
  int rays = 1, bits = 9, light_weight = 0;
  double order_normal_weight = prt::CompressionSettings{}.order_normal_weight;
  std::string column_wavelet_arg = prt::CompressionSettings{}.column_wavelet;
  std::string row_wavelet_arg = prt::CompressionSettings{}.row_wavelet;
  bool t_error = false;
  CLI::App app{"compression_bench: storage against relit error for 2D, 4D and adaptive 4D"};
  app.add_option("--run", run, "farm run folder to read T from (instead of the scenes)");
  app.add_option("--scenes", scenes_arg,
                 "benchmark scenes (default, dragon, armadillo, camel, lion, horse, teapot)");
  app.add_option("--n", n_arg, "cubemap resolutions, comma-separated");
  app.add_option("--rays", rays, "rays per texel when tracing");
  app.add_option("--cache", cache, "folder for traced transport matrices (reused when present)");
  app.add_option("--bits", bits, "quantisation bits");
  app.add_option("--budget", budget, "column | global | both");
  app.add_option("--schemes", schemes_arg, "2d,4d,adaptive4d");
  app.add_option("--keep", keep_arg, "comma-separated keep fractions");
  app.add_option("--column-keep", column_keep_arg,
                 "keep fractions for the column budget (default: --keep)");
  app.add_option(
      "--light-weight", light_weight,
      "global budget: row level l weighted by 2^(-w*l/2) (scene compression.light_weight)");
  app.add_option("--order-normal-weight", order_normal_weight,
                 "mesh column order: weight of the normal in the 6D Hilbert curve, 0 = position "
                 "only (scene compression.order_normal_weight)");
  app.add_option("--column-wavelet", column_wavelet_arg,
                 "column (spatial) wavelet: legall53 | cdf97 (scene compression.column_wavelet)");
  app.add_option("--row-wavelet", row_wavelet_arg,
                 "row (cubemap) wavelet: haar | d4 (scene compression.row_wavelet)");
  app.add_flag("--t-error", t_error, "also measure the relative Frobenius error of T (slower)");
  app.add_option("--out", out_dir, "folder for CSV, gnuplot scripts and PNG curves");
  CLI11_PARSE(app, argc, argv);
  spdlog::set_level(spdlog::level::warn);
  try {
    const prt::ColumnWavelet column_wavelet =
        prt::ParseColumnWavelet(column_wavelet_arg, "--column-wavelet");
    const prt::RowWavelet row_wavelet = prt::ParseRowWavelet(row_wavelet_arg, "--row-wavelet");
    const std::vector<double> keeps = SplitList<double>(keep_arg);
    const std::vector<double> column_keeps =
        column_keep_arg.empty() ? keeps : SplitList<double>(column_keep_arg);
    std::vector<prt::CompressionBudget> budgets;
    if (budget != "global") budgets.push_back(prt::CompressionBudget::kColumn);
    if (budget != "column") budgets.push_back(prt::CompressionBudget::kGlobal);
    std::vector<prt::CompressionScheme> schemes;
    for (const std::string& s : SplitList<std::string>(schemes_arg))
      schemes.push_back(prt::ParseCompressionScheme(s, "--schemes"));
    if (!run.empty()) {
      const Transport tr = prt::bench::ReadRunTransport(run, order_normal_weight);
      RunOne(tr, schemes, budgets, keeps, column_keeps, bits, light_weight, t_error, column_wavelet,
             row_wavelet, out_dir);
      return 0;
    }
    for (const std::string& scene : SplitList<std::string>(scenes_arg))
      for (int n : SplitList<int>(n_arg)) {
        const Transport tr = prt::bench::SceneTransport(scene, n, rays, cache, order_normal_weight);
        RunOne(tr, schemes, budgets, keeps, column_keeps, bits, light_weight, t_error,
               column_wavelet, row_wavelet, out_dir);
      }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "compression_bench: %s\n", e.what());
    return 1;
  }
  return 0;
}
