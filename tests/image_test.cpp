// image_test.cpp: OpenEXR / Radiance / PNG files, orientation, errors and sRGB transfer.
#include "src/image.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "tests/test_util.h"

namespace kiln {
namespace {

namespace fs = std::filesystem;

Image testImage(int w, int h, int channels) {
  Image image(w, h, channels);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int c = 0; c < channels; ++c)
        image.at(x, y)[c] = 0.1f * x + 1.7f * y + 0.013f * c + (c == 3 ? 0.25f : 0.0f) + 1e-3f;
  return image;
}

void writeBytes(const std::string& path, const std::string& bytes) {
  std::ofstream f(path, std::ios::binary);
  f.write(bytes.data(), std::streamsize(bytes.size()));
}

bool hasTmpFiles(const std::string& dir) {
  for (const auto& entry : fs::directory_iterator(dir))
    if (entry.path().extension() == ".tmp") return true;
  return false;
}

TEST(Image, RgbOfOneAndThreeChannels) {
  Image grey(2, 1, 1);
  grey.at(1, 0)[0] = 0.5f;
  EXPECT_EQ(grey.rgb(1, 0), vec3(0.5f));
  Image colour(1, 2, 4);
  colour.at(0, 1)[0] = 1;
  colour.at(0, 1)[1] = 2;
  colour.at(0, 1)[2] = 3;
  EXPECT_EQ(colour.rgb(0, 1), vec3(1, 2, 3));
}

TEST(Exr, FloatRoundTripIsExact) {
  std::string dir = test::makeTempDir("kiln_image");
  Image image = testImage(7, 5, 3);
  image.at(2, 3)[1] = 1e-20f;
  image.at(4, 1)[0] = 123456.789f;
  std::string path = dir + "/float.exr";
  ASSERT_TRUE(writeExr(path, image, true).ok());
  auto back = readHdrImage(path);
  ASSERT_TRUE(back.ok()) << back.error();
  EXPECT_EQ(back->width, 7);
  EXPECT_EQ(back->height, 5);
  EXPECT_EQ(back->channels, 3);
  EXPECT_EQ(back->pixels, image.pixels);
  EXPECT_FALSE(hasTmpFiles(dir));
}

TEST(Exr, HalfRoundTripWithinHalfPrecision) {
  std::string dir = test::makeTempDir("kiln_image");
  Image image = testImage(9, 4, 3);
  image.at(0, 0)[0] = 1e6f;  // beyond half's range: clamped to the largest half
  std::string path = dir + "/half.exr";
  ASSERT_TRUE(writeExr(path, image).ok());
  auto back = readHdrImage(path);
  ASSERT_TRUE(back.ok()) << back.error();
  ASSERT_EQ(back->pixels.size(), image.pixels.size());
  EXPECT_EQ(back->pixels[0], 65504.0f);
  for (size_t i = 1; i < image.pixels.size(); ++i)
    EXPECT_NEAR(back->pixels[i], image.pixels[i], std::abs(image.pixels[i]) * 4.9e-4f) << i;
}

TEST(Exr, RgbaRoundTripAndOrientation) {
  std::string dir = test::makeTempDir("kiln_image");
  Image image(3, 2, 4);
  // Only pixel (x = 1, y = 0), in the top row, is bright.
  float* p = image.at(1, 0);
  p[0] = 1.0f;
  p[1] = 2.0f;
  p[2] = 3.0f;
  p[3] = 0.5f;
  std::string path = dir + "/rgba.exr";
  ASSERT_TRUE(writeExr(path, image).ok());
  auto back = readHdrImage(path);
  ASSERT_TRUE(back.ok()) << back.error();
  ASSERT_EQ(back->channels, 4);
  EXPECT_EQ(back->pixels, image.pixels);  // all values exact in half
  EXPECT_EQ(back->rgb(1, 0), vec3(1, 2, 3));
  EXPECT_EQ(back->at(1, 0)[3], 0.5f);
  EXPECT_EQ(back->rgb(1, 1), vec3(0.0f));
}

TEST(Exr, GreyImageIsWrittenAsRgb) {
  std::string dir = test::makeTempDir("kiln_image");
  Image image(2, 2, 1);
  image.at(1, 1)[0] = 0.75f;
  ASSERT_TRUE(writeExr(dir + "/grey.exr", image).ok());
  auto back = readHdrImage(dir + "/grey.exr");
  ASSERT_TRUE(back.ok()) << back.error();
  EXPECT_EQ(back->channels, 3);
  EXPECT_EQ(back->rgb(1, 1), vec3(0.75f));
}

TEST(Exr, OverwritesAtomically) {
  std::string dir = test::makeTempDir("kiln_image");
  std::string path = dir + "/a.exr";
  ASSERT_TRUE(writeExr(path, testImage(2, 2, 3)).ok());
  ASSERT_TRUE(writeExr(path, testImage(4, 3, 3)).ok());
  auto back = readHdrImage(path);
  ASSERT_TRUE(back.ok());
  EXPECT_EQ(back->width, 4);
  EXPECT_FALSE(hasTmpFiles(dir));
}

TEST(Exr, FailedWriteLeavesNothingBehind) {
  std::string dir = test::makeTempDir("kiln_image");
  std::string path = dir + "/missing_dir/out.exr";
  Status s = writeExr(path, testImage(2, 2, 3));
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.error().find(path), std::string::npos) << s.error();
  EXPECT_FALSE(fs::exists(path));
  EXPECT_FALSE(fs::exists(path + ".tmp"));

  // A directory where the file should go: the rename fails and the temp file is removed.
  std::string blocked = dir + "/blocked.exr";
  fs::create_directories(blocked + "/child");
  s = writeExr(blocked, testImage(2, 2, 3));
  EXPECT_FALSE(s.ok());
  EXPECT_FALSE(fs::exists(blocked + ".tmp"));
  EXPECT_FALSE(hasTmpFiles(dir));
}

TEST(Exr, TruncatedFileIsAnError) {
  std::string dir = test::makeTempDir("kiln_image");
  std::string path = dir + "/full.exr";
  ASSERT_TRUE(writeExr(path, testImage(64, 64, 3), true).ok());
  std::string bytes = test::readTextFile(path);
  for (size_t keep : {bytes.size() / 2, size_t(100), size_t(10)}) {
    std::string cut = dir + "/cut.exr";
    writeBytes(cut, bytes.substr(0, keep));
    auto r = readHdrImage(cut);
    EXPECT_FALSE(r.ok()) << keep;
    EXPECT_NE(r.error().find(cut), std::string::npos) << r.error();
  }
}

TEST(ReadHdrImage, MissingAndGarbageFiles) {
  std::string dir = test::makeTempDir("kiln_image");
  auto missing = readHdrImage(dir + "/nope.exr");
  ASSERT_FALSE(missing.ok());
  EXPECT_NE(missing.error().find("nope.exr"), std::string::npos) << missing.error();

  std::string garbage = dir + "/garbage.hdr";
  test::writeTextFile(garbage, "this is not an image at all, just some text\n");
  auto g = readHdrImage(garbage);
  ASSERT_FALSE(g.ok());
  EXPECT_NE(g.error().find("garbage.hdr"), std::string::npos) << g.error();

  std::string empty = dir + "/empty.exr";
  test::writeTextFile(empty, "");
  EXPECT_FALSE(readHdrImage(empty).ok());

  // Right magic, garbage after it.
  std::string fakeExr = dir + "/fake.exr";
  writeBytes(fakeExr, std::string("\x76\x2f\x31\x01\x02\0\0\0garbage garbage garbage", 31));
  auto f = readHdrImage(fakeExr);
  ASSERT_FALSE(f.ok());
  EXPECT_NE(f.error().find("fake.exr"), std::string::npos) << f.error();
}

TEST(ReadHdrImage, RadianceFlatRgbe) {
  std::string dir = test::makeTempDir("kiln_image");
  std::string path = dir + "/tiny.hdr";
  // 3 x 2 pixels, top row first ("-Y 2 +X 3"), uncompressed RGBE (widths < 8 are never RLE).
  // Value = mantissa * 2^(e - 136).
  std::string bytes = "#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 2 +X 3\n";
  const unsigned char rgbe[6][4] = {{128, 64, 32, 129}, {0, 0, 0, 0},       {128, 128, 128, 128},
                                    {0, 0, 0, 0},       {200, 0, 100, 136}, {1, 2, 3, 140}};
  for (const auto& p : rgbe) bytes.append(reinterpret_cast<const char*>(p), 4);
  writeBytes(path, bytes);
  auto r = readHdrImage(path);
  ASSERT_TRUE(r.ok()) << r.error();
  ASSERT_EQ(r->width, 3);
  ASSERT_EQ(r->height, 2);
  ASSERT_EQ(r->channels, 3);
  EXPECT_EQ(r->rgb(0, 0), vec3(1.0f, 0.5f, 0.25f));
  EXPECT_EQ(r->rgb(1, 0), vec3(0.0f));
  EXPECT_EQ(r->rgb(2, 0), vec3(0.5f));
  EXPECT_EQ(r->rgb(1, 1), vec3(200.0f, 0.0f, 100.0f));
  EXPECT_EQ(r->rgb(2, 1), vec3(16.0f, 32.0f, 48.0f));
}

TEST(ReadHdrImage, SharedUffizi) {
  if (!test::sharedAvailable()) GTEST_SKIP() << "../shared not present";
  std::string path = test::sharedDir() + "/scenes/envmaps/uffizi.hdr";
  if (!fs::exists(path)) GTEST_SKIP() << path << " not present";
  auto r = readHdrImage(path);
  ASSERT_TRUE(r.ok()) << r.error();
  EXPECT_EQ(r->width, 256);
  EXPECT_EQ(r->height, 128);
  EXPECT_EQ(r->channels, 3);
  double maxValue = 0.0;
  for (float v : r->pixels) {
    ASSERT_TRUE(std::isfinite(v));
    ASSERT_GE(v, 0.0f);
    maxValue = std::max(maxValue, double(v));
  }
  EXPECT_GT(maxValue, 1.0);  // a real HDR: something brighter than white
}

TEST(Png, WritesAtomically) {
  std::string dir = test::makeTempDir("kiln_image");
  Image image(4, 3, 3);
  image.at(1, 0)[0] = 2.0f;  // clamped
  ASSERT_TRUE(writePng(dir + "/a.png", image).ok());
  std::string bytes = test::readTextFile(dir + "/a.png");
  ASSERT_GE(bytes.size(), 8u);
  EXPECT_EQ(bytes.substr(1, 3), "PNG");
  EXPECT_FALSE(hasTmpFiles(dir));
  // PNG is not an HDR format: readHdrImage refuses it by name.
  auto r = readHdrImage(dir + "/a.png");
  EXPECT_FALSE(r.ok());

  Status s = writePng(dir + "/missing/a.png", image);
  EXPECT_FALSE(s.ok());
  EXPECT_FALSE(fs::exists(dir + "/missing/a.png.tmp"));
}

TEST(Srgb, KnownValuesAndInverse) {
  EXPECT_NEAR(srgbToLinear(0.5f), 0.214041f, 1e-6f);
  EXPECT_FLOAT_EQ(srgbToLinear(0.0f), 0.0f);
  EXPECT_FLOAT_EQ(srgbToLinear(1.0f), 1.0f);
  EXPECT_FLOAT_EQ(srgbToLinear(0.04045f), 0.04045f / 12.92f);  // linear segment
  EXPECT_NEAR(linearToSrgb(0.214041f), 0.5f, 1e-6f);
  EXPECT_FLOAT_EQ(linearToSrgb(1.0f), 1.0f);
  EXPECT_FLOAT_EQ(linearToSrgb(0.001f), 0.01292f);
  for (int i = 0; i <= 1000; ++i) {
    float c = i / 1000.0f;
    EXPECT_NEAR(linearToSrgb(srgbToLinear(c)), c, 2e-6f) << c;
    EXPECT_NEAR(srgbToLinear(linearToSrgb(c)), c, 2e-6f) << c;
  }
}

}  // namespace
}  // namespace kiln
