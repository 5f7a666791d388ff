// prt-bench's report (docs/benchmarks.md): the summary with Pareto fronts and the papers'
// operating points, the plots (gnuplot), and the --check / --compare checks of an output folder.
#pragma once

#include <string>
#include <vector>

#include "bench/prt_bench_records.h"

namespace prt::bench {

// The Markdown summary of every record: per scene, the Pareto fronts of precomputation time,
// bytes and relighting time against error, the cheapest setting under error targets, and the
// papers' operating points next to ours. `command` is the command line that made them.
std::string Summary(const std::vector<Record>& all, const std::vector<std::string>& scenes,
                    const std::vector<std::string>& envs, const std::string& command);
// plots/<scene>_{time,size,relight}_error.png with gnuplot; false when gnuplot failed.
bool Plot(const std::vector<Record>& all, const std::string& scene, const std::string& dir);
// Sanity checks on DIR's CSV and summary; the problems found (none: empty).
std::vector<std::string> CheckOutputs(const std::string& dir);
// Every non-timing column of two output folders equal; the differences found.
std::vector<std::string> CompareOutputs(const std::string& a, const std::string& b);
// Prints the problems (or that there are none) and returns the exit code: 1 if any.
int Report(const std::vector<std::string>& bad, const std::string& what);

}  // namespace prt::bench
