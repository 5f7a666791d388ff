// Reading and writing environment maps (DESIGN.md, "Conventions"): OpenEXR lat-long and cube maps
// (the `envmap` header attribute honoured) and Radiance .hdr.
//
// Readers are safe on untrusted input: every size is validated before it is used, truncated or
// corrupt files throw prt::InputError naming the file, NaN/Inf pixels throw InputError naming the
// file and the pixel (x, y, channel), and negative radiance is clamped to 0 and counted.
#pragma once

#include <string>

#include "vocabulary/envmap.h"

namespace prt {

// Reads an environment: OpenEXR (any compression, half or float, scanline or tiled; R, G, B
// channels, or Y alone as grey) or Radiance RGBE (.hdr/.pic, flat, old-RLE or new-RLE scanlines),
// chosen by the file's magic bytes. The layout comes from the EXR `envmap` attribute; without it
// (and always for .hdr) a 2:1 image is lat-long and a 1:6 image is a cube, and a log line says
// so; any other shape throws InputError. A lat-long map must be at least 2×2 (OpenEXR maps
// pixel 0 and pixel w−1 to the two ends of the longitude range); a cube map must be w × 6w.
EnvironmentImage ReadEnvironment(const std::string& path, EnvironmentLoadInfo* info = nullptr);
EnvironmentImage ReadEnvironmentExr(const std::string& path, EnvironmentLoadInfo* info = nullptr);
EnvironmentImage ReadRadianceHdr(const std::string& path, EnvironmentLoadInfo* info = nullptr);

// Writes float RGB OpenEXR (ZIP) with the `envmap` attribute set from image.layout.
// Throws InputError naming the file when it cannot be written.
void WriteEnvironmentExr(const EnvironmentImage& image, const std::string& path);
// Writes Radiance RGBE ("-Y h +X w"), new-RLE scanlines when rle and 8 ≤ width ≤ 32767, flat
// scanlines otherwise. RGBE keeps 8 bits of mantissa: values round-trip within 1/256 of the
// pixel's largest channel. Negative values are written as 0.
void WriteRadianceHdr(const EnvironmentImage& image, const std::string& path, bool rle = true);

}  // namespace prt
