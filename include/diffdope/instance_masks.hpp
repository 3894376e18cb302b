#pragma once
// One observed mask for several instances of an object (a segmentation that labels both boxes "box"): each
// instance refines against its own part, so that its mask term does not pull it towards the other instance.
#include <opencv2/core.hpp>
#include <vector>

#include "diffdope/camera.hpp"
#include "diffdope/mesh.hpp"
#include "diffdope/pose.hpp"

namespace diffdope {

/// Splits `mask` (any type; nonzero = the object) among instances starting at `starts`. Each instance has a
/// projected box: the mesh's bounds at its start, grown by `grow` times its size on each side (as
/// RefinerOptions::no_mask_window). An 8-connected component inside one instance's box is that instance's; one
/// that reaches into several (instances whose images touch) is shared pixel by pixel, each pixel to the nearest
/// box centre among the boxes holding it (else among the boxes the component reaches into); one in no box is
/// nobody's (an instance not refined on this frame). Returns one CV_32F 0/1 mask per start, the size of `mask`.
std::vector<cv::Mat> split_mask_among_instances(const cv::Mat& mask, const Camera& camera, const Mesh& mesh,
                                                const std::vector<Pose>& starts, double grow);

}  // namespace diffdope
