#pragma once
// How well a given object mask (a segmenter's) agrees with the object's pixels that depth and colour show
// (derive_object_pixels()): what the refiner measures to decide whether a mask's outline can be taken as given.
#include "diffdope/refine_tuning.hpp"
#include <limits>
#include <opencv2/core.hpp>

namespace diffdope {


/// The mean distance (pixels, each capped at kOutlineOffsetCap) from the outline of `mask` to the outline of
/// `reference`, over the outline pixels within twice the cap of it: farther, the reference ran on into a
/// neighbour at the object's depth, and says nothing about the outline there. Both are single-channel images of
/// one size, inside at >= 0.5 (CV_8U: >= 128). The mask's outline is its pixels with a 4-neighbour outside. The reference's outline is both pixels of the pair that
/// straddles its edge: the last inside and the first outside. Depth's own edge is only known to that pair, since
/// readings there mix the object and what lies behind it. Where the image's border cuts a set there is no
/// outline. An exact mask gives about 0; a segmenter's outline grown or shrunk by k pixels about k, give or take
/// the straddling pixel, or the cap. With `depth` (CV_32FC1 metres, 0 = no reading) only the mask's outline
/// pixels with a reading at and around them count: in a hole (dark or shiny edges, a sensor's dropout at
/// silhouettes) the reference's edge is a guess. Returns NaN when no outline pixel counts, infinity when the
/// reference has no outline. Throws std::invalid_argument when the images differ in size or type.
double outline_offset(const cv::Mat& mask, const cv::Mat& reference, const cv::Mat& depth = cv::Mat());

/// A translation of a mask (pixels; +x right, +y down) and the outline_offset() left after it.
struct OutlineShift {
  double dx = 0, dy = 0;
  double offset = std::numeric_limits<double>::quiet_NaN();  // NaN: no outline pixel counted at any shift
};

/// The whole-pixel translation of `mask`, at most `max_shift` pixels long, that lays its outline nearest to the
/// outline of `reference` (outline_offset() without depth of the moved mask), and the offset left; of equal
/// offsets the shortest shift. A mask off the image as a whole shows as a shift with little offset left: a
/// segmenter run on a colour image that is not registered to depth, or a label drawn from a pose that is off the
/// image. A mask grown, shrunk or wandering keeps its offset at every shift. Throws std::invalid_argument when the
/// images differ in size or channels, or max_shift < 0.
OutlineShift best_outline_shift(const cv::Mat& mask, const cv::Mat& reference, int max_shift);

}  // namespace diffdope
