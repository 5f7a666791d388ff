// The rotation benchmark's error plot, drawn by gnuplot: for the executables (prt-view,
// viewer_bench) only, so that no library of prtfarm starts another program (prt_viewer_plot in
// viewer/CMakeLists.txt).
#pragma once

#include <string>

#include "viewer/viewer_session.h"

namespace prt {

// Plots the CSV like Overbeck et al. Figure 7 (image error against frame for NWA, BI and PBI,
// log scale, the rotation's end marked) into `png_path` with gnuplot, from a generated script
// written next to it. Returns false (and writes nothing but the script) when gnuplot is not on
// the PATH or fails.
bool PlotRotationErrors(const std::string& csv_path, const std::string& png_path,
                        const RotationOptions& options);

}  // namespace prt
