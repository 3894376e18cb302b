// Image headers and checked decoding (include/diffdope/image_file.hpp).
#include "diffdope/image_file.hpp"

#include <cctype>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <opencv2/imgcodecs.hpp>

#include "diffdope/input_files.hpp"
#include "diffdope/input_limits.hpp"

namespace diffdope {
namespace {

uint32_t be32(const unsigned char* p) { return uint32_t(p[0]) << 24 | uint32_t(p[1]) << 16 | uint32_t(p[2]) << 8 | p[3]; }

bool jpeg_size(const unsigned char* b, size_t n, long long* w, long long* h) {
  size_t i = 2;
  while (i + 4 <= n) {
    // Bytes before a marker are skipped, as libjpeg does ("extraneous bytes before marker"): the header check must
    // find the frame the decoder will use.
    if (b[i] != 0xFF) {
      ++i;
      continue;
    }
    const unsigned char marker = b[i + 1];
    if (marker == 0xFF) {  // fill byte
      ++i;
      continue;
    }
    if (marker == 0x00 || marker == 0xD8 || marker == 0x01 || (marker >= 0xD0 && marker <= 0xD7)) {  // no length
      i += 2;
      continue;
    }
    if (marker == 0xD9 || marker == 0xDA) return false;  // end of image or scan data before any frame header
    const size_t len = size_t(b[i + 2]) << 8 | b[i + 3];
    if (marker >= 0xC0 && marker <= 0xCF && marker != 0xC4 && marker != 0xC8 && marker != 0xCC) {
      if (i + 9 > n) return false;
      *h = (static_cast<long long>(b[i + 5]) << 8) | b[i + 6];
      *w = (static_cast<long long>(b[i + 7]) << 8) | b[i + 8];
      return true;
    }
    if (len < 2) return false;
    i += 2 + len;
  }
  return false;
}

bool tiff_size(const unsigned char* b, size_t n, long long* w, long long* h) {
  const bool little = b[0] == 'I';
  const auto u16 = [&](size_t at) -> uint32_t { return little ? b[at] | b[at + 1] << 8 : b[at] << 8 | b[at + 1]; };
  const auto u32 = [&](size_t at) -> uint32_t { return little ? u16(at) | u16(at + 2) << 16 : u16(at) << 16 | u16(at + 2); };
  if (u16(2) != 42) return false;  // (43: BigTIFF, not read here)
  const size_t ifd = u32(4);
  if (ifd + 2 > n) return false;
  const size_t entries = u16(ifd);
  long long width = -1, height = -1;
  for (size_t e = 0; e < entries; ++e) {
    const size_t at = ifd + 2 + 12 * e;
    if (at + 12 > n) return false;
    const uint32_t tag = u16(at), type = u16(at + 2);
    if (tag != 256 && tag != 257) continue;
    const long long value = type == 3 ? u16(at + 8) : type == 4 ? u32(at + 8) : -1;  // SHORT or LONG
    if (value < 0) return false;
    (tag == 256 ? width : height) = value;
  }
  if (width < 0 || height < 0) return false;
  *w = width, *h = height;
  return true;
}

bool pnm_size(const unsigned char* b, size_t n, long long* w, long long* h) {
  size_t i = 2;
  long long v[2];
  for (long long& x : v) {
    for (;;) {  // whitespace and comments
      while (i < n && std::isspace(b[i])) ++i;
      if (i < n && b[i] == '#') {
        while (i < n && b[i] != '\n') ++i;
        continue;
      }
      break;
    }
    if (i >= n || !std::isdigit(b[i])) return false;
    x = 0;
    for (int digits = 0; i < n && std::isdigit(b[i]); ++i, ++digits) {
      if (digits >= 10) return false;
      x = 10 * x + (b[i] - '0');
    }
  }
  *w = v[0], *h = v[1];
  return true;
}

}  // namespace

bool image_header_size(const std::string& bytes, long long* w, long long* h) {
  const auto* b = reinterpret_cast<const unsigned char*>(bytes.data());
  const size_t n = bytes.size();
  if (n >= 24 && std::memcmp(b, "\x89PNG\r\n\x1a\n", 8) == 0 && std::memcmp(b + 12, "IHDR", 4) == 0) {
    *w = be32(b + 16), *h = be32(b + 20);
    return true;
  }
  if (n >= 26 && b[0] == 'B' && b[1] == 'M') {
    int32_t bw, bh;
    std::memcpy(&bw, b + 18, 4), std::memcpy(&bh, b + 22, 4);
    *w = std::llabs(bw), *h = std::llabs(bh);
    return true;
  }
  if (n >= 4 && b[0] == 0xFF && b[1] == 0xD8) return jpeg_size(b, n, w, h);
  if (n >= 8 && ((b[0] == 'I' && b[1] == 'I') || (b[0] == 'M' && b[1] == 'M'))) return tiff_size(b, n, w, h);
  if (n >= 3 && b[0] == 'P' && b[1] >= '1' && b[1] <= '6') return pnm_size(b, n, w, h);
  return false;
}

cv::Mat read_image_file(const std::string& path, int flags, const std::string& kind, long long max_pixels) {
  namespace fs = std::filesystem;
  check_input_file(path);
  std::error_code ec;
  const std::uintmax_t size = fs::file_size(path, ec);
  if (ec) throw InputFileError(path, "cannot read the " + kind + " image (" + ec.message() + ")");
  if (size > input_limits::kMaxImageFileBytes)
    throw InputFileError(path, "the " + kind + " image is a file of more than " +
                                   std::to_string(input_limits::kMaxImageFileBytes >> 20) + " MB");
  std::ifstream in(path, std::ios::binary);
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (!in.good() && !in.eof()) throw InputFileError(path, "cannot read the " + kind + " image");
  long long w = 0, h = 0;
  if (!image_header_size(bytes, &w, &h))
    throw InputFileError(path, "cannot read it as an image: the " + kind + " image is not PNG, JPEG, BMP, TIFF or "
                               "PNM, or its header is cut short (its size is checked before decoding)");
  if (w <= 0 || h <= 0 || w > max_pixels || h > max_pixels || w * h > max_pixels)
    throw InputFileError(path, "the " + kind + " image is " + std::to_string(w) + "x" + std::to_string(h) +
                                   " pixels: more than the limit of " + std::to_string(max_pixels) +
                                   " (input_limits.hpp), or empty");
  cv::Mat img;
  try {
    const cv::Mat buf(1, int(bytes.size()), CV_8UC1, bytes.data());
    img = cv::imdecode(buf, flags | cv::IMREAD_IGNORE_ORIENTATION);
  } catch (const cv::Exception& e) {
    throw InputFileError(path, "cannot decode the " + kind + " image (" + e.err + ")");
  }
  if (img.empty()) throw InputFileError(path, "cannot decode the " + kind + " image (corrupt file or unsupported variant)");
  if (img.cols != w || img.rows != h)
    throw InputFileError(path, "the " + kind + " image decodes to " + std::to_string(img.cols) + "x" +
                                   std::to_string(img.rows) + ", not the header's " + std::to_string(w) + "x" +
                                   std::to_string(h));
  return img;
}

}  // namespace diffdope
