// run/image.prti (formats/image_file.h): round trip, and every hostile byte string an InputError.
#include "formats/image_file.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <string>

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
