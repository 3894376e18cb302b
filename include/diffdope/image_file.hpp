#pragma once
// Reading an image file safely: only a regular file, only a format whose header states its size (PNG, JPEG, BMP,
// TIFF, PNM), its pixels counted before anything is decoded, and the pixels as stored (no EXIF rotation: a
// camera's image is never turned).
#include <opencv2/core.hpp>
#include <string>

namespace diffdope {

/// Width and height from an encoded image's header, without decoding: PNG, JPEG (bytes between segments skipped,
/// as decoders do), BMP, TIFF (classic, first page) and PNM (P1-P6). False for other formats or a header cut short.
bool image_header_size(const std::string& bytes, long long* width, long long* height);

/// Decodes the image at `path` (cv::imread `flags`; EXIF orientation is ignored). Throws InputFileError
/// (input_files.hpp) naming the file when it is not a regular file, is larger than
/// input_limits::kMaxImageFileBytes, has a format whose size cannot be read from its header, holds more than
/// `max_pixels` pixels, or cannot be decoded. `kind` (e.g. "rgb") is said in the messages.
cv::Mat read_image_file(const std::string& path, int flags, const std::string& kind, long long max_pixels);

}  // namespace diffdope
