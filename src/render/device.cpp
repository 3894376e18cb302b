// Backend selection (include/diffdope/device.hpp). The CUDA half lives in cuda/cuda_renderer.cu and is linked
// only when the package is built with CUDA (DIFFDOPE_WITH_CUDA).
#include "diffdope/device.hpp"

#include <mutex>
#include <stdexcept>

namespace diffdope {

#ifdef DIFFDOPE_WITH_CUDA
// Defined in cuda/cuda_renderer.cu.
CudaDeviceInfo cuda_probe_device();
std::unique_ptr<Renderer> cuda_make_renderer(const RenderOptions& options);
#endif

CudaDeviceInfo cuda_device_info() {
  static std::once_flag once;
  static CudaDeviceInfo info;
  std::call_once(once, [] {
#ifdef DIFFDOPE_WITH_CUDA
    info = cuda_probe_device();
#else
    info.built = false;
    info.reason = "this build has no CUDA backend (configure with diffdope_ros_WITH_CUDA=ON and nvcc)";
#endif
  });
  return info;
}

std::unique_ptr<Renderer> make_cuda_renderer(const RenderOptions& options) {
  const CudaDeviceInfo info = cuda_device_info();
  if (!info.available) throw std::runtime_error("device 'cuda' requested but unavailable: " + info.reason);
#ifdef DIFFDOPE_WITH_CUDA
  return cuda_make_renderer(options);
#else
  (void)options;
  throw std::runtime_error("device 'cuda' requested but unavailable: " + info.reason);
#endif
}

std::unique_ptr<Renderer> make_renderer(const std::string& device, const RenderOptions& options, std::string* note) {
  if (note) note->clear();
  if (device == "cpu") return make_cpu_renderer(options);
  if (device == "cuda") return make_cuda_renderer(options);
  if (device == "auto") {
    const CudaDeviceInfo info = cuda_device_info();
    std::string why = info.reason;
    if (info.available) {
      try {
        auto r = make_cuda_renderer(options);
        if (note) *note = "device auto: using CUDA on " + info.name;
        return r;
      } catch (const std::exception& e) {  // e.g. the device is out of memory or exclusively in use
        why = e.what();
      }
    }
    if (note) *note = "device auto: no usable CUDA device (" + why + "), using the CPU backend";
    return make_cpu_renderer(options);
  }
  throw std::invalid_argument("device must be auto, cpu or cuda, got '" + device + "'");
}

}  // namespace diffdope
