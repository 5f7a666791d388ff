// prt-env-hdr: writes an environment map (OpenEXR or Radiance, what prt-view reads) as a Radiance
// .hdr, the format the web page reads (docs/web.md). RGBE keeps 8 bits of mantissa: prt-view and
// the page then light a pack from the same .hdr, so they see the same floats.
//   prt-env-hdr build/data/envmaps/sunrise.exr sunrise.hdr
#include <cstdio>
#include <exception>
#include <string>

#include "vocabulary/environment_io.h"

int main(int argc, char** argv) {
  if (argc != 3) {
    std::fprintf(stderr, "usage: %s IN.(exr|hdr) OUT.hdr\n", argv[0]);
    return 2;
  }
  try {
    const prt::EnvironmentImage image = prt::ReadEnvironment(argv[1]);
    prt::WriteRadianceHdr(image, argv[2]);
    std::printf("%s: %d x %d\n", argv[2], image.width, image.height);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "prt-env-hdr: %s\n", e.what());
    return 1;
  }
  return 0;
}
