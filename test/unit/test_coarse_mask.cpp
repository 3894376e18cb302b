// The segmenter-like degradation of a visible mask (diffdope_eval --masks coarse): deterministic for a seed, its
// IoU with the exact mask spread like a segmenter's, and an empty mask stays empty.
#include <gtest/gtest.h>

#include <algorithm>
#include <opencv2/imgproc.hpp>
#include <vector>

#include "diffdope/coarse_mask.hpp"

using namespace diffdope;

namespace {
double iou(const cv::Mat& a, const cv::Mat& b) {
  const cv::Mat A = a > 0.5, B = b > 0.5;
  return double(cv::countNonZero(A & B)) / cv::countNonZero(A | B);
}
}  // namespace

TEST(CoarseMask, IsDeterministicAndSpreadsLikeASegmentersMask) {
  cv::Mat exact = cv::Mat::zeros(240, 320, CV_8U);
  cv::ellipse(exact, cv::Point(160, 120), cv::Size(50, 35), 20, 0, 360, cv::Scalar(255), cv::FILLED);
  cv::rectangle(exact, cv::Rect(150, 60, 20, 30), cv::Scalar(255), cv::FILLED);  // a neck
  EXPECT_EQ(cv::countNonZero(coarse_mask(exact, 7) != coarse_mask(exact, 7)), 0);
  EXPECT_GT(cv::countNonZero(coarse_mask(exact, 7) != coarse_mask(exact, 8)), 0);
  std::vector<double> ious;
  int grown = 0, shrunk = 0;
  for (uint64_t seed = 0; seed < 40; ++seed) {
    const cv::Mat m = coarse_mask(exact, seed);
    ASSERT_EQ(m.type(), CV_32F);
    ASSERT_EQ(m.size(), exact.size());
    ious.push_back(iou(m, exact));
    const int n = cv::countNonZero(m > 0.5), e = cv::countNonZero(exact);
    grown += n > e, shrunk += n < e;
  }
  std::sort(ious.begin(), ious.end());
  // An object of ~5500 pixels: a few pixels of outline cost it 5-25 % of its IoU.
  EXPECT_GT(ious.front(), 0.6);
  EXPECT_LT(ious.back(), 0.99);
  EXPECT_GT(ious[ious.size() / 2], 0.75);
  EXPECT_LT(ious[ious.size() / 2], 0.95);
  EXPECT_GE(grown, 5);
  EXPECT_GE(shrunk, 5);
}

TEST(CoarseMask, AnEmptyMaskStaysEmptyAndBadInputThrows) {
  EXPECT_EQ(cv::countNonZero(coarse_mask(cv::Mat::zeros(20, 30, CV_8U), 1)), 0);
  EXPECT_THROW(coarse_mask(cv::Mat(), 1), std::invalid_argument);
  EXPECT_THROW(coarse_mask(cv::Mat::zeros(20, 30, CV_8UC3), 1), std::invalid_argument);
}
