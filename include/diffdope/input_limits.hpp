#pragma once
// The limits every input file meets, in one place: a file that exceeds one is refused with a message naming it,
// before it costs time or memory. Mesh-specific limits (vertices, triangles, texture pixels) are
// MeshLoadOptions' (mesh.hpp).
#include <cstdint>

namespace diffdope::input_limits {

/// Nesting depth of a JSON or YAML file (camera, pose, BOP files, configs): a deeper one is no such file, and
/// reading it recursively would exhaust the stack.
constexpr int kMaxNesting = 64;
/// Nodes a YAML file may expand to, aliases counted each time they are used (a "billion laughs" of a few
/// hundred bytes would otherwise expand to gigabytes).
constexpr long long kMaxYamlNodes = 100000;
/// Size of a camera, pose or options file.
constexpr std::uintmax_t kMaxTextFileBytes = std::uintmax_t(64) << 20;
/// Pixels of an input image (rgb, depth, mask), read from the file's header before decoding: 2^25 (e.g.
/// 8192 x 4096) is beyond any depth camera and keeps a decoded float RGB copy under 0.5 GB.
constexpr long long kMaxImagePixels = 1LL << 25;
/// Size of an image file, input or texture (compressed; an uncompressed 8192^2 RGB PNG is 200 MB).
constexpr std::uintmax_t kMaxImageFileBytes = std::uintmax_t(256) << 20;

/// Captures of one calibration (files, or the node's samples): three to ten constrain every direction; each holds
/// its images as floats (about 5 MB at 640 x 480), so hundreds would only cost memory.
constexpr int kMaxCaptures = 64;
/// Distance of a URDF joint's or visual's origin from its parent (metres).
constexpr double kMaxRobotOffset = 1000.0;

}  // namespace diffdope::input_limits
