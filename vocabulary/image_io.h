// Image output: 8-bit sRGB PNG from linear float RGB (exposure, tone map, sRGB transfer curve),
// float OpenEXR, and small helpers for error pictures (side by side, |a − b| × scale, false
// colour). Writers throw prt::InputError naming the file when it cannot be written.
#pragma once

#include <array>
#include <cstddef>
#include <string>
#include <vector>

namespace prt {

// Linear float RGB, interleaved (r, g, b per pixel), row-major from the top row.
struct ImageRgb {
  int width = 0;
  int height = 0;
  std::vector<float> pixels;  // 3·width·height

  ImageRgb() = default;
  ImageRgb(int w, int h) : width(w), height(h), pixels(static_cast<std::size_t>(3) * w * h, 0.f) {}
  std::size_t Index(int x, int y) const { return 3 * (static_cast<std::size_t>(y) * width + x); }
  float* At(int x, int y) { return &pixels[Index(x, y)]; }
  const float* At(int x, int y) const { return &pixels[Index(x, y)]; }
};

// The sRGB transfer curve (IEC 61966-2-1): linear [0, 1] → encoded [0, 1] and back.
// 12.92·x below 0.0031308, 1.055·x^(1/2.4) − 0.055 above. Inputs outside [0, 1] are clamped.
double SrgbEncode(double linear);
double SrgbDecode(double encoded);

enum class ToneMap {
  kClamp,     // exposure, then clamp to [0, 1]
  kReinhard,  // exposure, then x / (1 + x) per channel
};

struct ToneMapOptions {
  double exposure = 1.0;  // linear multiplier applied before tone mapping (2^stops)
  ToneMap tone_map = ToneMap::kClamp;
};

// Linear value → 8-bit sRGB code: exposure, tone map, sRGB curve, round to nearest.
// NaN maps to 0.
unsigned char ToSrgb8(double linear, const ToneMapOptions& options = {});

// Writes an 8-bit sRGB PNG (libpng). Throws InputError naming the file on failure.
void WritePng(const ImageRgb& image, const std::string& path, const ToneMapOptions& options = {});
// Writes linear float RGB OpenEXR (ZIP). Throws InputError naming the file on failure.
void WriteExr(const ImageRgb& image, const std::string& path);

// |a − b| × scale per channel. a and b must have the same size (std::invalid_argument).
ImageRgb AbsDifference(const ImageRgb& a, const ImageRgb& b, double scale = 1.0);
// a | b side by side; with_difference appends a third panel |a − b| × diff_scale.
ImageRgb SideBySide(const ImageRgb& a, const ImageRgb& b, bool with_difference = false,
                    double diff_scale = 1.0);

// False colour (a "turbo"-like ramp, dark blue → cyan → green → yellow → red) of t ∈ [0, 1],
// clamped; NaN gives black. Returned in LINEAR RGB, so WritePng shows the ramp's colours.
std::array<float, 3> FalseColour(double t);
// An image of width × height scalar values (row-major) in false colour, mapping [lo, hi] to the
// ramp (hi == lo maps everything to the middle).
ImageRgb FalseColourImage(const std::vector<float>& values, int width, int height, double lo,
                          double hi);

}  // namespace prt
