// loss_row() for every instruction set Highway targets, one chosen at run time (foreach_target.h compiles this
// file once per target). Built without FMA contraction (CMakeLists.txt), so each lane computes what the scalar
// pixel_loss() computes, bit for bit.
#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "simd_loss.cpp"
#include <hwy/foreach_target.h>  // IWYU pragma: keep
#include <hwy/highway.h>

#include "simd_loss.hpp"

HWY_BEFORE_NAMESPACE();
namespace diffdope {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

using DF = hn::ScalableTag<float>;
using DI = hn::RebindToSigned<DF>;

/// The lane type of lanes.hpp on this target's float vectors.
struct HwyLanes {
  using V = hn::Vec<DF>;
  using M = hn::Mask<DF>;
  static V set(float x) { return hn::Set(DF(), x); }
  static V zero() { return hn::Zero(DF()); }
  static V abs(V a) { return hn::Abs(a); }
  static M lt(V a, V b) { return hn::Lt(a, b); }
  static M gt(V a, V b) { return hn::Gt(a, b); }
  static M both(M a, M b) { return hn::And(a, b); }
  static M negate(M a) { return hn::Not(a); }
  static V select(M m, V a, V b) { return hn::IfThenElse(m, a, b); }
  static V sign(V a) {
    return hn::IfThenElse(hn::Gt(a, zero()), set(1.f), hn::IfThenElse(hn::Lt(a, zero()), set(-1.f), zero()));
  }
};

// The loss kernel built for this target (the definition must lie inside the target's region).
#include "diffdope/kernels/pixel_loss_lanes.inc"

int LossRowImpl(const LossRow& r, double* sum) {
  const DF d;
  const DI di;
  constexpr int kFields = sizeof(PixelAttr) / sizeof(float);
  static_assert(sizeof(PixelAttr) == kFields * sizeof(float), "PixelAttr is floats only");
  const size_t N = hn::Lanes(d);
  const auto field_index = hn::Mul(hn::Iota(di, 0), hn::Set(di, kFields));  // lane j: float j * kFields
  HWY_ALIGN float rgb[hn::MaxLanes(d)], depth[hn::MaxLanes(d)], mask[hn::MaxLanes(d)];
  using V = HwyLanes::V;
  int x = 0;
  for (; x + int(N) <= r.n; x += int(N)) {
    const float* post = &r.post[x].cov;
    const V cov = hn::GatherIndex(d, post, field_index);
    const V C[3] = {hn::GatherIndex(d, post + 1, field_index), hn::GatherIndex(d, post + 2, field_index),
                    hn::GatherIndex(d, post + 3, field_index)};
    const V D = hn::GatherIndex(d, post + 4, field_index);
    const V S = r.S ? hn::LoadU(d, r.S + x) : hn::Set(d, 1.f);
    V I[3] = {hn::Zero(d), hn::Zero(d), hn::Zero(d)};
    if (r.I) hn::LoadInterleaved3(d, r.I + 3 * x, I[0], I[1], I[2]);
    const V Id = r.D ? hn::LoadU(d, r.D + x) : hn::Zero(d);
    const PixelLossLanes<HwyLanes> v = HWY_NAMESPACE::pixel_loss_lanes<HwyLanes>(r.P, S, I, Id, hn::Gt(Id, hn::Zero(d)), cov, C, D);
    if (r.g_post) {
      float* g = &r.g_post[x].cov;
      hn::ScatterIndex(v.g_cov, d, g, field_index);
      for (int ch = 0; ch < 3; ++ch) hn::ScatterIndex(v.g_c[ch], d, g + 1 + ch, field_index);
      hn::ScatterIndex(v.g_d, d, g + 4, field_index);
    }
    hn::Store(v.rgb, d, rgb);
    hn::Store(v.depth, d, depth);
    hn::Store(v.mask, d, mask);
    for (size_t j = 0; j < N; ++j) {
      sum[0] += double(rgb[j]);
      sum[1] += double(depth[j]);
      sum[2] += double(mask[j]);
    }
  }
  return x;
}

const char* TargetName() { return hwy::TargetName(HWY_TARGET); }

}  // namespace HWY_NAMESPACE
}  // namespace diffdope
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace diffdope {
HWY_EXPORT(LossRowImpl);
HWY_EXPORT(TargetName);

int loss_row(const LossRow& row, double sum[3]) { return HWY_DYNAMIC_DISPATCH(LossRowImpl)(row, sum); }
const char* loss_row_target() { return HWY_DYNAMIC_DISPATCH(TargetName)(); }
}  // namespace diffdope
#endif
