// Test support for the SDL2 window tests (viewer_tests, under xvfb-run): run prt-view's window
// on a pack for a few frames and compare its screenshot with a headless render.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include "vocabulary/image_io.h"

namespace prt::testing {

// Runs `prt-view PACK --env ENV --window ... --screenshot DIR/shot.npy EXTRA` under a 320×240
// Xvfb (output in DIR/log.txt); returns the screenshot's path, or "" if prt-view failed.
inline std::string RunWindowScreenshot(const std::string& view_exe, const std::string& pack,
                                       const std::string& env, const std::filesystem::path& dir,
                                       const std::string& extra_args) {
  const std::string shot = (dir / "shot.npy").string();
  const std::string cmd = "xvfb-run -a -s '-screen 0 320x240x24' '" + view_exe + "' '" + pack +
                          "' --env '" + env + "' --window " + extra_args + " --screenshot '" +
                          shot + "' > '" + (dir / "log.txt").string() + "' 2>&1";
  return std::system(cmd.c_str()) == 0 ? shot : std::string();
}

// Largest difference, in 8-bit sRGB codes, between a screenshot's codes and a linear image.
inline double LargestCodeDifference(const std::vector<float>& codes, const ImageRgb& image) {
  double worst = 0;
  for (std::size_t i = 0; i < codes.size() && i < image.pixels.size(); ++i)
    worst = std::max(worst, std::abs(codes[i] - static_cast<double>(ToSrgb8(image.pixels[i]))));
  return worst;
}

}  // namespace prt::testing
