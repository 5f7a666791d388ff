#include "vocabulary/image_io.h"

#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfInputFile.h>
#include <gtest/gtest.h>
#include <png.h>
#include <unistd.h>

#include <cmath>
#include <cstring>
#include <filesystem>

#include "vocabulary/errors.h"

namespace prt {
namespace {

namespace fs = std::filesystem;

fs::path TempDir() {
  const fs::path d =
      fs::temp_directory_path() / ("prt_image_io_test_" + std::to_string(::getpid()));
  fs::create_directories(d);
  return d;
}

// The sRGB curve at its defining points (IEC 61966-2-1): 0 → 0, the linear/power breakpoint
// 0.0031308 → 0.0031308·12.92 = 0.040449936 from both branches, 1 → 1.
TEST(ImageIo, SrgbCurve) {
  EXPECT_EQ(SrgbEncode(0.0), 0.0);
  EXPECT_NEAR(SrgbEncode(0.0031308), 0.0031308 * 12.92, 1e-12);
  EXPECT_NEAR(1.055 * std::pow(0.0031308, 1 / 2.4) - 0.055, 0.0031308 * 12.92, 1e-7);
  EXPECT_NEAR(SrgbEncode(1.0), 1.0, 1e-15);
  EXPECT_NEAR(SrgbEncode(0.5), 0.735356983, 1e-8);
  for (double x : {0.0, 0.001, 0.0031308, 0.02, 0.18, 0.5, 0.9, 1.0}) {
    EXPECT_NEAR(SrgbDecode(SrgbEncode(x)), x, 1e-12) << x;
  }
  EXPECT_EQ(SrgbEncode(-1.0), 0.0);
  EXPECT_EQ(SrgbEncode(7.0), 1.0);
}

TEST(ImageIo, ToneMapping) {
  EXPECT_EQ(ToSrgb8(0.0), 0);
  EXPECT_EQ(ToSrgb8(1.0), 255);
  EXPECT_EQ(ToSrgb8(0.5), 188);  // 255·0.73536 = 187.5
  EXPECT_EQ(ToSrgb8(40.0), 255);
  EXPECT_EQ(ToSrgb8(std::nan("")), 0);
  EXPECT_EQ(ToSrgb8(0.25, {2.0, ToneMap::kClamp}), 188);
  EXPECT_EQ(ToSrgb8(1.0, {1.0, ToneMap::kReinhard}), 188);  // 1 / (1 + 1) = 0.5
  EXPECT_EQ(ToSrgb8(1e30, {1.0, ToneMap::kReinhard}), 255);
}

// Written with libpng, read back with libpng: the expected 8-bit sRGB codes.
TEST(ImageIo, PngRoundTripsThroughLibpng) {
  const fs::path dir = TempDir();
  ImageRgb img(4, 3);
  const float values[4] = {0.0f, 0.5f, 1.0f, 0.0031308f};
  for (int y = 0; y < 3; ++y) {
    for (int x = 0; x < 4; ++x) {
      float* p = img.At(x, y);
      p[0] = values[x];
      p[1] = values[(x + y) % 4];
      p[2] = 2.0f * static_cast<float>(y);
    }
  }
  const std::string path = (dir / "t.png").string();
  WritePng(img, path);
  png_image png;
  std::memset(&png, 0, sizeof(png));
  png.version = PNG_IMAGE_VERSION;
  ASSERT_TRUE(png_image_begin_read_from_file(&png, path.c_str())) << png.message;
  ASSERT_EQ(png.width, 4u);
  ASSERT_EQ(png.height, 3u);
  png.format = PNG_FORMAT_RGB;
  std::vector<unsigned char> bytes(PNG_IMAGE_SIZE(png));
  ASSERT_TRUE(png_image_finish_read(&png, nullptr, bytes.data(), 0, nullptr)) << png.message;
  const unsigned char codes[4] = {0, 188, 255, 10};  // 255·0.040449936 = 10.3
  for (int y = 0; y < 3; ++y) {
    for (int x = 0; x < 4; ++x) {
      const unsigned char* p = &bytes[3 * (static_cast<std::size_t>(y) * 4 + x)];
      EXPECT_EQ(p[0], codes[x]) << x << "," << y;
      EXPECT_EQ(p[1], codes[(x + y) % 4]) << x << "," << y;
      EXPECT_EQ(p[2], y == 0 ? 0 : 255) << x << "," << y;
    }
  }
  fs::remove_all(dir);
}

TEST(ImageIo, UnwritablePathThrowsNamingTheFile) {
  const ImageRgb img(2, 2);
  const std::string bad = "/nonexistent-dir-prt/sub/out.png";
  try {
    WritePng(img, bad);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(bad), std::string::npos) << e.what();
  }
  EXPECT_THROW(WriteExr(img, "/nonexistent-dir-prt/sub/out.exr"), InputError);
}

TEST(ImageIo, ExrRoundTrips) {
  const fs::path dir = TempDir();
  ImageRgb img(5, 2);
  for (std::size_t i = 0; i < img.pixels.size(); ++i)
    img.pixels[i] = 0.1f * static_cast<float>(i) + 1e-3f;
  const std::string path = (dir / "t.exr").string();
  WriteExr(img, path);
  Imf::InputFile file(path.c_str());
  const Imath::Box2i dw = file.header().dataWindow();
  ASSERT_EQ(dw.max.x - dw.min.x + 1, 5);
  std::vector<float> back(img.pixels.size());
  Imf::FrameBuffer fb;
  const char* names[3] = {"R", "G", "B"};
  for (int c = 0; c < 3; ++c) {
    fb.insert(names[c], Imf::Slice::Make(Imf::FLOAT, back.data() + c, dw, 3 * sizeof(float),
                                         15 * sizeof(float)));
  }
  file.setFrameBuffer(fb);
  file.readPixels(dw.min.y, dw.max.y);
  for (std::size_t i = 0; i < back.size(); ++i) EXPECT_EQ(back[i], img.pixels[i]);
  fs::remove_all(dir);
}

TEST(ImageIo, SideBySideAndDifference) {
  ImageRgb a(2, 1), b(2, 1);
  a.pixels = {1, 2, 3, 4, 5, 6};
  b.pixels = {1, 1, 1, 5, 5, 5};
  const ImageRgb d = AbsDifference(a, b, 10);
  EXPECT_EQ(d.pixels, (std::vector<float>{0, 10, 20, 10, 0, 10}));
  const ImageRgb s = SideBySide(a, b, true, 10);
  ASSERT_EQ(s.width, 6);
  ASSERT_EQ(s.height, 1);
  EXPECT_EQ(s.At(1, 0)[2], 6);
  EXPECT_EQ(s.At(2, 0)[0], 1);
  EXPECT_EQ(s.At(5, 0)[2], 10);
  EXPECT_THROW(AbsDifference(a, ImageRgb(1, 1)), std::invalid_argument);
}

TEST(ImageIo, FalseColourRamp) {
  const auto lo = FalseColour(0), mid = FalseColour(0.5), hi = FalseColour(1);
  EXPECT_GT(lo[2], lo[0]);  // dark blue at 0
  EXPECT_GT(hi[0], hi[2]);  // red at 1
  EXPECT_GT(mid[1], 0.5f);  // bright green in the middle
  EXPECT_EQ(FalseColour(-3), lo);
  EXPECT_EQ(FalseColour(std::nan("")), (std::array<float, 3>{0, 0, 0}));
  const ImageRgb img = FalseColourImage({0, 1, 2, 3}, 2, 2, 0, 3);
  EXPECT_EQ(img.At(0, 0)[2], lo[2]);
  EXPECT_EQ(img.At(1, 1)[0], hi[0]);
}

}  // namespace
}  // namespace prt
