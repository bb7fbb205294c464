// Image output (PNG 8-bit sRGB via stb_image_write, EXR float via tinyexr) and the image error
// (PSNR) used to compare a lossy format's render with the uncompressed one (docs/benchmark.md).
// PSNR is measured on exactly the 8-bit values the PNG writer stores.
#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include "slimrt/output.h"
#include "slimrt/render.h"

// Debian's libstb.so exports stbi_write_png; when the build links it (and defines
// SLIM_HAVE_LIBSTB) the implementation below is not compiled. Otherwise it is compiled here with
// internal linkage, so it can never clash with another copy.
#ifndef SLIM_HAVE_LIBSTB
#define STB_IMAGE_WRITE_STATIC
#define STB_IMAGE_WRITE_IMPLEMENTATION
#endif
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wunused-function"
#pragma GCC diagnostic ignored "-Wmissing-field-initializers"
#include <stb/stb_image_write.h>
#pragma GCC diagnostic pop

#include <tinyexr.h>

namespace slim {

namespace {

// Linear float -> 8-bit sRGB: clamp to [0, 1] (NaN -> 0), sRGB transfer curve, round to nearest.
uint8_t to_srgb8(float v) {
  if (!(v > 0.0f)) return 0;
  if (v >= 1.0f) return 255;
  float s = v <= 0.0031308f ? 12.92f * v : 1.055f * std::pow(v, 1.0f / 2.4f) - 0.055f;
  return uint8_t(std::min(255.0f, s * 255.0f + 0.5f));
}

void check_image(const Image& img, const std::string& what) {
  if (img.width <= 0 || img.height <= 0 ||
      img.rgb.size() != size_t(img.width) * size_t(img.height) * 3)
    throw Error(what + ": image is " + std::to_string(img.width) + "x" +
                std::to_string(img.height) + " with " + std::to_string(img.rgb.size()) +
                " floats, expected a positive size and 3 floats per pixel");
}

std::string lower_extension(const std::string& path) {
  size_t dot = path.find_last_of('.');
  size_t slash = path.find_last_of("/\\");
  if (dot == std::string::npos || (slash != std::string::npos && dot < slash)) return "";
  std::string ext = path.substr(dot);
  for (char& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
  return ext;
}

std::vector<uint8_t> to_srgb8(const Image& img) {
  std::vector<uint8_t> out(img.rgb.size());
  for (size_t i = 0; i < out.size(); ++i) out[i] = to_srgb8(img.rgb[i]);
  return out;
}

// The EXR bytes (3 float channels stored B, G, R as most viewers expect; ZIP-compressed from
// 16x16 up, as tinyexr's SaveEXR does), built in memory so that the file goes through
// write_file_atomically like every other output.
std::string exr_bytes(const Image& img, const std::string& path) {
  const size_t n = size_t(img.width) * size_t(img.height);
  std::vector<float> planes[3];
  for (int c = 0; c < 3; ++c) {
    planes[c].resize(n);
    for (size_t i = 0; i < n; ++i) planes[c][i] = img.rgb[3 * i + size_t(2 - c)];  // B, G, R
  }
  float* ptrs[3] = {planes[0].data(), planes[1].data(), planes[2].data()};
  EXRImage image;
  InitEXRImage(&image);
  image.num_channels = 3;
  image.images = reinterpret_cast<unsigned char**>(ptrs);
  image.width = img.width;
  image.height = img.height;
  EXRHeader header;
  InitEXRHeader(&header);
  header.compression_type = img.width < 16 && img.height < 16 ? TINYEXR_COMPRESSIONTYPE_NONE
                                                              : TINYEXR_COMPRESSIONTYPE_ZIP;
  EXRChannelInfo channels[3] = {};
  int types[3] = {TINYEXR_PIXELTYPE_FLOAT, TINYEXR_PIXELTYPE_FLOAT, TINYEXR_PIXELTYPE_FLOAT};
  int requested[3] = {TINYEXR_PIXELTYPE_FLOAT, TINYEXR_PIXELTYPE_FLOAT, TINYEXR_PIXELTYPE_FLOAT};
  for (int c = 0; c < 3; ++c) channels[c].name[0] = "BGR"[c];
  header.num_channels = 3;
  header.channels = channels;
  header.pixel_types = types;
  header.requested_pixel_types = requested;
  unsigned char* mem = nullptr;
  const char* err = nullptr;
  const size_t size = SaveEXRImageToMemory(&image, &header, &mem, &err);
  if (size == 0 || !mem) {
    std::string why = err ? err : "tinyexr returned no data";
    if (err) FreeEXRErrorMessage(err);
    std::free(mem);
    throw Error(path + ": cannot encode EXR: " + why);
  }
  std::string out(reinterpret_cast<const char*>(mem), size);
  std::free(mem);
  return out;
}

void append_bytes(void* context, void* data, int size) {
  static_cast<std::string*>(context)->append(static_cast<const char*>(data), size_t(size));
}

}  // namespace

void write_image(const Image& img, const std::string& path) {
  std::string ext = lower_extension(path);
  if (ext != ".png" && ext != ".exr")
    throw Error(path + ": unknown image extension, expected .png or .exr");
  check_image(img, path);
  std::string bytes;
  try {
    if (ext == ".png") {
      const std::vector<uint8_t> pixels = to_srgb8(img);
      if (!stbi_write_png_to_func(append_bytes, &bytes, img.width, img.height, 3, pixels.data(),
                                  img.width * 3))
        throw Error(path + ": cannot encode PNG (stb_image_write failed)");
    } else {
      bytes = exr_bytes(img, path);
    }
  } catch (const std::bad_alloc&) {
    throw Error(path + ": out of memory while encoding a " + std::to_string(img.width) + "x" +
                std::to_string(img.height) + " image");
  }
  write_file_atomically(path, bytes);
}

double psnr(const Image& a, const Image& b) {
  if (a.width != b.width || a.height != b.height)
    throw Error("psnr: image sizes differ: " + std::to_string(a.width) + "x" +
                std::to_string(a.height) + " vs " + std::to_string(b.width) + "x" +
                std::to_string(b.height));
  if (a.width == 0 && a.height == 0 && a.rgb.empty() && b.rgb.empty())
    return std::numeric_limits<double>::infinity();
  check_image(a, "psnr");
  check_image(b, "psnr");
  uint64_t sum_sq = 0;
  for (size_t i = 0; i < a.rgb.size(); ++i) {
    int d = int(to_srgb8(a.rgb[i])) - int(to_srgb8(b.rgb[i]));
    sum_sq += uint64_t(d * d);
  }
  if (sum_sq == 0) return std::numeric_limits<double>::infinity();
  double mse = double(sum_sq) / double(a.rgb.size());
  return 10.0 * std::log10(255.0 * 255.0 / mse);
}

}  // namespace slim
