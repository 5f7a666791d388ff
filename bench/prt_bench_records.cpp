// prt-bench's records and their CSV (see prt_bench_records.h).
#include "bench/prt_bench_records.h"

#include <algorithm>
#include <cstdio>
#include <ctime>
#include <fstream>
#include <sstream>
#include <stdexcept>

namespace prt::bench {

double Seconds(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

std::vector<std::string> SplitList(const std::string& s, char sep) {
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

void Finish(Record& r) {
  r.err_mean = 0;
  r.err_max = 0;
  for (double e : r.err_env) {
    r.err_mean += e / static_cast<double>(r.err_env.size());
    r.err_max = std::max(r.err_max, e);
  }
}

}  // namespace prt::bench
