#pragma once
// Read-only views of a texture and its mip pyramid, as kernels see them (host or device memory).

namespace diffdope {

/// One RGB float image, row 0 = top image row, 3 floats per texel in [0, 1].
struct TextureLevelView {
  const float* rgb;
  int width, height;
};

/// A texture with its mip pyramid (level 0 = full size, each next level half the size).
constexpr int kMaxTextureLevels = 16;
struct TextureView {
  TextureLevelView level[kMaxTextureLevels];
  int levels;
};

}  // namespace diffdope
