// prt-bench's records (docs/benchmarks.md): one sweep point and what it measured, their CSV
// schema, and the small formatting helpers the sweep and the report share.
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "bench/bench_scenes.h"  // CpuSeconds (process CPU seconds, all threads)

namespace prt::bench {

using Clock = std::chrono::steady_clock;

double Seconds(Clock::time_point t0);
std::vector<std::string> SplitList(const std::string& s, char sep = ',');
std::vector<double> Numbers(const std::string& s);
std::string Fmt(double v);
std::string Fmt3(double v);
std::string Percent(double v);

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

inline constexpr const char* kCsvColumns =
    "scene,n,samples,family,label,dense_budget,features,radius,keep,bits,terms,wall_s,cpu_s,rays,"
    "sampled_fraction,bytes,relight_ms,err_T,err_mean,err_max";
// Columns that hold timings (left out by --compare).
bool IsTimingColumn(const std::string& c);

std::string CsvHeader(const std::vector<std::string>& envs);

std::string ToCsv(const Record& r);

// Parses a row written by ToCsv; throws std::runtime_error naming `where` on a malformed row.
Record FromCsv(const std::string& line, std::size_t env_count, const std::string& where);

struct CsvFile {
  std::vector<std::string> columns, envs;
  std::vector<std::string> lines;
  std::vector<Record> records;
};

CsvFile ReadCsv(const std::string& path);

// Mean and max of a record's per-environment errors.
void Finish(Record& r);

}  // namespace prt::bench
