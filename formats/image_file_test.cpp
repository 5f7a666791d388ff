// run/image.prti (formats/image_file.h): round trip, and every hostile byte string an InputError.
#include "formats/image_file.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <string>
#include <vector>

#include "vocabulary/errors.h"
#include "vocabulary/hash.h"

namespace prt {
namespace {

ImageSamplesInfo Small() {
  ImageSamplesInfo info;
  info.camera.eye = {0.5, 1.25, 3};
  info.camera.target = {0, 0.25, 0};
  info.camera.fov_deg = 35;
  info.camera.width = 4;
  info.camera.height = 3;
  info.pixel_mesh = {0, 1, 1, kImageBackground, 0, 0, 1, 1, kImageBackground, 0, 1, 0};
  return info;
}

// The bytes with their checksum made right again (so that the content rules are what fails).
std::string Resealed(std::string b) {
  const uint64_t sum = Checksum64(b.data(), b.size() - 8);
  std::memcpy(b.data() + b.size() - 8, &sum, 8);
  return b;
}

TEST(ImageSamplesFile, RoundTripsExactly) {
  const ImageSamplesInfo a = Small();
  const std::string bytes = SerializeImageSamples(a);
  EXPECT_EQ(bytes.size(), 8 + 8 + 80 + 12 * 4 + 8u);
  const ImageSamplesInfo b = ParseImageSamples(bytes, "image.prti", 2);
  EXPECT_EQ(b.camera.width, 4);
  EXPECT_EQ(b.camera.height, 3);
  EXPECT_EQ(b.camera.eye, a.camera.eye);
  EXPECT_EQ(b.camera.target, a.camera.target);
  EXPECT_EQ(b.camera.up, a.camera.up);
  EXPECT_EQ(b.camera.fov_deg, 35.0);
  EXPECT_EQ(b.pixel_mesh, a.pixel_mesh);
}

// Glossy pixels (PRTIMG02): the per-mesh table round trips and weighs the pixels; a table that
// names no glossy mesh writes PRTIMG01's bytes; a bad table is refused.
TEST(ImageSamplesFile, GlossyTableRoundTripsAndWeighsPixels) {
  ImageSamplesInfo a = Small();
  const std::string plain = SerializeImageSamples(a);
  a.glossy_mesh = {0, 0};
  a.glossy_weight = {Rgb{0.5f, 0.5f, 0.5f}, Rgb{0.2f, 0.2f, 0.2f}};
  EXPECT_EQ(SerializeImageSamples(a), plain);
  a.glossy_mesh = {1, 0};
  a.glossy_weight = {Rgb{0.9f, 0.6f, 0.3f}, Rgb{0.f, 0.f, 0.f}};
  const std::string bytes = SerializeImageSamples(a);
  EXPECT_EQ(bytes.substr(0, 8), "PRTIMG02");
  EXPECT_EQ(bytes.size(), plain.size() + 4 + 2 * 16u);
  const ImageSamplesInfo b = ParseImageSamples(bytes, "image.prti", 2);
  EXPECT_EQ(b.pixel_mesh, a.pixel_mesh);
  EXPECT_EQ(b.glossy_mesh, a.glossy_mesh);
  EXPECT_EQ(b.glossy_weight, a.glossy_weight);
  EXPECT_TRUE(b.has_glossy_pixels());
  const std::vector<Rgb> mesh_albedo = {Rgb{0.1f, 0.1f, 0.1f}, Rgb{0.7f, 0.7f, 0.7f}};
  const std::vector<Rgb> w = PixelAlbedo(b, mesh_albedo);
  EXPECT_EQ(w[0], (Rgb{0.9f, 0.6f, 0.3f}));  // glossy mesh 0: its weight
  EXPECT_EQ(w[1], mesh_albedo[1]);           // diffuse mesh 1: its albedo
  EXPECT_EQ(w[3], (Rgb{0.f, 0.f, 0.f}));     // background
  auto refused = [](const std::string& b2, uint32_t meshes) {
    EXPECT_THROW(ParseImageSamples(b2, "run/image.prti", meshes), InputError);
  };
  refused(bytes, 3);  // a table of 2 for 3 meshes
  std::string flag = bytes;
  flag[flag.size() - 8 - 32] = 2;  // mesh 0's flags
  refused(Resealed(flag), 2);
  std::string weight = bytes;
  const float big = 1.5f;
  std::memcpy(weight.data() + weight.size() - 8 - 12, &big, 4);  // mesh 1's red weight
  refused(Resealed(weight), 2);
}

// Supersampled pixels (PRTIMG03): k, per-pixel coverage and weights round trip and weigh the
// pixels (PixelAlbedo, PixelEnvironmentShare); a corrupted coverage or weight is refused.
ImageSamplesInfo Supersampled() {
  ImageSamplesInfo a = Small();
  a.supersample = 4;
  a.coverage.assign(a.pixels(), 1.f);
  a.pixel_weight.assign(a.pixels(), Rgb{0.8f, 0.8f, 0.8f});
  for (std::size_t p = 0; p < a.pixels(); ++p)
    if (a.pixel_mesh[p] == kImageBackground) {
      a.coverage[p] = 0.f;
      a.pixel_weight[p] = Rgb{0.f, 0.f, 0.f};
    }
  a.coverage[1] = 0.375f;
  a.pixel_weight[1] = Rgb{0.3f, 0.2f, 0.1f};
  return a;
}

TEST(ImageSamplesFile, SupersampledPixelsRoundTripAndBlendTheEnvironment) {
  const ImageSamplesInfo a = Supersampled();
  const std::string bytes = SerializeImageSamples(a);
  EXPECT_EQ(bytes.substr(0, 8), "PRTIMG03");
  // An all-diffuse supersampled image writes an empty mesh table.
  EXPECT_EQ(bytes.size(), SerializeImageSamples(Small()).size() + 4 + 4 + 16 * 12u);
  const ImageSamplesInfo b = ParseImageSamples(bytes, "image.prti", 2);
  EXPECT_EQ(b.supersample, 4);
  EXPECT_EQ(b.camera.supersample, 4);
  EXPECT_EQ(b.coverage, a.coverage);
  EXPECT_EQ(b.pixel_mesh, a.pixel_mesh);
  EXPECT_FALSE(b.has_glossy_pixels());
  const std::vector<Rgb> mesh_albedo{Rgb{1.f, 1.f, 1.f}, Rgb{0.5f, 0.5f, 0.5f}};
  const std::vector<Rgb> w = PixelAlbedo(b, mesh_albedo);
  ASSERT_EQ(w.size(), 12u);
  EXPECT_EQ(w[1][0], 0.3f);
  EXPECT_EQ(w[1][2], 0.1f);
  EXPECT_EQ(w[0][0], 0.8f);
  const std::vector<float> share = PixelEnvironmentShare(b);
  EXPECT_EQ(share[1], 0.625f);
  EXPECT_EQ(share[3], 1.f);
  EXPECT_EQ(share[0], 0.f);
  // Without supersampling the share is the background flag.
  const std::vector<float> plain = PixelEnvironmentShare(Small());
  EXPECT_EQ(plain[3], 1.f);
  EXPECT_EQ(plain[1], 0.f);

  // With a glossy mesh the table is written in full and read back.
  ImageSamplesInfo g = Supersampled();
  g.glossy_mesh = {0, 1};
  g.glossy_weight = {Rgb{0.f, 0.f, 0.f}, Rgb{0.9f, 0.9f, 0.9f}};
  const ImageSamplesInfo gb = ParseImageSamples(SerializeImageSamples(g), "image.prti", 2);
  EXPECT_TRUE(gb.has_glossy_pixels());
  EXPECT_EQ(gb.glossy_weight[1][0], 0.9f);
  EXPECT_EQ(gb.pixel_weight[1][0], 0.3f);

  // Hostile: coverage outside [0, 1], a background pixel with coverage, a surface pixel
  // without, a weight that is negative or not finite, k outside 2…16, a truncated table.
  const std::size_t coverage_at = bytes.size() - 8 - 12 * 12 - 12 * 4;
  auto with_float = [&](std::size_t at, float x) {
    std::string c = bytes;
    std::memcpy(c.data() + at, &x, 4);
    return Resealed(c);
  };
  auto refused = [](const std::string& hostile, const std::string& what) {
    try {
      ParseImageSamples(hostile, "image.prti", 2);
      ADD_FAILURE() << "accepted: " << what;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("image.prti"), std::string::npos) << e.what();
    }
  };
  refused(with_float(coverage_at + 4, 1.5f), "coverage 1.5");
  refused(with_float(coverage_at + 4, std::nanf("")), "coverage NaN");
  refused(with_float(coverage_at + 3 * 4, 0.5f), "background pixel with coverage");
  refused(with_float(coverage_at, 0.f), "surface pixel without coverage");
  refused(with_float(coverage_at + 12 * 4 + 4, -0.25f), "negative weight");
  refused(with_float(coverage_at + 12 * 4 + 4, INFINITY), "infinite weight");
  std::string k = bytes;
  const uint32_t one = 1;
  std::memcpy(k.data() + coverage_at - 4, &one, 4);
  refused(Resealed(k), "k = 1");
  std::string cut = bytes.substr(0, bytes.size() - 12);
  cut += bytes.substr(bytes.size() - 8);
  refused(Resealed(cut), "truncated weights");
  // Accepted unchanged: the with_float helper itself.
  EXPECT_NO_THROW(ParseImageSamples(with_float(coverage_at + 4, 0.5f), "image.prti", 2));
}

TEST(ImageSamplesFile, HostileBytesAreInputErrorsNamingTheFile) {
  const std::string good = SerializeImageSamples(Small());
  auto refused = [](const std::string& bytes, uint32_t meshes, const std::string& what) {
    try {
      ParseImageSamples(bytes, "run/image.prti", meshes);
      ADD_FAILURE() << "accepted: " << what;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("run/image.prti"), std::string::npos) << e.what();
    }
  };
  refused("", 2, "empty");
  refused(good.substr(0, 20), 2, "truncated");
  std::string flipped = good;
  flipped[40] ^= 1;
  refused(flipped, 2, "a flipped byte");
  refused(good, 1, "a pixel naming mesh 1 of 1");
  std::string wide = good;
  const uint32_t big = 1u << 20;
  std::memcpy(wide.data() + 8, &big, 4);
  refused(Resealed(wide), 2, "a 2^20-pixel-wide image");
  std::string fov = good;
  const double bad = 180.0;
  std::memcpy(fov.data() + 16 + 72, &bad, 8);
  refused(Resealed(fov), 2, "fov 180");
  std::string nan_eye = good;
  const double nan = std::nan("");
  std::memcpy(nan_eye.data() + 16, &nan, 8);
  refused(Resealed(nan_eye), 2, "a NaN eye");
  std::string more = good;
  more.insert(more.size() - 8, "\0\0\0\0", 4);
  refused(Resealed(more), 2, "a pixel too many");
}

}  // namespace
}  // namespace prt
