#pragma once
// DD_HOST_DEVICE marks the maths that both the CPU backend and the CUDA kernels call: one source of truth.
#if defined(__CUDACC__)
#define DD_HOST_DEVICE __host__ __device__ __forceinline__
#else
#define DD_HOST_DEVICE inline
#endif
