// ~refine: the nodelet's callback queues a call for the worker and waits; Worker::processRequest answers it
// (refine_targets.hpp checks the call and picks its targets; this file adds the frame, TF and the time budget).
#include "diffdope_ros/conversions.hpp"
#include "ros/refiner/refiner_nodelet.hpp"

namespace diffdope_ros {

bool RefinerNodelet::onRefineService(diffdope_ros::Refine::Request& req, diffdope_ros::Refine::Response& res) {
  auto job = std::make_shared<Request>();
  job->request = req;
  std::future<diffdope_ros::Refine::Response> done = job->response.get_future();
  {
    std::lock_guard<std::mutex> lock(handover_.mutex);
    if (handover_.stop) {
      res.success = false;
      res.message = "the refiner is shutting down";
      return true;
    }
    handover_.requests.push_back(job);
  }
  handover_.cv.notify_one();
  res = done.get();
  return true;  // failures are reported in res.success / res.message, not as a failed call
}

diffdope_ros::Refine::Response Worker::processRequest(const diffdope_ros::Refine::Request& req,
                                                              const std::shared_ptr<const Frame>& frame) {
  diffdope_ros::Refine::Response res;
  auto fail = [&](const std::string& why) {
    res.success = false;
    res.message = why;
    errors_.warn("service", "~refine: " + why);
    return res;
  };
  const std::vector<TargetObject> objects = targetObjects();
  RefineRequestNames names;
  names.object_names = req.object_names;
  for (const auto& p : req.initial_poses) names.pose_names.push_back(p.name);
  names.iterations = req.iterations;
  names.batch_size = req.batch_size;
  const CheckedRequest checked = check_refine_request(objects, names, options_.refiner);
  if (!checked.error.empty()) return fail(checked.error);
  if (!frame) return fail("no synchronized frame received yet (check the input topics)");

  resetOnTimeJump(*frame);
  absorbDetections(*frame);
  const double stamp = frame->header.stamp.toSec();
  std::map<size_t, std::vector<diffdope::Pose>> requested;  // the call's own poses in the camera frame
  for (size_t j = 0; j < req.initial_poses.size(); ++j) {
    const size_t i = checked.pose_object[j];
    try {
      requested[i].push_back(meshPoseInCamera(req.initial_poses[j].pose, *slots_[i], *frame));
    } catch (const std::exception& e) {
      return fail(e.what());
    }
  }
  RequestTargets targets = plan_request_targets(objects, checked, requested, stamp);
  if (!targets.error.empty()) return fail(targets.error);
  // The time budget, before any detection is used up.
  const int count = int(targets.seeds.size() + targets.known.size());
  if (const std::string why =
          diffdope::check_request_time(checked.options, count, refine_time_, settings_.max_request_time);
      !why.empty())
    return fail(why);
  take_known_starts(objects, targets.known, stamp, targets.seeds);
  if (targets.seeds.empty())
    return fail("no object has a known pose (no recent detection or track); pass initial_poses");
  std::vector<std::string> skipped;
  res.results = refineAndPublish(*frame, targets.seeds, checked.options, &skipped);
  updateTrackingFlags(stamp);
  int ok = 0;
  for (const auto& r : res.results) ok += r.plausible;
  res.success = skipped.empty();  // every requested object has a result (plausible or not)
  res.message = "refined " + std::to_string(res.results.size()) + " object(s) on the frame at t=" + format_fixed(stamp) +
                ", " + std::to_string(ok) + " plausible";
  if (!skipped.empty()) res.message += "; not refined: " + join_names(skipped);
  return res;
}

}  // namespace diffdope_ros
