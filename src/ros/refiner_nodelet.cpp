// RefinerNodelet: see include/diffdope_ros/refiner_nodelet.hpp. Parameters and topics: README.md ("ROS node").
#include "diffdope_ros/refiner_nodelet.hpp"

#include <boost/bind/bind.hpp>
#include <opencv2/imgproc.hpp>
#include <pluginlib/class_list_macros.hpp>
#include <ros/package.h>
#include <sensor_msgs/image_encodings.h>
#include <tf2/exceptions.h>
#include <visualization_msgs/MarkerArray.h>

#include <sstream>

#include "diffdope_ros/conversions.hpp"

namespace diffdope_ros {
namespace {

const char* kInputNames[4] = {"rgb", "camera_info", "depth", "mask"};

std::string fmt(double v, int prec = 3) {
  std::ostringstream s;
  s.setf(std::ios::fixed);
  s.precision(prec);
  s << v;
  return s.str();
}

}  // namespace

// ---------------------------------------------------------------------------------------------- set-up ----

void RefinerNodelet::onInit() {
  loadParameters();
  ros::NodeHandle& pnh = getPrivateNodeHandle();
  tf_buffer_ = std::make_unique<tf2_ros::Buffer>(ros::Duration(30.0));
  tf_listener_ = std::make_unique<tf2_ros::TransformListener>(*tf_buffer_, getNodeHandle());
  tf_broadcaster_ = std::make_unique<tf2_ros::TransformBroadcaster>();
  refined_pub_ = pnh.advertise<diffdope_ros::RefinedPoseArray>("refined_poses", 10);
  markers_pub_ = pnh.advertise<visualization_msgs::MarkerArray>("markers", 1);
  it_ = std::make_unique<image_transport::ImageTransport>(getNodeHandle());
  image_transport::ImageTransport pit(pnh);
  overlay_pub_ = pit.advertise("overlay", 1);

  loadObjects();

  diagnostics_ = std::make_unique<diagnostic_updater::Updater>(getNodeHandle(), pnh, getName());
  diagnostics_->setHardwareID("diffdope_refiner");
  diagnostics_->add("refiner", this, &RefinerNodelet::onDiagnostics);

  worker_ = std::thread([this] { workerLoop(); });
  setupInputs();
  // The service runs on the multi-threaded queue: a call waits for the worker without holding up the inputs.
  refine_srv_ = getMTPrivateNodeHandle().advertiseService("refine", &RefinerNodelet::onRefineService, this);
  watchdog_timer_ = pnh.createWallTimer(ros::WallDuration(1.0), &RefinerNodelet::onWatchdog, this);
  NODELET_INFO_STREAM("diffdope refiner ready: mode "
                      << (mode_ == Mode::kOnRequest ? "on_request" : mode_ == Mode::kTracking ? "tracking" : "continuous")
                      << ", inputs rgb" << (use_depth_ ? "+depth" : "") << (use_mask_ ? "+mask" : "")
                      << ", " << slots_.size() << " object(s), " << refiner_options_.batch_size << " runs x "
                      << refiner_options_.iterations << " iterations, backend "
                      << (refiner_ ? refiner_->backend() : std::string("none")));
}

void RefinerNodelet::loadParameters() {
  ros::NodeHandle& pnh = getPrivateNodeHandle();
  std::string mode = pnh.param<std::string>("mode", "tracking");
  if (mode == "continuous") mode_ = Mode::kContinuous;
  else if (mode == "tracking") mode_ = Mode::kTracking;
  else if (mode == "on_request") mode_ = Mode::kOnRequest;
  else {
    NODELET_ERROR_STREAM("~mode: unknown value '" << mode << "' (continuous, tracking, on_request); using tracking");
    mode_ = Mode::kTracking;
  }
  use_depth_ = pnh.param("use_depth", true);
  use_mask_ = pnh.param("use_mask", false);
  queue_size_ = std::max(1, pnh.param("queue_size", 10));
  max_interval_ = pnh.param("max_interval", 0.1);
  sync_timeout_ = pnh.param("sync_timeout", 3.0);
  tf_timeout_ = pnh.param("tf_timeout", 0.1);
  frame_prefix_ = pnh.param<std::string>("frame_prefix", "diffdope_");
  fixed_frame_ = pnh.param<std::string>("fixed_frame", "");
  detection_prefix_ = pnh.param<std::string>("detection_topic_prefix", "/dope/pose_");
  publish_tf_ = pnh.param("publish_tf", true);
  publish_implausible_ = pnh.param("publish_implausible", false);
  // on_request also seeds from its own previous results ("refine again" on a newer frame).
  track_options_.tracking = mode_ != Mode::kContinuous;
  track_options_.max_detection_age = pnh.param("max_detection_age", 1.0);
  track_options_.track_timeout = pnh.param("track_timeout", 3.0);
  track_options_.max_failures = std::max(1, pnh.param("max_track_failures", 2));
  track_options_.predict = pnh.param("predict_motion", true);
  errors_.set_throttle_period(pnh.param("error_throttle", 5.0));
}

void RefinerNodelet::loadObjects() {
  ros::NodeHandle& pnh = getPrivateNodeHandle();
  const std::string objects_path = pnh.param<std::string>("objects_config", "");
  const std::string refiner_path = pnh.param<std::string>("refiner_config", "");
  const diffdope::PackageResolver resolver = [](const std::string& pkg) { return ros::package::getPath(pkg); };
  diffdope::ObjectsConfig cfg;
  try {
    if (objects_path.empty()) throw std::runtime_error("~objects_config is not set (path to the objects YAML)");
    cfg = diffdope::load_objects_config(objects_path, resolver);
    refiner_options_ = cfg.refiner;
    // The optional refiner file overrides the objects file's refiner section (launch-time tuning).
    if (!refiner_path.empty()) refiner_options_ = diffdope::RefinerOptions::from_yaml_file(refiner_path, cfg.refiner);
    if (pnh.hasParam("iterations")) refiner_options_.iterations = pnh.param("iterations", refiner_options_.iterations);
    if (pnh.hasParam("batch_size")) refiner_options_.batch_size = pnh.param("batch_size", refiner_options_.batch_size);
    const std::string device = pnh.param<std::string>("device", "");  // "" = the YAML's choice
    if (!device.empty()) refiner_options_.device = device;
    refiner_options_.validate();
    // One refiner (and renderer: CUDA keeps the meshes on the device) for the node's life; "cuda" without a
    // device throws here, "auto" falls back to the CPU with one line.
    refiner_ = std::make_unique<diffdope::Refiner>(refiner_options_);
  } catch (const std::exception& e) {
    errors_.error("config", std::string("configuration error, no object will be refined: ") + e.what());
    return;
  }
  for (size_t i = 0; i < cfg.objects.size(); ++i) {
    auto slot = std::make_unique<Slot>();
    slot->config = cfg.objects[i];
    try {
      slot->mesh = std::make_unique<diffdope::Mesh>(diffdope::load_object_mesh(slot->config));
      slot->track = diffdope::ObjectTrack(track_options_, slot->mesh->center().cast<double>());
      NODELET_INFO_STREAM("object '" << slot->config.name << "': " << slot->mesh->num_triangles() << " triangles, "
                                     << "diameter " << fmt(slot->mesh->diameter()) << " m");
    } catch (const std::exception& e) {
      slot->disabled_reason = e.what();
      errors_.error("mesh_" + slot->config.name,
                    "object '" + slot->config.name + "' disabled: cannot load its mesh: " + e.what());
    }
    slot->pose_pub = pnh.advertise<geometry_msgs::PoseStamped>("refined/" + slot->config.name, 10);
    slots_.push_back(std::move(slot));
  }
}

void RefinerNodelet::setupInputs() {
  ros::NodeHandle& nh = getNodeHandle();
  ros::NodeHandle& pnh = getPrivateNodeHandle();
  for (size_t i = 0; i < slots_.size(); ++i) {
    Slot& s = *slots_[i];
    const std::string topic = s.config.pose_topic.empty() ? detection_prefix_ + s.config.name : s.config.pose_topic;
    s.detection_sub = nh.subscribe<geometry_msgs::PoseStamped>(
        topic, 5, boost::bind(&RefinerNodelet::onDetection, this, boost::placeholders::_1, i));
  }
  initial_poses_sub_ = pnh.subscribe("initial_poses", 5, &RefinerNodelet::onInitialPoses, this);

  // ~image_transport selects the transport (raw, compressed, ...) for every image input.
  const image_transport::TransportHints hints("raw", ros::TransportHints(), pnh);
  rgb_sub_.subscribe(*it_, "rgb/image_rect_color", queue_size_, hints);
  info_sub_.subscribe(nh, "rgb/camera_info", queue_size_);
  if (use_depth_) depth_sub_.subscribe(*it_, "depth/image_rect", queue_size_, hints);
  if (use_mask_) mask_sub_.subscribe(*it_, "mask", queue_size_, hints);
  rgb_sub_.registerCallback(boost::function<void(const sensor_msgs::ImageConstPtr&)>(
      [this](const sensor_msgs::ImageConstPtr& m) { noteArrival(0, m->header); }));
  info_sub_.registerCallback(boost::function<void(const sensor_msgs::CameraInfoConstPtr&)>(
      [this](const sensor_msgs::CameraInfoConstPtr& m) { noteArrival(1, m->header); }));
  if (use_depth_)
    depth_sub_.registerCallback(boost::function<void(const sensor_msgs::ImageConstPtr&)>(
        [this](const sensor_msgs::ImageConstPtr& m) { noteArrival(2, m->header); }));
  if (use_mask_)
    mask_sub_.registerCallback(boost::function<void(const sensor_msgs::ImageConstPtr&)>(
        [this](const sensor_msgs::ImageConstPtr& m) { noteArrival(3, m->header); }));

  const ros::Duration max_interval(std::max(0.0, max_interval_));
  if (use_depth_ && use_mask_) {
    sync4_ = std::make_unique<message_filters::Synchronizer<Policy4>>(Policy4(queue_size_), rgb_sub_, info_sub_,
                                                                       depth_sub_, mask_sub_);
    if (max_interval_ > 0) sync4_->setMaxIntervalDuration(max_interval);
    sync4_->registerCallback(&RefinerNodelet::onSync4, this);
  } else if (use_depth_ || use_mask_) {
    sync3_ = std::make_unique<message_filters::Synchronizer<Policy3>>(Policy3(queue_size_), rgb_sub_, info_sub_,
                                                                       use_depth_ ? depth_sub_ : mask_sub_);
    if (max_interval_ > 0) sync3_->setMaxIntervalDuration(max_interval);
    sync3_->registerCallback(&RefinerNodelet::onSync3, this);
  } else {
    sync2_ = std::make_unique<message_filters::Synchronizer<Policy2>>(Policy2(queue_size_), rgb_sub_, info_sub_);
    if (max_interval_ > 0) sync2_->setMaxIntervalDuration(max_interval);
    sync2_->registerCallback(&RefinerNodelet::onSync2, this);
  }
}

RefinerNodelet::~RefinerNodelet() {
  {
    std::lock_guard<std::mutex> lock(work_mutex_);
    stop_ = true;
    for (auto& r : requests_) {
      diffdope_ros::Refine::Response res;
      res.success = false;
      res.message = "the refiner is shutting down";
      r->response.set_value(res);
    }
    requests_.clear();
  }
  work_cv_.notify_all();
  if (worker_.joinable()) worker_.join();
  watchdog_timer_.stop();
  refine_srv_.shutdown();
  rgb_sub_.unsubscribe();
  info_sub_.unsubscribe();
  depth_sub_.unsubscribe();
  mask_sub_.unsubscribe();
  initial_poses_sub_.shutdown();
  for (auto& s : slots_) s->detection_sub.shutdown();
  sync2_.reset();
  sync3_.reset();
  sync4_.reset();
  diagnostics_.reset();
}

// ------------------------------------------------------------------------------------------- callbacks ----

void RefinerNodelet::noteArrival(int index, const std_msgs::Header& header) {
  std::lock_guard<std::mutex> lock(arrival_mutex_);
  last_arrival_[index] = ros::WallTime::now();
  last_stamp_[index] = header.stamp;
}

void RefinerNodelet::onSync2(const sensor_msgs::ImageConstPtr& rgb, const sensor_msgs::CameraInfoConstPtr& info) {
  onImages(rgb, info, nullptr, nullptr);
}

void RefinerNodelet::onSync3(const sensor_msgs::ImageConstPtr& rgb, const sensor_msgs::CameraInfoConstPtr& info,
                             const sensor_msgs::ImageConstPtr& third) {
  if (use_depth_) onImages(rgb, info, third, nullptr);
  else onImages(rgb, info, nullptr, third);
}

void RefinerNodelet::onSync4(const sensor_msgs::ImageConstPtr& rgb, const sensor_msgs::CameraInfoConstPtr& info,
                             const sensor_msgs::ImageConstPtr& depth, const sensor_msgs::ImageConstPtr& mask) {
  onImages(rgb, info, depth, mask);
}

void RefinerNodelet::onImages(const sensor_msgs::ImageConstPtr& rgb, const sensor_msgs::CameraInfoConstPtr& info,
                              const sensor_msgs::ImageConstPtr& depth, const sensor_msgs::ImageConstPtr& mask) {
  {
    std::lock_guard<std::mutex> lock(arrival_mutex_);
    last_sync_ = ros::WallTime::now();
  }
  auto frame = std::make_shared<Frame>();
  frame->received = ros::WallTime::now();
  frame->header = rgb->header;
  frame->rgb_msg = rgb;
  try {
    if (rgb->header.frame_id.empty()) throw std::invalid_argument("rgb image: empty header.frame_id");
    std::string warning;
    frame->camera = camera_from_info(*info, &warning);
    if (!warning.empty()) errors_.warn("camera_info_k", warning);
    if (int(rgb->width) != frame->camera.width || int(rgb->height) != frame->camera.height)
      throw std::invalid_argument("rgb image is " + std::to_string(rgb->width) + "x" + std::to_string(rgb->height) +
                                  " but camera_info says " + std::to_string(info->width) + "x" +
                                  std::to_string(info->height));
    frame->observation.rgb = rgb_from_image(*rgb);
    auto same_size = [&](const sensor_msgs::Image& im, const char* what) {
      if (im.width != rgb->width || im.height != rgb->height)
        throw std::invalid_argument(std::string(what) + " image is " + std::to_string(im.width) + "x" +
                                    std::to_string(im.height) + " but rgb is " + std::to_string(rgb->width) + "x" +
                                    std::to_string(rgb->height) + " (register it to the rgb camera)");
    };
    if (depth) {
      same_size(*depth, "depth");
      frame->observation.depth = depth_from_image(*depth);
    }
    if (mask) {
      same_size(*mask, "mask");
      frame->labels = labels_from_image(*mask);
    }
  } catch (const std::exception& e) {
    const std::string what = e.what();  // "<input> image: problem": throttle per input, not one for all
    errors_.error("input/" + what.substr(0, what.find(':')), "input frame dropped: " + what);
    return;
  }
  {
    std::lock_guard<std::mutex> lock(work_mutex_);
    ++stats_.frames_synced;
    if (frame_pending_) ++stats_.frames_skipped;  // the worker was busy: streaming takes the newest frame
    latest_frame_ = frame;
    frame_pending_ = mode_ != Mode::kOnRequest;
  }
  work_cv_.notify_one();
}

void RefinerNodelet::onDetection(const geometry_msgs::PoseStampedConstPtr& msg, size_t slot) {
  storeDetection(*msg, slot, "detection for '" + slots_[slot]->config.name + "'");
}

void RefinerNodelet::onInitialPoses(const diffdope_ros::InitialPoseArrayConstPtr& msg) {
  for (const auto& p : msg->poses) {
    size_t i = 0;
    while (i < slots_.size() && slots_[i]->config.name != p.name) ++i;
    if (i == slots_.size()) {
      errors_.error("unknown_object", "~initial_poses: unknown object name '" + p.name + "' (not in the objects config)");
      continue;
    }
    storeDetection(p.pose, i, "~initial_poses entry for '" + p.name + "'");
  }
}

void RefinerNodelet::storeDetection(const geometry_msgs::PoseStamped& pose, size_t slot, const std::string& origin) {
  try {
    pose_from_msg(pose.pose, origin);  // reject NaN / zero quaternions at once
    if (pose.header.frame_id.empty()) throw std::invalid_argument(origin + ": empty header.frame_id");
  } catch (const std::exception& e) {
    errors_.error("pose/" + slots_[slot]->config.name, std::string("initial pose ignored: ") + e.what());
    return;
  }
  std::lock_guard<std::mutex> lock(detections_mutex_);
  slots_[slot]->pending_detection = pose;
}

bool RefinerNodelet::onRefineService(diffdope_ros::Refine::Request& req, diffdope_ros::Refine::Response& res) {
  auto job = std::make_shared<Request>();
  job->request = req;
  std::future<diffdope_ros::Refine::Response> done = job->response.get_future();
  {
    std::lock_guard<std::mutex> lock(work_mutex_);
    if (stop_) {
      res.success = false;
      res.message = "the refiner is shutting down";
      return true;
    }
    requests_.push_back(job);
  }
  work_cv_.notify_one();
  res = done.get();
  return true;  // failures are reported in res.success / res.message, not as a failed call
}

void RefinerNodelet::onWatchdog(const ros::WallTimerEvent&) {
  // Inputs that arrive but never form a synchronized set (a silent topic, stamps too far apart) are an error.
  const ros::WallTime now = ros::WallTime::now();
  std::lock_guard<std::mutex> lock(arrival_mutex_);
  const bool rgb_recent = !last_arrival_[0].isZero() && (now - last_arrival_[0]).toSec() < 1.5;
  const double since_sync = last_sync_.isZero() ? (now - last_arrival_[0]).toSec() : (now - last_sync_).toSec();
  if (rgb_recent && since_sync > sync_timeout_) {
    std::ostringstream msg;
    msg << "no synchronized input for " << fmt(since_sync, 1) << " s (~sync_timeout " << sync_timeout_
        << " s, ~max_interval " << max_interval_ << " s); last stamps:";
    const bool used[4] = {true, true, use_depth_, use_mask_};
    for (int i = 0; i < 4; ++i) {
      if (!used[i]) continue;
      msg << " " << kInputNames[i] << "=";
      if (last_arrival_[i].isZero()) msg << "never received";
      else msg << fmt(last_stamp_[i].toSec());
    }
    msg << " (topics: " << rgb_sub_.getTopic() << ", " << info_sub_.getTopic()
        << (use_depth_ ? ", " + depth_sub_.getTopic() : "") << (use_mask_ ? ", " + mask_sub_.getTopic() : "") << ")";
    errors_.error("sync", msg.str());
  }
  if (diagnostics_) diagnostics_->update();
}

void RefinerNodelet::onDiagnostics(diagnostic_updater::DiagnosticStatusWrapper& stat) {
  Stats s;
  {
    std::lock_guard<std::mutex> lock(work_mutex_);
    s = stats_;
  }
  const ErrorReporter::Summary e = errors_.summary();
  int enabled = 0;
  for (const auto& slot : slots_) enabled += slot->mesh != nullptr;
  const double span = (s.last_refined - s.first_refined).toSec();
  const double rate = s.frames_refined > 1 && span > 0 ? (s.frames_refined - 1) / span : 0.0;
  const bool recent_error = e.last_error_time > 0 && ros::WallTime::now().toSec() - e.last_error_time < 10.0;
  if (enabled == 0) stat.summary(diagnostic_msgs::DiagnosticStatus::ERROR, "no object can be refined: " + e.last_error);
  else if (recent_error) stat.summary(diagnostic_msgs::DiagnosticStatus::WARN, e.last_error);
  else stat.summary(diagnostic_msgs::DiagnosticStatus::OK, "refining");
  stat.add("objects enabled", std::to_string(enabled) + " of " + std::to_string(slots_.size()));
  stat.add("backend", refiner_ ? refiner_->backend() : std::string("none (configuration error)"));
  for (const auto& slot : slots_)
    stat.add("object " + slot->config.name,
             slot->mesh ? (slot->tracking ? "tracking" : "waiting for a pose") : "disabled: " + slot->disabled_reason);
  stat.add("frames synchronized", s.frames_synced);
  stat.add("frames refined", s.frames_refined);
  stat.add("frames skipped (worker busy)", s.frames_skipped);
  stat.add("objects refined", s.objects_refined);
  stat.add("implausible results", s.implausible);
  stat.add("refine rate (frames/s)", fmt(rate, 2));
  stat.add("last latency (s)", fmt(s.last_latency));
  stat.add("mean latency (s)", fmt(s.frames_refined ? s.latency_sum / s.frames_refined : -1.0));
  stat.add("last refine time (ms)", fmt(s.last_refine_ms, 1));
  stat.add("last error", e.last_error);
  for (const auto& kv : e.error_counts) stat.add("errors: " + kv.first, kv.second);
}

// ---------------------------------------------------------------------------------------------- worker ----

void RefinerNodelet::workerLoop() {
  while (true) {
    std::shared_ptr<Request> job;
    std::shared_ptr<const Frame> frame;
    {
      std::unique_lock<std::mutex> lock(work_mutex_);
      work_cv_.wait(lock, [this] { return stop_ || !requests_.empty() || frame_pending_; });
      if (stop_) return;
      frame = latest_frame_;
      if (!requests_.empty()) {  // service calls first: a caller is waiting
        job = requests_.front();
        requests_.pop_front();
      } else {
        frame_pending_ = false;
      }
    }
    try {
      if (job) job->response.set_value(processRequest(job->request, frame));
      else processStreaming(frame);
    } catch (const std::exception& e) {  // a bug guard: the node keeps running and says why
      errors_.error("internal", std::string("refinement failed: ") + e.what());
      if (job) {
        diffdope_ros::Refine::Response res;
        res.success = false;
        res.message = std::string("refinement failed: ") + e.what();
        try {
          job->response.set_value(res);
        } catch (const std::future_error&) {
        }
      }
    }
  }
}

diffdope::Pose RefinerNodelet::meshPoseInCamera(const geometry_msgs::PoseStamped& pose, const Slot& slot,
                                                const Frame& frame) {
  const std::string what = "initial pose of '" + slot.config.name + "'";
  diffdope::Pose in_source = pose_from_msg(pose.pose, what);
  diffdope::Pose camera_from_source;  // identity when the pose is already in the camera frame
  const std::string& camera = frame.header.frame_id;
  const std::string source = pose.header.frame_id;
  if (source != camera && source != "/" + camera) {
    geometry_msgs::TransformStamped t;
    try {
      const ros::Duration timeout(tf_timeout_);
      if (fixed_frame_.empty() || pose.header.stamp.isZero())
        t = tf_buffer_->lookupTransform(camera, source, frame.header.stamp, timeout);
      else  // the detection's frame at its own stamp, through a fixed frame to the camera at the image stamp
        t = tf_buffer_->lookupTransform(camera, frame.header.stamp, source, pose.header.stamp, fixed_frame_, timeout);
    } catch (const tf2::TransformException& e) {
      throw std::runtime_error(what + ": no transform from '" + source + "' to '" + camera + "' at t=" +
                               fmt(frame.header.stamp.toSec()) + ": " + e.what());
    }
    camera_from_source = pose_from_transform(t.transform, what + " (TF)");
  }
  const diffdope::Pose mesh_pose = camera_from_source * in_source * slot.config.model_transform;
  if (!(mesh_pose.t.z() > refiner_options_.render.near_plane))
    throw std::runtime_error(what + ": the object is behind the camera (z = " + fmt(mesh_pose.t.z()) +
                             " m in '" + camera + "')");
  return mesh_pose;
}

void RefinerNodelet::absorbDetections(const Frame& frame) {
  std::vector<std::pair<size_t, geometry_msgs::PoseStamped>> pending;
  {
    std::lock_guard<std::mutex> lock(detections_mutex_);
    for (size_t i = 0; i < slots_.size(); ++i)
      if (slots_[i]->pending_detection) {
        pending.emplace_back(i, *slots_[i]->pending_detection);
        slots_[i]->pending_detection.reset();
      }
  }
  for (auto& [i, msg] : pending) {
    Slot& s = *slots_[i];
    if (!s.mesh) continue;
    try {
      const double stamp = msg.header.stamp.isZero() ? frame.header.stamp.toSec() : msg.header.stamp.toSec();
      s.track.add_detection(meshPoseInCamera(msg, s, frame), stamp);
    } catch (const std::exception& e) {
      errors_.error("pose/" + s.config.name, std::string("initial pose ignored: ") + e.what());
    }
  }
}

void RefinerNodelet::processStreaming(const std::shared_ptr<const Frame>& frame) {
  if (!frame) return;
  absorbDetections(*frame);
  SeedList seeds;
  const double stamp = frame->header.stamp.toSec();
  for (size_t i = 0; i < slots_.size(); ++i) {
    if (!slots_[i]->mesh) continue;
    auto starts = slots_[i]->track.seeds_for(stamp);
    if (!starts.empty()) seeds.emplace_back(i, std::move(starts));
  }
  if (!seeds.empty()) refineAndPublish(*frame, seeds, refiner_options_);
}

diffdope_ros::Refine::Response RefinerNodelet::processRequest(const diffdope_ros::Refine::Request& req,
                                                              const std::shared_ptr<const Frame>& frame) {
  diffdope_ros::Refine::Response res;
  auto fail = [&](const std::string& why) {
    res.success = false;
    res.message = why;
    errors_.warn("service", "~refine: " + why);
    return res;
  };
  auto find = [&](const std::string& name) -> long {
    for (size_t i = 0; i < slots_.size(); ++i)
      if (slots_[i]->config.name == name) return long(i);
    return -1;
  };
  // Check every name first: a request with a typo refines nothing.
  std::vector<std::string> unknown, disabled;
  for (const auto& n : req.object_names) {
    const long i = find(n);
    if (i < 0) unknown.push_back(n);
    else if (!slots_[i]->mesh) disabled.push_back(n + " (" + slots_[i]->disabled_reason + ")");
  }
  for (const auto& p : req.initial_poses) {
    const long i = find(p.name);
    if (i < 0) unknown.push_back(p.name);
    else if (!slots_[i]->mesh) disabled.push_back(p.name + " (" + slots_[i]->disabled_reason + ")");
  }
  auto join = [](const std::vector<std::string>& v) {
    std::string s;
    for (const auto& x : v) s += (s.empty() ? "" : ", ") + x;
    return s;
  };
  if (!unknown.empty()) return fail("unknown object name(s): " + join(unknown) + " (not in the objects config)");
  if (!disabled.empty()) return fail("object(s) disabled: " + join(disabled));
  if (req.iterations < 0 || req.batch_size < 0) return fail("iterations and batch_size must be >= 0 (0 = configured)");
  if (!frame) return fail("no synchronized frame received yet (check the input topics)");

  absorbDetections(*frame);
  const double stamp = frame->header.stamp.toSec();
  SeedList seeds;
  std::vector<bool> chosen(slots_.size(), false);
  for (const auto& p : req.initial_poses) {
    const size_t i = size_t(find(p.name));
    if (chosen[i]) return fail("object '" + p.name + "' has two initial poses in the request");
    try {
      seeds.emplace_back(i, std::vector<diffdope::Seed>{diffdope::Seed{
                                meshPoseInCamera(p.pose, *slots_[i], *frame), diffdope::SeedSource::kRequest, stamp}});
    } catch (const std::exception& e) {
      return fail(e.what());
    }
    chosen[i] = true;
  }
  std::vector<std::string> missing;
  if (req.object_names.empty() && req.initial_poses.empty()) {
    for (size_t i = 0; i < slots_.size(); ++i)
      if (slots_[i]->mesh)
        if (auto starts = slots_[i]->track.seeds_for(stamp); !starts.empty()) {
          seeds.emplace_back(i, std::move(starts));
          chosen[i] = true;
        }
    if (seeds.empty()) return fail("no object has a known pose (no recent detection or track); pass initial_poses");
  } else {
    for (const auto& n : req.object_names) {
      const size_t i = size_t(find(n));
      if (chosen[i]) continue;
      if (auto starts = slots_[i]->track.seeds_for(stamp); !starts.empty()) {
        seeds.emplace_back(i, std::move(starts));
        chosen[i] = true;
      } else {
        missing.push_back(n);
      }
    }
    if (!missing.empty())
      return fail("no initial pose for " + join(missing) + " (no recent detection or track); pass initial_poses");
  }
  diffdope::RefinerOptions options = refiner_options_;
  if (req.iterations > 0) options.iterations = req.iterations;
  if (req.batch_size > 0) options.batch_size = req.batch_size;
  res.results = refineAndPublish(*frame, seeds, options);
  int ok = 0;
  for (const auto& r : res.results) ok += r.plausible;
  res.success = true;
  res.message = "refined " + std::to_string(res.results.size()) + " object(s) on the frame at t=" + fmt(stamp) +
                ", " + std::to_string(ok) + " plausible";
  return res;
}

std::vector<diffdope_ros::RefinedPose> RefinerNodelet::refineAndPublish(
    const Frame& frame, const SeedList& seeds, const diffdope::RefinerOptions& options) {
  const ros::WallTime start = ros::WallTime::now();
  std::vector<diffdope::ObjectTarget> targets;
  std::vector<size_t> slot_of, seeds_of;
  std::vector<diffdope_ros::RefinedPose> out;
  for (size_t n = 0; n < seeds.size(); ++n) {
    const auto& [i, starts] = seeds[n];
    Slot& s = *slots_[i];
    diffdope::ObjectTarget t;
    t.mesh = s.mesh.get();
    t.initial = starts.front().pose;
    for (size_t j = 1; j < starts.size(); ++j) t.alternatives.push_back(starts[j].pose);
    if (!frame.labels.empty()) {
      t.mask = object_mask(frame.labels, s.config.mask_label);
      if (cv::countNonZero(t.mask) == 0) {
        // The segmentation says the object is not visible: refining against an empty mask would push it away.
        errors_.warn("empty_mask_" + s.config.name, "object '" + s.config.name + "' has no pixels in the mask (label " +
                                                        std::to_string(s.config.mask_label) + "): not refined");
        if (s.track.report(t.initial, false, frame.header.stamp.toSec())) reportLostTrack(s);
        continue;
      }
    }
    targets.push_back(t);
    slot_of.push_back(i);
    seeds_of.push_back(n);
  }
  if (targets.empty()) {
    for (const auto& [i, starts] : seeds) slots_[i]->tracking = slots_[i]->track.tracking();
    return out;
  }
  // Per-call overrides (service) get their own refiner; streaming reuses the node's.
  std::unique_ptr<diffdope::Refiner> custom;
  if (options.iterations != refiner_options_.iterations || options.batch_size != refiner_options_.batch_size)
    custom = std::make_unique<diffdope::Refiner>(options);
  diffdope::Refiner& refiner = custom ? *custom : *refiner_;
  std::vector<diffdope::RefineResult> results = refiner.refine_all(frame.camera, frame.observation, targets);

  diffdope_ros::RefinedPoseArray array;
  array.header = frame.header;
  std::vector<geometry_msgs::TransformStamped> transforms;
  int implausible = 0;
  for (size_t k = 0; k < results.size(); ++k) {
    Slot& s = *slots_[slot_of[k]];
    const diffdope::RefineResult& r = results[k];
    const std::vector<diffdope::Seed>& starts = seeds[seeds_of[k]].second;
    if (!r.error.empty()) {
      errors_.error("refine_" + s.config.name, "object '" + s.config.name + "' not refined: " + r.error);
      if (s.track.report(starts.front().pose, false, frame.header.stamp.toSec())) reportLostTrack(s);
      continue;
    }
    const diffdope::Seed& seed = starts[std::min<size_t>(size_t(r.start), starts.size() - 1)];
    if (s.track.report(r.pose, r.plausible, frame.header.stamp.toSec())) reportLostTrack(s);
    implausible += !r.plausible;
    const diffdope::Pose inv_model = s.config.model_transform.inverse();
    diffdope_ros::RefinedPose p;
    p.name = s.config.name;
    p.pose.header = frame.header;
    p.pose.pose = pose_to_msg(r.pose * inv_model);
    p.initial_pose = pose_to_msg(seed.pose * inv_model);
    p.source = diffdope::to_string(seed.source);
    p.mask_iou = r.mask_iou;
    p.depth_inliers = r.depth_inliers;
    p.loss = r.loss.total;
    p.initial_loss = r.initial_loss;
    p.converged = r.converged;
    p.plausible = r.plausible;
    p.iterations = r.iterations;
    p.time_ms = r.time_ms;
    out.push_back(p);
    if (!r.plausible && !publish_implausible_) continue;  // scores still go out in ~refined_poses
    s.pose_pub.publish(p.pose);
    if (s.last_tf_stamp == frame.header.stamp) continue;  // already on TF for this image: listeners keep the first
    s.last_tf_stamp = frame.header.stamp;
    geometry_msgs::TransformStamped t;
    t.header = frame.header;
    t.child_frame_id = frame_prefix_ + s.config.name;
    t.transform = transform_to_msg(r.pose * inv_model);
    transforms.push_back(t);
  }
  for (const auto& [i, starts] : seeds) slots_[i]->tracking = slots_[i]->track.tracking();
  if (publish_tf_ && !transforms.empty()) tf_broadcaster_->sendTransform(transforms);
  const double latency = (ros::Time::now() - frame.header.stamp).toSec();
  array.poses = out;
  array.latency = latency;
  array.processing_time = (ros::WallTime::now() - frame.received).toSec();
  refined_pub_.publish(array);
  {
    std::lock_guard<std::mutex> lock(work_mutex_);
    const ros::WallTime now = ros::WallTime::now();
    if (stats_.frames_refined == 0) stats_.first_refined = now;
    stats_.last_refined = now;
    ++stats_.frames_refined;
    stats_.objects_refined += long(out.size());
    stats_.implausible += implausible;
    stats_.last_latency = latency;
    stats_.latency_sum += latency;
    stats_.last_refine_ms = (now - start).toSec() * 1e3;
  }
  try {  // visualisation must never cost the refinement its result
    if (overlay_pub_.getNumSubscribers() > 0) publishOverlay(frame, slot_of, results);
    if (markers_pub_.getNumSubscribers() > 0) publishMarkers(frame, slot_of, results);
  } catch (const std::exception& e) {
    errors_.error("visualisation", std::string("overlay/markers not published: ") + e.what());
  }
  return out;
}

void RefinerNodelet::reportLostTrack(const Slot& s) {
  errors_.warn("lost_" + s.config.name, "lost track of '" + s.config.name + "' (" +
                                            std::to_string(track_options_.max_failures) +
                                            " implausible refinements in a row); waiting for a detection");
}

void RefinerNodelet::publishOverlay(const Frame& frame, const std::vector<size_t>& slots,
                                    const std::vector<diffdope::RefineResult>& results) {
  cv::Mat canvas;
  frame.observation.rgb.convertTo(canvas, CV_8UC3, 255.0);
  cv::cvtColor(canvas, canvas, cv::COLOR_RGB2BGR);
  auto renderer = diffdope::make_cpu_renderer(refiner_options_.render);
  for (size_t k = 0; k < results.size(); ++k) {
    const Slot& s = *slots_[slots[k]];
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
    const Eigen::Vector2d c = frame.camera.project(r.pose.t);
    cv::putText(canvas, s.config.name + (r.plausible ? "" : " (implausible)"), cv::Point(int(c.x()), int(c.y())),
                cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(255, 255, 255), 1, cv::LINE_AA);
  }
  overlay_pub_.publish(cv_bridge::CvImage(frame.header, sensor_msgs::image_encodings::BGR8, canvas).toImageMsg());
}

void RefinerNodelet::publishMarkers(const Frame& frame, const std::vector<size_t>& slots,
                                    const std::vector<diffdope::RefineResult>& results) {
  visualization_msgs::MarkerArray markers;
  for (size_t k = 0; k < results.size(); ++k) {
    const Slot& s = *slots_[slots[k]];
    visualization_msgs::Marker m;
    m.header = frame.header;
    m.ns = "diffdope";
    m.id = int(slots[k]);
    m.type = visualization_msgs::Marker::MESH_RESOURCE;
    m.mesh_resource = s.config.mesh.rfind("package://", 0) == 0 ? s.config.mesh : "file://" + s.config.mesh_path;
    m.mesh_use_embedded_materials = true;
    m.action = results[k].error.empty() ? int(visualization_msgs::Marker::ADD) : int(visualization_msgs::Marker::DELETE);
    m.pose = pose_to_msg(results[k].pose);  // the mesh's own frame
    m.scale.x = m.scale.y = m.scale.z = s.config.mesh_scale;
    m.color.r = results[k].plausible ? 0.2f : 0.9f;
    m.color.g = results[k].plausible ? 0.9f : 0.2f;
    m.color.b = 0.2f;
    m.color.a = 0.8f;
    markers.markers.push_back(m);
  }
  markers_pub_.publish(markers);
}

}  // namespace diffdope_ros

PLUGINLIB_EXPORT_CLASS(diffdope_ros::RefinerNodelet, nodelet::Nodelet)
