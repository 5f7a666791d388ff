#include "vocabulary/image_io.h"

#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfOutputFile.h>
#include <OpenEXR/ImfStdIO.h>
#include <png.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <stdexcept>

#include "vocabulary/errors.h"

namespace prt {

namespace {
void CheckImage(const ImageRgb& image, const char* who) {
  if (image.width <= 0 || image.height <= 0 ||
      image.pixels.size() != static_cast<std::size_t>(3) * image.width * image.height) {
    throw std::invalid_argument(std::string(who) + ": image size does not match its pixels");
  }
}
}  // namespace

double SrgbEncode(double linear) {
  const double x = std::clamp(linear, 0.0, 1.0);
  if (x == 1.0) return 1.0;
  return x <= 0.0031308 ? 12.92 * x : std::min(1.0, 1.055 * std::pow(x, 1.0 / 2.4) - 0.055);
}

double SrgbDecode(double encoded) {
  const double x = std::clamp(encoded, 0.0, 1.0);
  if (x == 1.0) return 1.0;
  return x <= 0.04045 ? x / 12.92 : std::min(1.0, std::pow((x + 0.055) / 1.055, 2.4));
}

unsigned char ToSrgb8(double linear, const ToneMapOptions& options) {
  if (std::isnan(linear)) return 0;
  double x = std::max(0.0, linear * options.exposure);
  if (options.tone_map == ToneMap::kReinhard) x = std::isinf(x) ? 1.0 : x / (1.0 + x);
  return static_cast<unsigned char>(std::lround(255.0 * SrgbEncode(x)));
}

namespace {

// Images are written to `path`.tmp and renamed over `path` once complete, so that a failed
// write (a full disk) never destroys an earlier image at `path`.
void ReplaceWithTemporary(const std::string& tmp, const std::string& path) {
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    const int e = errno;
    std::remove(tmp.c_str());
    throw InputError(path, std::string("cannot rename the temporary file: ") + std::strerror(e));
  }
}

}  // namespace

void WritePng(const ImageRgb& image, const std::string& path, const ToneMapOptions& options) {
  CheckImage(image, "WritePng");
  std::vector<std::uint8_t> bytes(image.pixels.size());
  for (std::size_t i = 0; i < bytes.size(); ++i) bytes[i] = ToSrgb8(image.pixels[i], options);
  // libpng's simplified API reports errors through its return value, not longjmp; it removes
  // the file it failed to write.
  png_image png;
  std::memset(&png, 0, sizeof(png));
  png.version = PNG_IMAGE_VERSION;
  png.width = static_cast<png_uint_32>(image.width);
  png.height = static_cast<png_uint_32>(image.height);
  png.format = PNG_FORMAT_RGB;
  const std::string tmp = path + ".tmp";
  errno = 0;
  const int ok =
      png_image_write_to_file(&png, tmp.c_str(), 0, bytes.data(), 3 * image.width, nullptr);
  if (!ok) {
    // libpng says only "Write Error"; errno says why (a full disk, a read-only folder).
    const int e = errno;
    const std::string msg =
        std::string(png.message) + (e != 0 ? std::string(": ") + std::strerror(e) : "");
    png_image_free(&png);
    std::remove(tmp.c_str());
    throw InputError(path, "cannot write PNG: " + msg);
  }
  ReplaceWithTemporary(tmp, path);
}

void WriteExr(const ImageRgb& image, const std::string& path) {
  CheckImage(image, "WriteExr");
  const std::string tmp = path + ".tmp";
  std::ofstream os(tmp, std::ios::binary | std::ios::trunc);
  try {
    if (!os) throw std::runtime_error(std::string("cannot create: ") + std::strerror(errno));
    {
      Imf::StdOFStream stream(os, tmp.c_str());
      Imf::Header header(image.width, image.height);
      header.compression() = Imf::ZIP_COMPRESSION;
      for (const char* c : {"R", "G", "B"}) header.channels().insert(c, Imf::Channel(Imf::FLOAT));
      Imf::OutputFile file(stream, header);
      Imf::FrameBuffer fb;
      const Imath::Box2i dw = header.dataWindow();
      const std::size_t xs = 3 * sizeof(float), ys = xs * image.width;
      fb.insert("R", Imf::Slice::Make(Imf::FLOAT, image.pixels.data() + 0, dw, xs, ys));
      fb.insert("G", Imf::Slice::Make(Imf::FLOAT, image.pixels.data() + 1, dw, xs, ys));
      fb.insert("B", Imf::Slice::Make(Imf::FLOAT, image.pixels.data() + 2, dw, xs, ys));
      file.setFrameBuffer(fb);
      file.writePixels(image.height);
    }  // ~OutputFile writes the line offsets and swallows errors: the stream's state tells.
    os.close();
    if (!os) throw std::runtime_error(std::string("write failed: ") + std::strerror(errno));
  } catch (const std::exception& e) {
    os.close();
    std::remove(tmp.c_str());
    throw InputError(path, std::string("cannot write OpenEXR: ") + e.what());
  }
  ReplaceWithTemporary(tmp, path);
}

ImageRgb AbsDifference(const ImageRgb& a, const ImageRgb& b, double scale) {
  CheckImage(a, "AbsDifference");
  CheckImage(b, "AbsDifference");
  if (a.width != b.width || a.height != b.height) {
    throw std::invalid_argument("AbsDifference: images differ in size");
  }
  ImageRgb d(a.width, a.height);
  for (std::size_t i = 0; i < d.pixels.size(); ++i) {
    d.pixels[i] = static_cast<float>(std::abs(double{a.pixels[i]} - b.pixels[i]) * scale);
  }
  return d;
}

ImageRgb SideBySide(const ImageRgb& a, const ImageRgb& b, bool with_difference, double diff_scale) {
  CheckImage(a, "SideBySide");
  CheckImage(b, "SideBySide");
  if (a.width != b.width || a.height != b.height) {
    throw std::invalid_argument("SideBySide: images differ in size");
  }
  const int panels = with_difference ? 3 : 2;
  ImageRgb out(a.width * panels, a.height);
  const ImageRgb diff = with_difference ? AbsDifference(a, b, diff_scale) : ImageRgb();
  for (int y = 0; y < a.height; ++y) {
    for (int p = 0; p < panels; ++p) {
      const ImageRgb& src = p == 0 ? a : (p == 1 ? b : diff);
      std::copy_n(src.At(0, y), 3 * a.width, out.At(p * a.width, y));
    }
  }
  return out;
}

std::array<float, 3> FalseColour(double t) {
  if (std::isnan(t)) return {0, 0, 0};
  // Control points of a turbo-like ramp, in sRGB-encoded values, at t = 0, 0.2, …, 1.
  static constexpr double kRamp[6][3] = {{0.19, 0.07, 0.23}, {0.27, 0.51, 0.99},
                                         {0.10, 0.90, 0.70}, {0.64, 0.99, 0.24},
                                         {0.98, 0.50, 0.10}, {0.48, 0.02, 0.01}};
  const double s = std::clamp(t, 0.0, 1.0) * 5;
  const int i = std::min(4, static_cast<int>(s));
  const double f = s - i;
  std::array<float, 3> out;
  for (int c = 0; c < 3; ++c) {
    out[c] = static_cast<float>(SrgbDecode(kRamp[i][c] * (1 - f) + kRamp[i + 1][c] * f));
  }
  return out;
}

ImageRgb FalseColourImage(const std::vector<float>& values, int width, int height, double lo,
                          double hi) {
  if (width <= 0 || height <= 0 ||
      values.size() != static_cast<std::size_t>(width) * static_cast<std::size_t>(height)) {
    throw std::invalid_argument("FalseColourImage: values do not match width × height");
  }
  ImageRgb out(width, height);
  for (std::size_t i = 0; i < values.size(); ++i) {
    const double t = hi > lo ? (values[i] - lo) / (hi - lo) : 0.5;
    const std::array<float, 3> c = FalseColour(t);
    std::copy(c.begin(), c.end(), &out.pixels[3 * i]);
  }
  return out;
}

}  // namespace prt
