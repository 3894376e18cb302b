// The Worker's visual outputs, computed only while someone subscribes: the overlay image (initial and refined
// outlines over the RGB image) and the meshes as rviz markers.
#include <cv_bridge/cv_bridge.h>
#include <opencv2/imgproc.hpp>
#include <sensor_msgs/image_encodings.h>
#include <visualization_msgs/MarkerArray.h>

#include "diffdope_ros/conversions.hpp"
#include "ros/refiner/worker.hpp"

namespace diffdope_ros {

void Worker::publishOverlay(const Frame& frame, const TargetList& targets,
                                    const std::vector<diffdope::RefineResult>& results) {
  cv::Mat canvas;
  frame.observation.rgb.convertTo(canvas, CV_8UC3, 255.0);
  cv::cvtColor(canvas, canvas, cv::COLOR_RGB2BGR);
  if (!overlay_renderer_) overlay_renderer_ = diffdope::make_cpu_renderer(options_.refiner.render);
  diffdope::Renderer* renderer = overlay_renderer_.get();
  for (size_t k = 0; k < results.size(); ++k) {
    const Slot& s = *slots_[targets[k].first];
    const std::string& name = s.instances[size_t(targets[k].second)].name;
    const diffdope::RefineResult& r = results[k];
    if (!r.error.empty()) continue;
    auto outline = [&](const diffdope::Pose& pose, const cv::Scalar& colour, int thickness) {
      const auto img = renderer->render(frame.camera, *s.mesh, {pose}).front();
      if (img.coverage.empty()) return;
      cv::Mat full = img.coverage >= 0.5;  // full-frame coverage
      std::vector<std::vector<cv::Point>> contours;
      cv::findContours(full, contours, cv::RETR_EXTERNAL, cv::CHAIN_APPROX_SIMPLE);
      cv::drawContours(canvas, contours, -1, colour, thickness, cv::LINE_AA);
      return;
    };
    outline(r.initial_pose, cv::Scalar(0, 200, 255), 1);                                   // initial: amber
    outline(r.pose, r.plausible ? cv::Scalar(60, 220, 60) : cv::Scalar(40, 40, 230), 2);  // refined: green / red
    if (!(r.pose.t.z() > options_.refiner.render.near_plane)) continue;
    const Eigen::Vector2d c = frame.camera.project(r.pose.t);
    if (!c.allFinite() || std::abs(c.x()) > 1e5 || std::abs(c.y()) > 1e5) continue;
    cv::putText(canvas, name + (r.plausible ? "" : " (implausible)"), cv::Point(int(c.x()), int(c.y())),
                cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(255, 255, 255), 1, cv::LINE_AA);
  }
  publishers_.overlay.publish(cv_bridge::CvImage(frame.header, sensor_msgs::image_encodings::BGR8, canvas).toImageMsg());
}

void Worker::publishMarkers(const Frame& frame, const TargetList& targets,
                                    const std::vector<diffdope::RefineResult>& results) {
  visualization_msgs::MarkerArray markers;
  for (size_t k = 0; k < results.size(); ++k) {
    const Slot& s = *slots_[targets[k].first];
    visualization_msgs::Marker m;
    m.header = frame.header;
    m.ns = "diffdope";
    m.id = int(targets[k].first) * diffdope::ObjectConfig::kMaxInstances + targets[k].second;  // one per instance
    m.type = visualization_msgs::Marker::MESH_RESOURCE;
    m.mesh_resource = s.config.mesh.rfind("package://", 0) == 0 ? s.config.mesh : "file://" + s.config.mesh_path;
    m.mesh_use_embedded_materials = true;
    m.action = results[k].error.empty() ? int(visualization_msgs::Marker::ADD) : int(visualization_msgs::Marker::DELETE);
    m.pose = pose_to_msg(results[k].pose);  // the mesh's own frame
    m.scale.x = m.scale.y = m.scale.z = s.config.mesh_scale;
    m.lifetime = ros::Duration(options_.track.track_timeout);  // a lost object does not stay drawn
    m.color.r = results[k].plausible ? 0.2f : 0.9f;
    m.color.g = results[k].plausible ? 0.9f : 0.2f;
    m.color.b = 0.2f;
    m.color.a = 0.8f;
    markers.markers.push_back(m);
  }
  publishers_.markers.publish(markers);
}

}  // namespace diffdope_ros
