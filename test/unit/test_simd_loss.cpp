// loss_row() (the CPU's loss pass, SIMD over the whole vectors of a row) against pixel_loss_step() pixel by pixel:
// the same bits for every value, gradient and sum, over the cases the formula distinguishes and rows of every
// length around the vector width.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <vector>

#include "simd_loss.hpp"

namespace {
using namespace diffdope;

template <class T>
bool same_bits(T a, T b) {
  return std::memcmp(&a, &b, sizeof a) == 0;
}

struct RowData {
  std::vector<PixelAttr> post;
  std::vector<float> S, I, D;
};

/// Pixels drawn from the cases pixel_loss() tells apart: uncovered, covered and blended coverage; observed mask
/// 0, 1 or partial; no depth reading, a valid one, an occluder far in front, NaN; now and then a NaN colour.
RowData make_row(int n, std::mt19937& rng) {
  std::uniform_real_distribution<float> u(0.f, 1.f);
  const auto pick = [&](std::initializer_list<float> v) { return *(v.begin() + int(u(rng) * float(v.size()) * 0.999f)); };
  const float nan = std::numeric_limits<float>::quiet_NaN();
  RowData r;
  for (int i = 0; i < n; ++i) {
    const float cov = pick({0.f, 1.f, 0.3f, 0.5f, 1.f});
    const float depth = 0.4f + 0.2f * u(rng);
    r.post.push_back(PixelAttr{cov, {cov * u(rng), cov * u(rng), cov * u(rng)}, cov * depth});
    r.S.push_back(pick({0.f, 1.f, 1.f, 0.5f, 0.2f}));
    for (int c = 0; c < 3; ++c) r.I.push_back(u(rng) < 0.03f ? nan : u(rng));
    r.D.push_back(pick({0.f, -1.f, depth + 0.01f, depth - 0.3f, depth + 0.2f, nan}));
  }
  return r;
}

TEST(SimdLoss, ARowGivesThePixelKernelsBitsForEveryValueGradientAndSum) {
  std::mt19937 rng(7);
  std::vector<PixelLossParams> params = {{0.3f, 0.2f, 0.1f, 0.5f, 0.05f, 0.02f},   // every term, occlusion on
                                         {0.3f, 0.f, 0.1f, 0.5f, 0.05f, 0.f},      // no depth term, no occlusion
                                         {0.f, 0.2f, 0.f, 0.25f, 0.03f, 0.02f}};   // depth alone
  int rows = 0;
  for (const PixelLossParams& P : params)
    for (int n : {0, 1, 3, 4, 7, 8, 9, 15, 16, 17, 31, 32, 33, 64, 101})
      for (int absent = 0; absent < 8; ++absent)  // bit 0: no S, bit 1: no rgb, bit 2: no depth
        for (bool gradient : {false, true}) {
          const RowData d = make_row(n, rng);
          std::vector<PixelAttr> g(size_t(n), PixelAttr{-7.f, {-7.f, -7.f, -7.f}, -7.f});
          const LossRow row{P, d.post.data(), absent & 1 ? nullptr : d.S.data(), absent & 2 ? nullptr : d.I.data(),
                            absent & 4 ? nullptr : d.D.data(), gradient ? g.data() : nullptr, n};
          double sum[3] = {0.5, 0.25, 0.125};  // loss_row adds to what is there
          const int done = loss_row(row, sum);
          ASSERT_LE(done, n);
          if (n >= 64) ASSERT_GT(done, 0) << "a vector holds at most 64 floats (2048-bit SVE)";
          double want[3] = {0.5, 0.25, 0.125};
          const float zero3[3] = {0.f, 0.f, 0.f};
          for (int x = 0; x < done; ++x) {
            PixelLossGrad pg;
            const PixelAttr& a = d.post[size_t(x)];
            const PixelLossValue v = pixel_loss_step(P, row.S ? row.S[x] : 1.f, row.I ? row.I + 3 * x : zero3,
                                                     row.D ? row.D[x] : 0.f, a.cov, a.c, a.d, &pg);
            want[0] += double(v.rgb), want[1] += double(v.depth), want[2] += double(v.mask);
            const PixelAttr& got = g[size_t(x)];
            if (gradient) {
              ASSERT_TRUE(same_bits(got.cov, pg.cov) && same_bits(got.d, pg.d) && same_bits(got.c[0], pg.c[0]) &&
                          same_bits(got.c[1], pg.c[1]) && same_bits(got.c[2], pg.c[2]))
                  << "gradient of pixel " << x << " of " << n << ": " << got.cov << " vs " << pg.cov;
            } else {
              ASSERT_EQ(got.cov, -7.f) << "no gradient asked, none written";
            }
          }
          for (int x = done; x < n; ++x) ASSERT_EQ(g[size_t(x)].cov, -7.f) << "the rest is the caller's";
          for (int k = 0; k < 3; ++k)
            ASSERT_TRUE(same_bits(sum[k], want[k])) << "term " << k << ", n " << n << ": " << sum[k] << " vs " << want[k];
          ++rows;
        }
  EXPECT_EQ(rows, 3 * 15 * 8 * 2);
  std::printf("loss_row runs on %s\n", loss_row_target());
}

}  // namespace
