// Reading and writing environment maps: OpenEXR (lat-long and cube, the envmap attribute) and
// Radiance RGBE .hdr (see environment_io.h).
#include "vocabulary/environment_io.h"

#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfInputFile.h>
#include <OpenEXR/ImfOutputFile.h>
#include <OpenEXR/ImfStandardAttributes.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <memory>
#include <numbers>
#include <sstream>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "vocabulary/bytes.h"
#include "vocabulary/durable_file.h"
#include "vocabulary/errors.h"

namespace prt {

namespace {

// ---- Layout inference and pixel checks ----

EnvmapLayout InferLayout(const std::string& path, std::int64_t w, std::int64_t h) {
  if (w == 2 * h) {
    spdlog::info("{}: no envmap attribute; {}x{} (2:1) taken as a lat-long map", path, w, h);
    return EnvmapLayout::kLatLong;
  }
  if (h == 6 * w) {
    spdlog::info("{}: no envmap attribute; {}x{} (1:6) taken as a cube map", path, w, h);
    return EnvmapLayout::kCube;
  }
  throw InputError(path, "no envmap attribute and the shape " + std::to_string(w) + "x" +
                             std::to_string(h) + " is neither 2:1 (lat-long) nor 1:6 (cube)");
}

// NaN/Inf are rejected with the pixel named; negatives are clamped to 0 and counted.
void CheckAndClamp(const std::string& path, EnvironmentImage& img, EnvironmentLoadInfo& info) {
  static const char* kNames[3] = {"R", "G", "B"};
  for (int c = 0; c < 3; ++c) {
    std::vector<float>& ch = img.Channel(c);
    for (std::size_t i = 0; i < ch.size(); ++i) {
      const float v = ch[i];
      if (!std::isfinite(v)) {
        const int x = static_cast<int>(i % static_cast<std::size_t>(img.width));
        const int y = static_cast<int>(i / static_cast<std::size_t>(img.width));
        throw InputError(path, std::string(std::isnan(v) ? "NaN" : "Inf") +
                                   " at pixel (x=" + std::to_string(x) +
                                   ", y=" + std::to_string(y) + ", channel " + kNames[c] + ")");
      }
      if (v < 0) {
        info.most_negative = std::min(info.most_negative, static_cast<double>(v));
        ++info.negatives_clamped;
        ch[i] = 0;
      }
    }
  }
  if (info.negatives_clamped > 0) {
    spdlog::warn("{}: clamped {} negative pixel values to 0 (most negative {})", path,
                 info.negatives_clamped, info.most_negative);
  }
}

}  // namespace

// ---- OpenEXR ----

EnvironmentImage ReadEnvironmentExr(const std::string& path, EnvironmentLoadInfo* info_out) {
  EnvironmentLoadInfo info;
  EnvironmentImage img;
  try {
    Imf::InputFile file(path.c_str());
    const Imf::Header& header = file.header();
    const Imath::Box2i dw = header.dataWindow();
    const std::int64_t w = std::int64_t{dw.max.x} - dw.min.x + 1;
    const std::int64_t h = std::int64_t{dw.max.y} - dw.min.y + 1;
    ValidateEnvironmentShape(path, EnvmapLayout::kLatLong, std::max<std::int64_t>(w, 2),
                             std::max<std::int64_t>(h, 2));  // size limits only
    EnvmapLayout layout;
    if (Imf::hasEnvmap(header)) {
      const Imf::Envmap e = Imf::envmapAttribute(header).value();
      if (e == Imf::ENVMAP_LATLONG) {
        layout = EnvmapLayout::kLatLong;
      } else if (e == Imf::ENVMAP_CUBE) {
        layout = EnvmapLayout::kCube;
      } else {
        throw InputError(path, "unknown envmap attribute value " + std::to_string(int{e}));
      }
      info.layout_from_attribute = true;
    } else {
      layout = InferLayout(path, w, h);
    }
    ValidateEnvironmentShape(path, layout, w, h);
    if (!file.isComplete()) throw InputError(path, "file is truncated (missing pixel data)");

    img = EnvironmentImage::Zero(layout, static_cast<int>(w), static_cast<int>(h));
    const Imf::ChannelList& channels = header.channels();
    const bool rgb =
        channels.findChannel("R") && channels.findChannel("G") && channels.findChannel("B");
    const bool grey = !rgb && channels.findChannel("Y");
    if (!rgb && !grey) {
      std::string names;
      for (auto it = channels.begin(); it != channels.end(); ++it) {
        names += std::string(names.empty() ? "" : ", ") + it.name();
      }
      throw InputError(path, "no R, G, B (or Y) channels; found: " + names);
    }
    Imf::FrameBuffer fb;
    const std::size_t xs = sizeof(float), ys = sizeof(float) * static_cast<std::size_t>(w);
    if (rgb) {
      fb.insert("R", Imf::Slice::Make(Imf::FLOAT, img.r.data(), dw, xs, ys));
      fb.insert("G", Imf::Slice::Make(Imf::FLOAT, img.g.data(), dw, xs, ys));
      fb.insert("B", Imf::Slice::Make(Imf::FLOAT, img.b.data(), dw, xs, ys));
    } else {
      fb.insert("Y", Imf::Slice::Make(Imf::FLOAT, img.r.data(), dw, xs, ys));
    }
    file.setFrameBuffer(fb);
    file.readPixels(dw.min.y, dw.max.y);
    if (grey) {
      img.g = img.r;
      img.b = img.r;
    }
  } catch (const InputError&) {
    throw;
  } catch (const std::exception& e) {
    throw InputError(path, std::string("cannot read OpenEXR: ") + e.what());
  }
  CheckAndClamp(path, img, info);
  if (info_out) *info_out = info;
  return img;
}

void WriteEnvironmentExr(const EnvironmentImage& image, const std::string& path) {
  if (image.width <= 0 || image.height <= 0 || image.r.size() != image.PixelCount() ||
      image.g.size() != image.PixelCount() || image.b.size() != image.PixelCount()) {
    throw std::invalid_argument("WriteEnvironmentExr: image channels do not match its size");
  }
  try {
    Imf::Header header(image.width, image.height);
    header.compression() = Imf::ZIP_COMPRESSION;
    Imf::addEnvmap(header,
                   image.layout == EnvmapLayout::kCube ? Imf::ENVMAP_CUBE : Imf::ENVMAP_LATLONG);
    for (const char* c : {"R", "G", "B"}) header.channels().insert(c, Imf::Channel(Imf::FLOAT));
    Imf::OutputFile file(path.c_str(), header);
    Imf::FrameBuffer fb;
    const Imath::Box2i dw = header.dataWindow();
    const std::size_t xs = sizeof(float), ys = sizeof(float) * image.width;
    fb.insert("R", Imf::Slice::Make(Imf::FLOAT, image.r.data(), dw, xs, ys));
    fb.insert("G", Imf::Slice::Make(Imf::FLOAT, image.g.data(), dw, xs, ys));
    fb.insert("B", Imf::Slice::Make(Imf::FLOAT, image.b.data(), dw, xs, ys));
    file.setFrameBuffer(fb);
    file.writePixels(image.height);
  } catch (const std::exception& e) {
    throw InputError(path, std::string("cannot write OpenEXR: ") + e.what());
  }
}

// ---- Radiance RGBE ----
// Format: Greg Ward, "Real Pixels" (Graphics Gems II, 1991) and the Radiance file format notes:
// a text header ending in an empty line, a resolution line, then scanlines of 4-byte RGBE
// pixels, either flat (with old-style (1,1,1,n) repeat runs) or "new" run-length encoded
// (2, 2, width>>8, width&255, then each channel run-length coded separately).

namespace {

float RgbeComponent(std::uint8_t c, std::uint8_t e) {
  return e == 0 ? 0.0f : static_cast<float>(std::ldexp(c + 0.5, static_cast<int>(e) - 136));
}

// The file's reader: a read past the end is an InputError naming the file and the field.
ByteReader RadianceReader(const std::string& path, const std::string& data) {
  return ByteReader(data, [&path](const char* what, std::size_t) {
    throw InputError(path, std::string("truncated in ") + what);
  });
}

// One header line without its '\n'; lines longer than 64 KiB are corrupt.
std::string Line(ByteReader& in, const std::string& path) {
  const std::size_t end = in.rest().find('\n');
  if (end == std::string_view::npos) throw InputError(path, "truncated header");
  if (end > 65536) throw InputError(path, "header line too long");
  std::string line(in.Take(end, "header"));
  in.Skip(1, "header");
  return line;
}

}  // namespace

EnvironmentImage ReadRadianceHdr(const std::string& path, EnvironmentLoadInfo* info_out) {
  const std::string data = ReadWholeFile(path);
  ByteReader in = RadianceReader(path, data);
  const std::string magic = Line(in, path);
  if (magic.rfind("#?", 0) != 0) throw InputError(path, "not a Radiance file (no #? line)");
  for (;;) {
    const std::string line = Line(in, path);
    if (line.empty() || line == "\r") break;
    if (line.rfind("FORMAT=", 0) == 0) {
      const std::string f = line.substr(7);
      if (f.rfind("32-bit_rle_rgbe", 0) != 0) {
        throw InputError(path, "unsupported Radiance FORMAT '" + f + "' (only 32-bit_rle_rgbe)");
      }
    } else if (line.rfind("EXPOSURE=", 0) == 0) {
      // Radiance says pixel = radiance × EXPOSURE; like most tools we keep the stored values.
      spdlog::debug("{}: {} (ignored)", path, line);
    }
  }
  const std::string res = Line(in, path);
  std::istringstream rs(res);
  std::string ys, xs;
  long long h = 0, w = 0;
  if (!(rs >> ys >> h >> xs >> w) || (ys != "-Y" && ys != "+Y") || (xs != "+X" && xs != "-X")) {
    throw InputError(path, "unsupported resolution line '" + res +
                               "' (expected -Y h +X w; transposed images are not supported)");
  }
  EnvironmentLoadInfo info;
  const EnvmapLayout layout = InferLayout(path, w, h);
  ValidateEnvironmentShape(path, layout, w, h);
  EnvironmentImage img = EnvironmentImage::Zero(layout, static_cast<int>(w), static_cast<int>(h));
  const int W = img.width;
  std::vector<std::uint8_t> scan(static_cast<std::size_t>(W) * 4);
  for (int y = 0; y < img.height; ++y) {
    const std::string where = "scanline " + std::to_string(y);
    const std::string_view ahead = in.rest();
    const bool new_rle = W >= 8 && W < 32768 && ahead.size() >= 4 && ahead[0] == 2 &&
                         ahead[1] == 2 && (static_cast<std::uint8_t>(ahead[2]) & 0x80) == 0;
    if (new_rle) {
      in.Get<std::uint8_t>(where.c_str());
      in.Get<std::uint8_t>(where.c_str());
      // Big-endian, read in two statements (the operands of | are unsequenced).
      const int enc_hi = in.Get<std::uint8_t>(where.c_str());
      const int enc_w = (enc_hi << 8) | in.Get<std::uint8_t>(where.c_str());
      if (enc_w != W) {
        throw InputError(path, where + ": RLE width " + std::to_string(enc_w) +
                                   " does not match the image width " + std::to_string(W));
      }
      for (int c = 0; c < 4; ++c) {
        int x = 0;
        while (x < W) {
          int count = in.Get<std::uint8_t>(where.c_str());
          if (count > 128) {
            count -= 128;
            if (count > W - x) throw InputError(path, where + ": RLE run overflows the scanline");
            const std::uint8_t v = in.Get<std::uint8_t>(where.c_str());
            for (int i = 0; i < count; ++i) scan[4 * static_cast<std::size_t>(x++) + c] = v;
          } else {
            if (count == 0 || count > W - x) {
              throw InputError(path, where + ": bad RLE literal count " + std::to_string(count));
            }
            for (int i = 0; i < count; ++i) {
              scan[4 * static_cast<std::size_t>(x++) + c] = in.Get<std::uint8_t>(where.c_str());
            }
          }
        }
      }
    } else {
      int x = 0, shift = 0;
      while (x < W) {
        std::uint8_t p[4];
        for (auto& b : p) b = in.Get<std::uint8_t>(where.c_str());
        if (p[0] == 1 && p[1] == 1 && p[2] == 1) {  // old-style run: repeat the previous pixel
          if (x == 0) throw InputError(path, where + ": repeat run with no previous pixel");
          if (shift > 16) throw InputError(path, where + ": repeat run too long");
          const long long count = static_cast<long long>(p[3]) << shift;
          if (count > W - x) throw InputError(path, where + ": repeat run overflows scanline");
          for (long long i = 0; i < count; ++i, ++x) {
            std::memcpy(&scan[4 * static_cast<std::size_t>(x)],
                        &scan[4 * static_cast<std::size_t>(x - 1)], 4);
          }
          shift += 8;
        } else {
          std::memcpy(&scan[4 * static_cast<std::size_t>(x)], p, 4);
          ++x;
          shift = 0;
        }
      }
    }
    const int row = ys == "-Y" ? y : img.height - 1 - y;
    for (int x = 0; x < W; ++x) {
      const int col = xs == "+X" ? x : W - 1 - x;
      const std::uint8_t* p = &scan[4 * static_cast<std::size_t>(x)];
      const std::size_t i = img.Index(col, row);
      img.r[i] = RgbeComponent(p[0], p[3]);
      img.g[i] = RgbeComponent(p[1], p[3]);
      img.b[i] = RgbeComponent(p[2], p[3]);
    }
  }
  CheckAndClamp(path, img, info);
  if (info_out) *info_out = info;
  return img;
}

void WriteRadianceHdr(const EnvironmentImage& image, const std::string& path, bool rle) {
  if (image.width <= 0 || image.height <= 0 || image.r.size() != image.PixelCount() ||
      image.g.size() != image.PixelCount() || image.b.size() != image.PixelCount()) {
    throw std::invalid_argument("WriteRadianceHdr: image channels do not match its size");
  }
  std::string out = "#?RADIANCE\n# Written by prtfarm\nFORMAT=32-bit_rle_rgbe\n\n-Y " +
                    std::to_string(image.height) + " +X " + std::to_string(image.width) + "\n";
  const int W = image.width;
  const bool use_rle = rle && W >= 8 && W < 32768;
  std::vector<std::uint8_t> scan(static_cast<std::size_t>(W) * 4);
  for (int y = 0; y < image.height; ++y) {
    for (int x = 0; x < W; ++x) {
      const std::size_t i = image.Index(x, y);
      double c[3] = {image.r[i], image.g[i], image.b[i]};
      for (double& v : c) v = std::isfinite(v) ? std::clamp(v, 0.0, 1.7e38) : 0.0;
      const double m = std::max({c[0], c[1], c[2]});
      std::uint8_t* p = &scan[4 * static_cast<std::size_t>(x)];
      if (m < 1e-32) {
        p[0] = p[1] = p[2] = p[3] = 0;
      } else {
        int e;
        const double scale = std::frexp(m, &e) * 256.0 / m;
        for (int k = 0; k < 3; ++k) {
          p[k] = static_cast<std::uint8_t>(std::min(255.0, std::floor(c[k] * scale)));
        }
        p[3] = static_cast<std::uint8_t>(e + 128);
      }
    }
    if (!use_rle) {
      out.append(reinterpret_cast<const char*>(scan.data()), scan.size());
      continue;
    }
    out.push_back(2);
    out.push_back(2);
    out.push_back(static_cast<char>(W >> 8));
    out.push_back(static_cast<char>(W & 255));
    for (int c = 0; c < 4; ++c) {
      auto at = [&](int x) { return scan[4 * static_cast<std::size_t>(x) + c]; };
      int x = 0;
      while (x < W) {
        int run = 1;
        while (x + run < W && run < 127 && at(x + run) == at(x)) ++run;
        if (run >= 4) {
          out.push_back(static_cast<char>(128 + run));
          out.push_back(static_cast<char>(at(x)));
          x += run;
          continue;
        }
        const int start = x;
        int len = 0;
        while (x < W && len < 128) {
          int r = 1;
          while (x + r < W && r < 4 && at(x + r) == at(x)) ++r;
          if (r >= 4) break;
          ++x;
          ++len;
        }
        out.push_back(static_cast<char>(len));
        for (int i = start; i < start + len; ++i) out.push_back(static_cast<char>(at(i)));
      }
    }
  }
  std::ofstream f(path, std::ios::binary | std::ios::trunc);
  if (!f) throw InputError(path, "cannot open for writing");
  f.write(out.data(), static_cast<std::streamsize>(out.size()));
  f.close();
  if (!f) throw InputError(path, "write failed");
}

EnvironmentImage ReadEnvironment(const std::string& path, EnvironmentLoadInfo* info) {
  std::ifstream f(path, std::ios::binary);
  if (!f) throw InputError(path, "cannot open for reading");
  char magic[4] = {0, 0, 0, 0};
  f.read(magic, 4);
  if (f.gcount() == 4 && static_cast<unsigned char>(magic[0]) == 0x76 &&
      static_cast<unsigned char>(magic[1]) == 0x2f &&
      static_cast<unsigned char>(magic[2]) == 0x31 &&
      static_cast<unsigned char>(magic[3]) == 0x01) {
    return ReadEnvironmentExr(path, info);
  }
  if (f.gcount() >= 2 && magic[0] == '#' && magic[1] == '?') return ReadRadianceHdr(path, info);
  throw InputError(path, "neither OpenEXR nor Radiance .hdr (unrecognised magic bytes)");
}

}  // namespace prt
