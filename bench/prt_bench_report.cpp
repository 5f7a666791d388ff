// prt-bench's summary, plots and output checks (see prt_bench_report.h).
#include "bench/prt_bench_report.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <set>
#include <sstream>
#include <stdexcept>

namespace prt::bench {

namespace fs = std::filesystem;

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

}  // namespace prt::bench
