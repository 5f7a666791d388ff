#include "vocabulary/wavelet_filter.h"

namespace prt {

const char* WaveletFilterName(WaveletFilter filter) {
  switch (filter) {
    case WaveletFilter::kHaar:
      return "haar";
    case WaveletFilter::kDaubechies4:
      return "d4";
    case WaveletFilter::kLeGall53:
      return "legall53";
    case WaveletFilter::kCdf97:
      return "cdf97";
  }
  return "unknown";
}

bool ParseWaveletFilter(std::string_view name, WaveletFilter* filter) {
  struct Alias {
    const char* name;
    WaveletFilter filter;
  };
  static constexpr Alias kAliases[] = {{"haar", WaveletFilter::kHaar},
                                       {"d4", WaveletFilter::kDaubechies4},
                                       {"daubechies4", WaveletFilter::kDaubechies4},
                                       {"legall53", WaveletFilter::kLeGall53},
                                       {"5/3", WaveletFilter::kLeGall53},
                                       {"53", WaveletFilter::kLeGall53},
                                       {"le_gall_5_3", WaveletFilter::kLeGall53},
                                       {"cdf97", WaveletFilter::kCdf97},
                                       {"9/7", WaveletFilter::kCdf97},
                                       {"97", WaveletFilter::kCdf97},
                                       {"cdf_9_7", WaveletFilter::kCdf97}};
  for (const Alias& a : kAliases) {
    if (name == a.name) {
      *filter = a.filter;
      return true;
    }
  }
  return false;
}

}  // namespace prt
