// The wavelet filters prtfarm transforms with, and their names in docs and scene files.
#pragma once

#include <cstdint>
#include <string_view>

namespace prt {

enum class WaveletFilter : std::uint8_t { kHaar = 0, kDaubechies4 = 1, kLeGall53 = 2, kCdf97 = 3 };

// "haar", "d4", "legall53", "cdf97" (the names docs and scene files use).
const char* WaveletFilterName(WaveletFilter filter);
// Accepts the names above and the aliases "daubechies4", "5/3", "53", "le_gall_5_3", "9/7",
// "97", "cdf_9_7" (case-sensitive). Returns false, leaving *filter alone, when unknown.
bool ParseWaveletFilter(std::string_view name, WaveletFilter* filter);
// True for the lifting filters (any length, symmetric extension).
inline bool IsLiftingFilter(WaveletFilter f) {
  return f == WaveletFilter::kLeGall53 || f == WaveletFilter::kCdf97;
}

}  // namespace prt
