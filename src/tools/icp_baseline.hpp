#pragma once
// The classic baseline the refiner is compared with (diffdope_eval --method icp): point-to-plane ICP of the
// model's rendered surface to the observed depth near the start, with projective data association (each rendered
// pixel pairs with the observed point on the same ray, as depth-camera trackers do) and Gauss-Newton steps on the
// linearised point-to-plane distances. The observed points are the given mask's, or without one the object's
// pixels derived at the start (derive_object_pixels(): the table and neighbours removed, as a careful user crops
// the depth), bounded by the box when one is given. Depth only: colour and silhouette are not used.
#include <string>

#include "diffdope/camera.hpp"
#include "diffdope/mesh.hpp"
#include "diffdope/observation.hpp"
#include "diffdope/pose.hpp"
#include "diffdope/renderer.hpp"

namespace diffdope {

struct IcpOptions {
  int iterations = 30;        // Gauss-Newton steps at most
  double max_distance = 0.02;  // metres: pairs farther apart than this (along the normal or the ray) are dropped
  double image_scale = 0.5;    // images are compared at this scale, as the refiner's
};

struct IcpResult {
  Pose pose;             // the start where nothing could be paired
  int iterations = 0;    // steps taken
  int pairs = 0;         // pairs at the last step
  double time_ms = 0;
  std::string error;     // no depth, nothing observed near the start
};

IcpResult icp_refine(Renderer& renderer, const Camera& camera, const Observation& observed, const Mesh& mesh,
                     const Pose& start, const IcpOptions& options = IcpOptions());

}  // namespace diffdope
