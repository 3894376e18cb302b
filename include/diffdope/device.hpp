#pragma once
// Backend selection: device "cpu", "cuda" or "auto" (CUDA when a device is present, else CPU with one log line).
#include <memory>
#include <string>

#include "diffdope/renderer.hpp"

namespace diffdope {

struct CudaDeviceInfo {
  bool built = false;      // compiled with the CUDA backend (diffdope_ros_WITH_CUDA and nvcc)
  bool available = false;  // built and a usable device is present
  std::string name;        // device name and compute capability when available
  std::string reason;      // why not available
};

/// Probes the CUDA runtime once per process (~10 ms without a GPU) and caches the answer.
CudaDeviceInfo cuda_device_info();

/// The CUDA backend: the same render pipeline and stages as the CPU backend, launched as CUDA kernels. Throws std::runtime_error with
/// the reason when it is not built or no device is present.
std::unique_ptr<Renderer> make_cuda_renderer(const RenderOptions& options = {});

/// Renderer for `device`. "auto" falls back to the CPU when CUDA is unavailable and says so in `note` (one
/// line; empty when nothing needs saying). "cuda" without a device throws std::runtime_error naming the
/// reason; an unknown name throws std::invalid_argument.
std::unique_ptr<Renderer> make_renderer(const std::string& device, const RenderOptions& options = {},
                                        std::string* note = nullptr);

}  // namespace diffdope
