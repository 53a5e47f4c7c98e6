// image.cpp: reading OpenEXR and Radiance HDR images, writing OpenEXR and PNG atomically.
//
// OpenEXR's data window has y growing downwards, and stb_image returns the top row first,
// so both already match kiln's row 0 = top convention; nothing is flipped.
#include "src/image.h"

#include <Imath/half.h>
#include <OpenEXR/ImfArray.h>
#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfCompression.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfInputFile.h>
#include <OpenEXR/ImfOutputFile.h>
#include <OpenEXR/ImfRgba.h>
#include <OpenEXR/ImfRgbaFile.h>
#include <stb_image.h>
#include <stb_image_write.h>

#include <algorithm>
#include <cassert>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <exception>
#include <filesystem>
#include <fstream>

#include "src/text_file.h"

namespace kiln {

vec3 Image::rgb(int x, int y) const {
  const float* p = at(x, y);
  if (channels >= 3) return vec3(p[0], p[1], p[2]);
  return vec3(p[0]);  // grey, or grey + alpha
}

namespace {

// The pixel budget of an HDR image (a sky map, a lightmap page read back): larger images are
// refused from their header, before anything is allocated. 2^25 pixels is an 8192 x 4096
// equirectangular map; a sky map costs about 36 bytes a pixel once its sampling tables are
// built, so a 16384^2 map took 9.7 GB (docs/limits.md).
constexpr int64_t kMaxPixels = int64_t(1) << 25;

std::string budgetMessage(int64_t w, int64_t h, const char* format) {
  return std::string(format) + " image of " + std::to_string(w) + " x " + std::to_string(h) +
         " pixels is empty or larger than kiln's budget of " + std::to_string(kMaxPixels) +
         " pixels (8192 x 4096): downsample it";
}

Error fileError(const std::string& path, const std::string& what) {
  return Error{path + ": " + what};
}

Result<Image> readRadiance(const std::string& path) {
  int w = 0, h = 0, comp = 0;
  if (stbi_info(path.c_str(), &w, &h, &comp) && int64_t(w) * h > kMaxPixels)
    return fileError(path, budgetMessage(w, h, "Radiance HDR"));
  stbi_set_flip_vertically_on_load(false);
  float* data = stbi_loadf(path.c_str(), &w, &h, &comp, 3);
  if (!data) {
    const char* reason = stbi_failure_reason();
    return fileError(path, std::string("cannot read Radiance HDR image (") +
                               (reason ? reason : "unknown error") + ")");
  }
  Image image(w, h, 3);
  std::memcpy(image.pixels.data(), data, image.pixels.size() * sizeof(float));
  stbi_image_free(data);
  return image;
}

Result<Image> readExr(const std::string& path) {
  try {
    Imf::InputFile file(path.c_str());
    const Imf::Header& header = file.header();
    Imath::Box2i dw = header.dataWindow();
    int64_t w = int64_t(dw.max.x) - dw.min.x + 1, h = int64_t(dw.max.y) - dw.min.y + 1;
    if (w <= 0 || h <= 0 || w * h > kMaxPixels)
      return fileError(path, budgetMessage(w, h, "OpenEXR"));
    if (!file.isComplete()) return fileError(path, "OpenEXR file is truncated or incomplete");
    const Imf::ChannelList& channels = header.channels();
    auto has = [&](const char* name) { return channels.findChannel(name) != nullptr; };
    bool rgb = has("R") || has("G") || has("B");
    bool alpha = has("A");

    if (!rgb && has("Y") && (has("RY") || has("BY"))) {
      // Luminance/chroma file: let the RGBA interface reconstruct RGB (half precision).
      Imf::RgbaInputFile rgbaFile(path.c_str());
      Imf::Array2D<Imf::Rgba> buffer(h, w);
      rgbaFile.setFrameBuffer(&buffer[0][0] - dw.min.x - dw.min.y * w, 1, size_t(w));
      rgbaFile.readPixels(dw.min.y, dw.max.y);
      Image image(int(w), int(h), alpha ? 4 : 3);
      for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
          const Imf::Rgba& p = buffer[y][x];
          float* q = image.at(x, y);
          q[0] = p.r;
          q[1] = p.g;
          q[2] = p.b;
          if (alpha) q[3] = p.a;
        }
      return image;
    }

    // Otherwise read R, G, B (missing ones filled with 0) and A as floats; a file without
    // colour channels gives grey from Y, or else from its first channel.
    const char* greyName = nullptr;
    if (!rgb) {
      if (has("Y")) {
        greyName = "Y";
      } else if (channels.begin() != channels.end()) {
        greyName = channels.begin().name();
      } else {
        return fileError(path, "OpenEXR file has no channels");
      }
      const Imf::Channel* c = channels.findChannel(greyName);
      if (c->xSampling != 1 || c->ySampling != 1)
        return fileError(path, std::string("OpenEXR channel ") + greyName + " is subsampled");
    }
    int n = alpha ? 4 : 3;
    Image image(int(w), int(h), n);
    Imf::FrameBuffer fb;
    char* base = reinterpret_cast<char*>(image.pixels.data());
    size_t xStride = sizeof(float) * n, yStride = xStride * size_t(w);
    auto slice = [&](int offset, double fill) {
      return Imf::Slice::Make(Imf::FLOAT, base + offset * sizeof(float), dw, xStride, yStride, 1, 1,
                              fill);
    };
    if (rgb) {
      fb.insert("R", slice(0, 0.0));
      fb.insert("G", slice(1, 0.0));
      fb.insert("B", slice(2, 0.0));
    } else {
      fb.insert(greyName, slice(0, 0.0));
    }
    if (alpha) fb.insert("A", slice(3, 1.0));
    file.setFrameBuffer(fb);
    file.readPixels(dw.min.y, dw.max.y);
    if (!rgb)
      for (size_t i = 0; i < size_t(w) * size_t(h); ++i)
        image.pixels[i * n + 1] = image.pixels[i * n + 2] = image.pixels[i * n];
    return image;
  } catch (const std::exception& e) {
    return fileError(path, std::string("cannot read OpenEXR image (") + e.what() + ")");
  } catch (...) {
    return fileError(path, "cannot read OpenEXR image (unknown error)");
  }
}

// Writes through `write` into path.tmp, then renames it over `path`. On any failure the
// temporary file is removed and `path` is left as it was.
template <typename WriteFn>
Status writeAtomically(const std::string& path, WriteFn&& write) {
  std::string tmp = path + ".tmp";
  std::error_code ec;
  std::string failure;
  try {
    failure = write(tmp);
  } catch (const std::exception& e) {
    failure = e.what();
  } catch (...) {
    failure = "unknown error";
  }
  if (failure.empty()) {
    std::filesystem::rename(tmp, path, ec);
    if (!ec) return Status::success();
    failure = "cannot rename " + tmp + " (" + ec.message() + ")";
  }
  std::filesystem::remove(tmp, ec);
  return fileError(path, "cannot write image (" + failure + ")");
}

float toHalfRange(float v) {
  // Finite values beyond half's range would become infinities; clamp them instead.
  constexpr float kHalfMax = 65504.0f;
  return std::isfinite(v) ? std::clamp(v, -kHalfMax, kHalfMax) : v;
}

}  // namespace

Result<Image> readHdrImage(const std::string& path) {
  // Regular files only: a FIFO would block the open, a device never end.
  if (Status regular = checkRegularFile(path); !regular) return Error{regular.error()};
  std::ifstream in(path, std::ios::binary);
  if (!in)
    return fileError(path, std::string("cannot open image file (") + std::strerror(errno) + ")");
  char magic[16] = {};
  in.read(magic, sizeof magic);
  size_t got = size_t(in.gcount());
  in.close();
  auto startsWith = [&](const char* s) {
    size_t n = std::strlen(s);
    return got >= n && std::memcmp(magic, s, n) == 0;
  };
  // OpenEXR magic 20000630 = 0x01312f76, stored little-endian.
  static const unsigned char kExrMagic[4] = {0x76, 0x2f, 0x31, 0x01};
  if (got >= 4 && std::memcmp(magic, kExrMagic, 4) == 0) return readExr(path);
  if (startsWith("#?RADIANCE") || startsWith("#?RGBE")) return readRadiance(path);
  if (got == 0) return fileError(path, "image file is empty");
  return fileError(path, "unknown image format (expected OpenEXR or Radiance .hdr)");
}

Status writeExr(const std::string& path, const Image& image, bool fullFloat) {
  assert(!image.empty() && image.channels >= 1 && image.channels <= 4);
  return writeAtomically(path, [&](const std::string& tmp) -> std::string {
    const int w = image.width, h = image.height;
    const bool alpha = image.channels == 4;
    const int n = alpha ? 4 : 3;
    const Imf::PixelType type = fullFloat ? Imf::FLOAT : Imf::HALF;
    Imf::Header header(w, h);
    header.compression() = Imf::ZIP_COMPRESSION;
    const char* names[4] = {"R", "G", "B", "A"};
    for (int c = 0; c < n; ++c) header.channels().insert(names[c], Imf::Channel(type));

    // Interleaved RGB(A) in the file's pixel type (1- and 2-channel images become grey).
    std::vector<float> floats(size_t(w) * h * n);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        float* q = &floats[(size_t(y) * w + x) * n];
        vec3 c = image.rgb(x, y);
        q[0] = c.r;
        q[1] = c.g;
        q[2] = c.b;
        if (alpha) q[3] = image.at(x, y)[3];
      }
    std::vector<half> halves;
    char* base;
    size_t elem;
    if (fullFloat) {
      base = reinterpret_cast<char*>(floats.data());
      elem = sizeof(float);
    } else {
      halves.resize(floats.size());
      for (size_t i = 0; i < floats.size(); ++i) halves[i] = half(toHalfRange(floats[i]));
      base = reinterpret_cast<char*>(halves.data());
      elem = sizeof(half);
    }
    Imf::FrameBuffer fb;
    for (int c = 0; c < n; ++c)
      fb.insert(names[c], Imf::Slice(type, base + c * elem, elem * n, elem * n * size_t(w)));
    {
      Imf::OutputFile file(tmp.c_str(), header);
      file.setFrameBuffer(fb);
      file.writePixels(h);
    }  // closed (and flushed) before the rename
    return {};
  });
}

Status writePng(const std::string& path, const Image& image) {
  assert(!image.empty() && image.channels >= 1 && image.channels <= 4);
  return writeAtomically(path, [&](const std::string& tmp) -> std::string {
    std::vector<unsigned char> bytes(image.pixels.size());
    for (size_t i = 0; i < bytes.size(); ++i) {
      float v = image.pixels[i];
      v = std::isnan(v) ? 0.0f : std::clamp(v, 0.0f, 1.0f);
      bytes[i] = static_cast<unsigned char>(std::lround(v * 255.0f));
    }
    if (!stbi_write_png(tmp.c_str(), image.width, image.height, image.channels, bytes.data(),
                        image.width * image.channels))
      return "stbi_write_png failed";
    return {};
  });
}

float srgbToLinear(float c) {
  return c <= 0.04045f ? c / 12.92f : std::pow((c + 0.055f) / 1.055f, 2.4f);
}

float linearToSrgb(float c) {
  return c <= 0.0031308f ? 12.92f * c : 1.055f * std::pow(c, 1.0f / 2.4f) - 0.055f;
}

}  // namespace kiln
