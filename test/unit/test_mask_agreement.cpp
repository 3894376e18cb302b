// outline_offset(): how far a given mask's outline lies from a reference's (the pixels depth shows), the measure
// by which the refiner takes a segmenter's mask as given or replaces it; best_outline_shift(): a mask off as a whole.
#include <gtest/gtest.h>

#include <cmath>
#include <opencv2/imgproc.hpp>

#include "diffdope/mask_agreement.hpp"

using namespace diffdope;

namespace {
cv::Mat ellipse_mask() {
  cv::Mat m = cv::Mat::zeros(120, 160, CV_32F);
  cv::ellipse(m, cv::Point(80, 60), cv::Size(40, 25), 15, 0, 360, cv::Scalar(1), cv::FILLED);
  return m;
}
cv::Mat moved(const cv::Mat& m, int pixels) {  // grown (> 0) or shrunk (< 0) by |pixels|
  cv::Mat out;
  const cv::Mat disc = cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * std::abs(pixels) + 1, 2 * std::abs(pixels) + 1));
  if (pixels > 0) cv::dilate(m, out, disc);
  else cv::erode(m, out, disc);
  return out;
}
}  // namespace

TEST(MaskAgreement, AnExactOutlineScoresZeroAgainstTheStraddlingPixels) {
  const cv::Mat exact = ellipse_mask();
  EXPECT_DOUBLE_EQ(outline_offset(exact, exact), 0.0);
  // Depth's pixels a pixel short of the object (mixed readings at the edge) straddle the same edge; a pixel
  // beyond it is a pixel off.
  EXPECT_LT(outline_offset(exact, moved(exact, -1)), 0.1);
  EXPECT_NEAR(outline_offset(exact, moved(exact, 1)), 1.0, 0.1);
  // An 8-bit mask reads the same as a float one.
  cv::Mat exact8;
  exact.convertTo(exact8, CV_8U, 255);
  EXPECT_DOUBLE_EQ(outline_offset(exact8, exact), 0.0);
}

TEST(MaskAgreement, AGrownOrShrunkOutlineScoresItsShiftUpToTheCap) {
  const cv::Mat exact = ellipse_mask();
  for (int k : {2, 3}) {
    EXPECT_NEAR(outline_offset(moved(exact, k), exact), k - 0.5, 0.6) << "grown by " << k;
    EXPECT_NEAR(outline_offset(moved(exact, -k), exact), k - 0.5, 0.6) << "shrunk by " << k;
  }
  EXPECT_NEAR(outline_offset(moved(exact, 5), exact), kOutlineOffsetCap, 0.15);
  // Twice the cap or more from any edge of the reference is no outline error: the reference ran on into a
  // neighbour there, and only the rest of the outline counts.
  EXPECT_TRUE(std::isnan(outline_offset(moved(exact, 10), exact)));
  cv::Mat merged = exact.clone();
  cv::rectangle(merged, cv::Rect(110, 40, 30, 40), cv::Scalar(1), cv::FILLED);  // a neighbour at the same depth
  EXPECT_LT(outline_offset(exact, merged), 0.3);  // only where the two meet
  // A blob taken in raises the mean only by its share of the outline.
  cv::Mat blob = exact.clone();
  cv::circle(blob, cv::Point(120, 60), 6, cv::Scalar(1), cv::FILLED);
  EXPECT_GT(outline_offset(blob, exact), 0.05);
  EXPECT_LT(outline_offset(blob, exact), 0.5);
}

TEST(MaskAgreement, TheImagesBorderIsNoOutline) {
  cv::Mat m = cv::Mat::zeros(60, 80, CV_32F), r;
  m(cv::Rect(0, 0, 40, 60)).setTo(1);  // the left half, cut by the frame on three sides
  r = m.clone();
  EXPECT_DOUBLE_EQ(outline_offset(m, r), 0.0);
  r(cv::Rect(0, 0, 40, 60)).setTo(0);
  r(cv::Rect(0, 0, 39, 60)).setTo(1);
  EXPECT_DOUBLE_EQ(outline_offset(m, r), 0.0);  // within the straddling pixel
}

TEST(MaskAgreement, NoOutlineOrMismatchedImages) {
  const cv::Mat exact = ellipse_mask();
  EXPECT_TRUE(std::isnan(outline_offset(cv::Mat::zeros(120, 160, CV_32F), exact)));
  EXPECT_TRUE(std::isinf(outline_offset(exact, cv::Mat::zeros(120, 160, CV_32F))));
  EXPECT_THROW(outline_offset(exact, cv::Mat::zeros(60, 80, CV_32F)), std::invalid_argument);
  EXPECT_THROW(outline_offset(cv::Mat::zeros(120, 160, CV_32FC3), exact), std::invalid_argument);
  EXPECT_THROW(outline_offset(exact, exact, cv::Mat::ones(120, 160, CV_16U)), std::invalid_argument);
  EXPECT_THROW(outline_offset(exact, exact, cv::Mat::ones(60, 80, CV_32F)), std::invalid_argument);
  EXPECT_TRUE(std::isnan(outline_offset(exact, exact, cv::Mat::zeros(120, 160, CV_32F))));  // nothing read
}

TEST(MaskAgreement, OnlyWhereDepthReadsAroundTheOutline) {
  const cv::Mat exact = ellipse_mask();
  // The mask grown by 3 pixels on its right half; there the depth has a hole along the edge.
  cv::Mat given = exact.clone(), depth(120, 160, CV_32F, cv::Scalar(1.0f));
  moved(exact, 3)(cv::Rect(80, 0, 80, 120)).copyTo(given(cv::Rect(80, 0, 80, 120)));
  EXPECT_GT(outline_offset(given, exact), 0.8);
  depth(cv::Rect(82, 0, 78, 120)).setTo(0);
  EXPECT_LT(outline_offset(given, exact, depth), 0.1);
}

// best_outline_shift(): a mask off the image as a whole is found as a shift; a grown one is not.
TEST(MaskAgreement, AMaskOffAsAWholeIsFoundAsAShift) {
  const cv::Mat exact = ellipse_mask();
  cv::Mat off;
  cv::warpAffine(exact, off, cv::Matx23d(1, 0, 3, 0, 1, -2), exact.size(), cv::INTER_NEAREST);  // 3 right, 2 up
  EXPECT_GT(outline_offset(off, exact), 1.0);
  const OutlineShift s = best_outline_shift(off, exact, 4);
  EXPECT_DOUBLE_EQ(s.dx, -3.0);  // the shift that lays it back
  EXPECT_DOUBLE_EQ(s.dy, 2.0);
  EXPECT_DOUBLE_EQ(s.offset, 0.0);
  // Beyond max_shift it is not found, and the offset left says so.
  EXPECT_GT(best_outline_shift(off, exact, 2).offset, 0.5);
  // An exact mask needs no shift: of equal offsets the shortest wins.
  const OutlineShift none = best_outline_shift(exact, exact, 4);
  EXPECT_DOUBLE_EQ(none.dx, 0.0);
  EXPECT_DOUBLE_EQ(none.dy, 0.0);
  EXPECT_DOUBLE_EQ(none.offset, 0.0);
}

TEST(MaskAgreement, AGrownMaskKeepsMostOfItsOffsetAtEveryShift) {
  // A shift lays one side of a grown outline on the edge only by moving the other side away (to the cap).
  const cv::Mat exact = ellipse_mask();
  for (int k : {2, 3}) {  // (grown by one, its outline is depth's straddling pixel: 0)
    const cv::Mat grown = moved(exact, k);
    const OutlineShift s = best_outline_shift(grown, exact, 4);
    EXPECT_GT(s.offset, 0.6 * outline_offset(grown, exact)) << "grown by " << k;
    EXPECT_GT(s.offset, 0.4 * k) << "grown by " << k;
  }
}

TEST(MaskAgreement, AShiftOfNothingOrMismatchedImages) {
  const cv::Mat exact = ellipse_mask();
  EXPECT_TRUE(std::isnan(best_outline_shift(cv::Mat::zeros(120, 160, CV_32F), exact, 3).offset));
  EXPECT_TRUE(std::isnan(best_outline_shift(exact, cv::Mat::zeros(120, 160, CV_32F), 3).offset));
  EXPECT_THROW(best_outline_shift(exact, cv::Mat::zeros(60, 80, CV_32F), 3), std::invalid_argument);
  EXPECT_THROW(best_outline_shift(exact, exact, -1), std::invalid_argument);
}
