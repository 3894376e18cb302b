// RefinerNodelet set-up, parameters, input callbacks, the service hand-over, the sync watchdog and diagnostics.
// The worker (refinement and publishing): refiner_worker.cpp; overlay and markers: refiner_visualization.cpp.
// Parameters and topics: docs/ros.md.
#include "diffdope_ros/refiner_nodelet.hpp"
#include "diffdope_ros/detection_selection.hpp"

#include "base/option_range.hpp"

#include <boost/bind/bind.hpp>
#include <pluginlib/class_list_macros.hpp>
#include <ros/package.h>
#include <visualization_msgs/MarkerArray.h>

#include <sstream>

#include "diffdope_ros/conversions.hpp"

namespace diffdope_ros {
namespace {

const char* kInputNames[4] = {"rgb", "camera_info", "depth", "mask"};

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

  setupReconfigure();
  worker_ = std::thread([this] { workerLoop(); });
  setupInputs();
  // The service runs on its own queue and thread: a call waits for the worker without holding up the inputs or
  // the other nodelets of the manager. Calls are served one after the other (the worker refines one at a time).
  ros::NodeHandle service_nh(getPrivateNodeHandle());
  service_nh.setCallbackQueue(&service_queue_);
  refine_srv_ = service_nh.advertiseService("refine", &RefinerNodelet::onRefineService, this);
  service_spinner_ = std::make_unique<ros::AsyncSpinner>(1, &service_queue_);
  service_spinner_->start();
  watchdog_timer_ = pnh.createWallTimer(ros::WallDuration(1.0), &RefinerNodelet::onWatchdog, this);
  NODELET_INFO_STREAM("diffdope refiner ready: mode "
                      << to_string(mode_)
                      << ", inputs rgb" << (use_depth_ ? "+depth" : "") << (use_mask_ ? "+mask" : "")
                      << ", " << slots_.size() << " object(s), " << refiner_options_.batch_size << " runs x "
                      << refiner_options_.iterations << " iterations (steady tracks: "
                      << (track_options_.batch_size > 0 ? track_options_.batch_size : refiner_options_.batch_size)
                      << " x " << (track_options_.iterations > 0 ? track_options_.iterations : refiner_options_.iterations)
                      << "), backend "
                      << (refiner_ ? refiner_->backend() : std::string("none")));
}

void RefinerNodelet::loadParameters() {
  ros::NodeHandle& pnh = getPrivateNodeHandle();
  try {
    mode_ = parse_stream_mode(pnh.param<std::string>("mode", "tracking"));
  } catch (const std::invalid_argument& e) {
    NODELET_ERROR_STREAM("~" << e.what() << "; using tracking");
    mode_ = Mode::kTracking;
  }
  use_depth_ = pnh.param("use_depth", true);
  use_mask_ = pnh.param("use_mask", false);
  queue_size_ = pnh.param("queue_size", 10);
  max_interval_ = pnh.param("max_interval", 0.1);
  sync_timeout_ = pnh.param("sync_timeout", 3.0);
  tf_timeout_ = pnh.param("tf_timeout", 0.1);
  max_request_time_ = pnh.param("max_request_time", 10.0);
  frame_prefix_ = pnh.param<std::string>("frame_prefix", "diffdope_");
  fixed_frame_ = pnh.param<std::string>("fixed_frame", "");
  detection_prefix_ = pnh.param<std::string>("detection_topic_prefix", "/dope/pose_");
  detections_topic_ = pnh.param<std::string>("detections_topic", "");
  XmlRpc::XmlRpcValue ids;
  if (pnh.getParam("class_ids", ids)) {
    // DOPE's own layout: {object name: class id}.
    if (ids.getType() != XmlRpc::XmlRpcValue::TypeStruct) {
      errors_.error("config", "~class_ids: expected a mapping of object names to DOPE class ids, e.g. {cracker: 1}");
    } else {
      for (auto& kv : ids) {
        if (kv.second.getType() == XmlRpc::XmlRpcValue::TypeInt) class_ids_[kv.first] = static_cast<int>(kv.second);
        else errors_.error("config", "~class_ids: the id of '" + kv.first + "' is not an integer: ignored");
      }
    }
  }
  publish_tf_ = pnh.param("publish_tf", true);
  publish_implausible_ = pnh.param("publish_implausible", false);
  // on_request also seeds from its own previous results ("refine again" on a newer frame).
  track_options_.tracking = mode_ != Mode::kContinuous;
  track_options_.max_detection_age = pnh.param("max_detection_age", 1.0);
  track_options_.track_timeout = pnh.param("track_timeout", 3.0);
  track_options_.max_failures = pnh.param("max_track_failures", 2);
  track_options_.predict = pnh.param("predict_motion", true);
  const double error_throttle = pnh.param("error_throttle", 5.0);
  // Out of range: a configuration error (loadObjects() reports it; nothing is refined), the inputs still set up
  // with the defaults so that their counts and diagnostics keep working.
  try {
    const diffdope::OptionRange check{"parameters"};
    check("~queue_size", queue_size_, 1, 1000, " messages");
    check.above("~max_interval", max_interval_, 0, 10, " seconds");
    check("~sync_timeout", sync_timeout_, 0, 3600, " seconds");
    check("~tf_timeout", tf_timeout_, 0, 60, " seconds");
    check.above("~max_request_time", max_request_time_, 0, 3600, " seconds");
    check("~error_throttle", error_throttle, 0, 3600, " seconds");
    track_options_.validate();
    errors_.set_throttle_period(error_throttle);
  } catch (const std::invalid_argument& e) {
    parameter_error_ = e.what();
    queue_size_ = 10, max_interval_ = 0.1, sync_timeout_ = 3.0, tf_timeout_ = 0.1, max_request_time_ = 10.0;
  }
}

void RefinerNodelet::loadObjects() {
  ros::NodeHandle& pnh = getPrivateNodeHandle();
  const std::string objects_path = pnh.param<std::string>("objects_config", "");
  const std::string refiner_path = pnh.param<std::string>("refiner_config", "");
  const diffdope::PackageResolver resolver = [](const std::string& pkg) { return ros::package::getPath(pkg); };
  diffdope::ObjectsConfig cfg;
  try {
    if (!parameter_error_.empty()) throw std::invalid_argument(parameter_error_);
    if (objects_path.empty()) throw std::runtime_error("~objects_config is not set (path to the objects YAML)");
    cfg = diffdope::load_objects_config(objects_path, resolver);
    refiner_options_ = cfg.refiner;
    // The optional refiner file overrides the objects file's refiner section (launch-time tuning).
    if (!refiner_path.empty()) refiner_options_ = diffdope::RefinerOptions::from_yaml_file(refiner_path, cfg.refiner);
    // Then the ~parameters of the runtime settings (cfg/Refiner.cfg: iterations, image_scale, loss weights...),
    // checked as the YAML's are.
    RefinerConfig launch = to_config({mode_, refiner_options_, track_options_, publish_implausible_});
    launch.__fromServer__(pnh);
    launch.mode = to_string(mode_);  // (read above, with its own message)
    const RuntimeSettings settings = from_config(launch, {mode_, refiner_options_, track_options_, publish_implausible_});
    refiner_options_ = settings.refiner;
    track_options_ = settings.track;
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
  if (use_mask_) {  // several objects reading "any nonzero pixel" would all get the union of their masks
    int any = 0;
    for (const auto& o : cfg.objects) any += o.mask_label < 0;
    if (any > 1)
      errors_.warn("mask_labels", "~use_mask with " + std::to_string(any) +
                                      " objects without a mask_label: each gets every nonzero mask pixel; give "
                                      "each object its label");
  }
  for (size_t i = 0; i < cfg.objects.size(); ++i) {
    auto slot = std::make_unique<Slot>();
    slot->config = cfg.objects[i];
    try {
      slot->mesh = std::make_unique<diffdope::Mesh>(diffdope::load_object_mesh(slot->config));
      refiner_->prepare(*slot->mesh);  // its first detection then pays no set-up
      // Detections within one diameter of an instance's last known centre are that instance's.
      slot->tracks = std::make_unique<diffdope::InstanceTracks>(
          slot->config.max_instances, track_options_, slot->mesh->center().cast<double>(), slot->mesh->diameter());
      NODELET_INFO_STREAM("object '" << slot->config.name << "': " << slot->mesh->num_triangles() << " triangles, "
                                     << "diameter " << format_fixed(slot->mesh->diameter()) << " m"
                                     << (slot->config.max_instances > 1
                                             ? ", up to " + std::to_string(slot->config.max_instances) + " instances"
                                             : std::string()));
    } catch (const std::exception& e) {
      slot->mesh.reset();
      slot->disabled_reason = e.what();
      errors_.error("mesh_" + slot->config.name,
                    "object '" + slot->config.name + "' disabled: cannot load its mesh: " + e.what());
    }
    for (int k = 0; k < slot->config.max_instances; ++k) {
      Instance in;
      in.name = diffdope::instance_name(slot->config, k);
      in.pose_pub = pnh.advertise<geometry_msgs::PoseStamped>("refined/" + in.name, 10);
      in.cov_pub = pnh.advertise<geometry_msgs::PoseWithCovarianceStamped>("refined_cov/" + in.name, 10);
      slot->instances.push_back(in);
    }
    slots_.push_back(std::move(slot));
  }
}

void RefinerNodelet::setupReconfigure() {
  runtime_settings_ = {mode_, refiner_options_, track_options_, publish_implausible_};
  applied_config_ = to_config(runtime_settings_);
  // The server starts from the node's own values (YAML, then ~parameters), not from the .cfg defaults. Its
  // constructor advertises set_parameters before updateConfig below: holding the server's mutex makes a call that
  // arrives in between wait, instead of seeing (and applying) the .cfg defaults.
  boost::recursive_mutex::scoped_lock lock(reconfigure_mutex_);
  reconfigure_server_ =
      std::make_unique<dynamic_reconfigure::Server<RefinerConfig>>(reconfigure_mutex_, getPrivateNodeHandle());
  reconfigure_server_->updateConfig(applied_config_);
  reconfigure_server_->setCallback(
      boost::bind(&RefinerNodelet::onReconfigure, this, boost::placeholders::_1, boost::placeholders::_2));
}

void RefinerNodelet::onReconfigure(RefinerConfig& config, uint32_t level) {
  RuntimeSettings settings;
  try {
    settings = from_config(config, runtime_settings_);
  } catch (const std::invalid_argument& e) {
    errors_.error("reconfigure", std::string("reconfigure refused, the previous values stay: ") + e.what());
    config = applied_config_;  // the server publishes what is in force
    return;
  }
  runtime_settings_ = settings;
  applied_config_ = config;
  if (level == ~0u) return;  // setCallback's first call: the values the node started with
  {
    std::lock_guard<std::mutex> lock(work_mutex_);
    pending_settings_ = settings;
    if (settings.mode == Mode::kOnRequest) frame_pending_ = false;  // nothing more is streamed, not even that one
  }
  mode_ = settings.mode;  // the input callbacks read it; the rest the worker takes at its next job
  NODELET_INFO_STREAM("reconfigured: mode " << to_string(settings.mode) << ", " << settings.refiner.batch_size
                                            << " runs x " << settings.refiner.iterations
                                            << " iterations, image scale " << settings.refiner.image_scale
                                            << " (from the next frame)");
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
  if (!detections_topic_.empty()) {
    subscribeDetectionArray();
    for (const auto& slot : slots_)
      if (!class_ids_.count(slot->config.name))
        errors_.warn("class_ids", "object '" + slot->config.name + "' has no id in ~class_ids: " + detections_topic_ +
                                      " cannot seed it");
  }

  // Each image input has its own transport, as depth_image_proc does: a robot that records colour as
  // "compressed" needs "compressedDepth" (or raw) for depth, and a label mask must stay lossless.
  const image_transport::TransportHints hints("raw", ros::TransportHints(), pnh, "image_transport");
  const image_transport::TransportHints depth_hints("raw", ros::TransportHints(), pnh, "depth_image_transport");
  const image_transport::TransportHints mask_hints("raw", ros::TransportHints(), pnh, "mask_image_transport");
  input_error_ = unknown_transports(
      it_->getLoadableTransports(),
      {{"image_transport", hints.getTransport()},
       {"depth_image_transport", use_depth_ ? depth_hints.getTransport() : "raw"},
       {"mask_image_transport", use_mask_ ? mask_hints.getTransport() : "raw"}});
  if (!input_error_.empty()) {  // a clear error at start; the node stays up and says so in diagnostics
    errors_.error("transport", input_error_);
    return;
  }
  rgb_sub_.subscribe(*it_, "rgb/image_rect_color", queue_size_, hints);
  info_sub_.subscribe(nh, "rgb/camera_info", queue_size_);
  if (use_depth_) depth_sub_.subscribe(*it_, "depth/image_rect", queue_size_, depth_hints);
  if (use_mask_) mask_sub_.subscribe(*it_, "mask", queue_size_, mask_hints);
  using sensor_msgs::CameraInfo;
  using sensor_msgs::Image;
  const auto arrive = [this](int index) { return [this, index](const auto& m) { noteArrival(index, m.header); }; };
  const auto reject = [this](int index) { return [this, index](const std::string& why) { rejectInput(index, why); }; };
  rgb_in_.connect(rgb_sub_, arrive(0), [](const Image& m) {
    if (m.header.frame_id.empty()) throw std::invalid_argument("rgb image: empty header.frame_id");
    check_rgb_image(m);
  }, reject(0));
  info_in_.connect(info_sub_, arrive(1), [](const CameraInfo& m) { camera_from_info(m); }, reject(1));
  if (use_depth_) depth_in_.connect(depth_sub_, arrive(2), [](const Image& m) { check_depth_image(m); }, reject(2));
  if (use_mask_) mask_in_.connect(mask_sub_, arrive(3), [](const Image& m) { check_labels_image(m); }, reject(3));

  const ros::Duration max_interval(std::max(0.0, max_interval_));
  if (use_depth_ && use_mask_) {
    sync4_ = std::make_unique<message_filters::Synchronizer<Policy4>>(Policy4(queue_size_), rgb_in_, info_in_,
                                                                       depth_in_, mask_in_);
    if (max_interval_ > 0) sync4_->setMaxIntervalDuration(max_interval);
    sync4_->registerCallback(&RefinerNodelet::onSync4, this);
  } else if (use_depth_ || use_mask_) {
    sync3_ = std::make_unique<message_filters::Synchronizer<Policy3>>(Policy3(queue_size_), rgb_in_, info_in_,
                                                                       use_depth_ ? depth_in_ : mask_in_);
    if (max_interval_ > 0) sync3_->setMaxIntervalDuration(max_interval);
    sync3_->registerCallback(&RefinerNodelet::onSync3, this);
  } else {
    sync2_ = std::make_unique<message_filters::Synchronizer<Policy2>>(Policy2(queue_size_), rgb_in_, info_in_);
    if (max_interval_ > 0) sync2_->setMaxIntervalDuration(max_interval);
    sync2_->registerCallback(&RefinerNodelet::onSync2, this);
  }
}

RefinerNodelet::~RefinerNodelet() {
  reconfigure_server_.reset();  // (its callback uses the members below)
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
  if (service_spinner_) service_spinner_->stop();
  refine_srv_.shutdown();
  rgb_in_.disconnect(), info_in_.disconnect(), depth_in_.disconnect(), mask_in_.disconnect();
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
  ++input_counts_[index].received;
  last_arrival_[index] = ros::WallTime::now();
  if (index == 0 && first_arrival_.isZero()) first_arrival_ = last_arrival_[index];
  last_stamp_[index] = header.stamp;
}

void RefinerNodelet::rejectInput(int index, const std::string& reason) {
  {
    std::lock_guard<std::mutex> lock(arrival_mutex_);
    ++input_counts_[index].malformed;
  }
  // Throttled per input; reason reads "<input> image: problem".
  errors_.error(std::string("input/") + kInputNames[index], std::string(kInputNames[index]) + " message dropped: " + reason);
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
    ++input_counts_[0].synchronized, ++input_counts_[1].synchronized;
    if (depth) ++input_counts_[2].synchronized;
    if (mask) ++input_counts_[3].synchronized;
  }
  auto frame = std::make_shared<Frame>();
  frame->received = ros::WallTime::now();
  frame->header = rgb->header;
  frame->rgb_msg = rgb;
  try {  // (each message passed its own checks before the synchronizer: CheckedInput)
    std::string warning;
    frame->camera = camera_from_info(*info, &warning);
    if (!warning.empty()) errors_.warn("camera_info_k", warning);
    // The rgb image's frame is the camera frame used; inputs in other frames are most likely not registered to
    // it (another camera of the rig, unaligned depth). Said, not refused: some drivers name frames loosely.
    const auto differs = [&](const std::string& other, const char* what) {
      if (!other.empty() && strip_slash(other) != strip_slash(rgb->header.frame_id))
        errors_.warn(std::string("frame/") + what, std::string(what) + " is in frame '" + other +
                                                       "' but the rgb image in '" + rgb->header.frame_id +
                                                       "': using the rgb frame (is it registered to the rgb camera?)");
    };
    differs(info->header.frame_id, "camera_info");
    if (depth) differs(depth->header.frame_id, "depth");
    if (mask) differs(mask->header.frame_id, "mask");
    if (int(rgb->width) != frame->camera.width || int(rgb->height) != frame->camera.height)
      throw std::invalid_argument("rgb image is " + std::to_string(rgb->width) + "x" + std::to_string(rgb->height) +
                                  " but camera_info says " + std::to_string(info->width) + "x" +
                                  std::to_string(info->height));
    auto same_size = [&](const sensor_msgs::Image& im, const char* what) {
      if (im.width != rgb->width || im.height != rgb->height)
        throw std::invalid_argument(std::string(what) + " image is " + std::to_string(im.width) + "x" +
                                    std::to_string(im.height) + " but rgb is " + std::to_string(rgb->width) + "x" +
                                    std::to_string(rgb->height) + " (register it to the rgb camera)");
    };
    if (depth) {
      same_size(*depth, "depth");
      frame->depth_msg = depth;
    }
    if (mask) {
      same_size(*mask, "mask");
      frame->mask_msg = mask;
    }
  } catch (const std::exception& e) {
    reportInputError(e);
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

void RefinerNodelet::reportInputError(const std::exception& e) {
  const std::string what = e.what();  // "<input> image: problem": throttle per input, not one for all
  errors_.error("input/" + what.substr(0, what.find(':')), "input frame dropped: " + what);
}

void RefinerNodelet::onDetection(const geometry_msgs::PoseStampedConstPtr& msg, size_t slot) {
  storeDetections({*msg}, slot, "detection for '" + slots_[slot]->config.name + "'");
}

void RefinerNodelet::onInitialPoses(const diffdope_ros::InitialPoseArrayConstPtr& msg) {
  std::map<size_t, std::vector<geometry_msgs::PoseStamped>> by_slot;  // entries of one name: its instances
  for (const auto& p : msg->poses) {
    size_t i = 0;
    while (i < slots_.size() && slots_[i]->config.name != p.name) ++i;
    if (i == slots_.size()) {
      errors_.error("unknown_object", "~initial_poses: unknown object name '" + p.name + "' (not in the objects config)");
      continue;
    }
    by_slot[i].push_back(p.pose);
  }
  for (const auto& [i, poses] : by_slot)
    storeDetections(poses, i, "~initial_poses entry for '" + slots_[i]->config.name + "'");
}

void RefinerNodelet::storeDetections(const std::vector<geometry_msgs::PoseStamped>& poses, size_t slot,
                                     const std::string& origin) {
  std::vector<geometry_msgs::PoseStamped> usable;
  for (const auto& pose : poses) {
    try {
      pose_from_msg(pose.pose, origin);  // reject NaN / zero quaternions at once
      if (pose.header.frame_id.empty()) throw std::invalid_argument(origin + ": empty header.frame_id");
      usable.push_back(pose);
    } catch (const std::exception& e) {
      errors_.error("pose/" + slots_[slot]->config.name, std::string("initial pose ignored: ") + e.what());
    }
  }
  if (usable.empty()) return;
  std::lock_guard<std::mutex> lock(detections_mutex_);
  auto& pending = slots_[slot]->pending_detections;
  // The newest message wins; but with several instances, messages of the same stamp are one detection round
  // (a detector that publishes a PoseStamped per instance, one after the other).
  if (pending && !pending->empty() && slots_[slot]->config.max_instances > 1 &&
      pending->front().header.stamp == usable.front().header.stamp)
    pending->insert(pending->end(), usable.begin(), usable.end());
  else
    pending = std::move(usable);
}

void RefinerNodelet::subscribeDetectionArray() {
  detection_array_sub_.shutdown();
  detection_array_sub_ = getNodeHandle().subscribe<topic_tools::ShapeShifter>(detections_topic_, 5,
                                                                              &RefinerNodelet::onDetectionArray, this);
}

void RefinerNodelet::onDetectionArray(const topic_tools::ShapeShifter::ConstPtr& msg) {
  const auto count = [this](long DetectionArrayCounts::*field, long n) {
    std::lock_guard<std::mutex> lock(arrival_mutex_);
    detection_array_counts_.*field += n;
  };
  count(&DetectionArrayCounts::received, 1);
  const std::string where = "~detections_topic " + detections_topic_ + ": ";
  if (msg->getDataType() != kDetection3DArrayType || msg->getMD5Sum() != kDetection3DArrayMd5) {
    count(&DetectionArrayCounts::malformed, 1);
    errors_.error("detections", where + "a " + msg->getDataType() + " (MD5 " + msg->getMD5Sum() + "), expected " +
                                    kDetection3DArrayType + " with MD5 " + kDetection3DArrayMd5 +
                                    " (DOPE's, integer class ids): ignored");
    // A ROS 1 subscription keeps the type of the first publisher it connects to: subscribe afresh (from the
    // watchdog, outside this callback) so that a publisher of the right type can still connect.
    resubscribe_detections_ = true;
    return;
  }
  DecodedDetectionArray decoded;
  try {
    std::vector<uint8_t> bytes(msg->size());
    ros::serialization::OStream out(bytes.data(), uint32_t(bytes.size()));
    msg->write(out);
    decoded = decode_detection3d_array(bytes.data(), bytes.size());
  } catch (const std::exception& e) {
    count(&DetectionArrayCounts::malformed, 1);
    errors_.error("detections", where + e.what() + ": ignored");
    return;
  }
  const DetectionSelection chosen = select_detections(decoded, class_ids_);
  count(&DetectionArrayCounts::unknown_class, long(chosen.unknown_class_ids.size()));
  if (!chosen.unknown_class_ids.empty())
    errors_.warn("class_ids", where + std::to_string(chosen.unknown_class_ids.size()) +
                                  " detection(s) with a class id no object has in ~class_ids (first: " +
                                  std::to_string(chosen.unknown_class_ids.front()) + ")");
  for (const auto& [name, poses] : chosen.by_object) {
    for (size_t i = 0; i < slots_.size(); ++i) {
      if (slots_[i]->config.name != name) continue;
      count(&DetectionArrayCounts::used, long(poses.size()));
      storeDetections(poses, i, where + "class id " + std::to_string(class_ids_.at(name)) + " ('" + name + "')");
    }
  }
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
  // Once the publisher of the other type has gone (while it is connected a new subscription would take its type
  // again, and a publisher of the right one still could not connect).
  if (resubscribe_detections_ && detection_array_sub_.getNumPublishers() == 0) {
    resubscribe_detections_ = false;
    subscribeDetectionArray();
  }
  // Inputs that arrive but never form a synchronized set (a silent topic, stamps too far apart) are an error.
  const ros::WallTime now = ros::WallTime::now();
  std::unique_lock<std::mutex> lock(arrival_mutex_);
  const bool rgb_recent = !last_arrival_[0].isZero() && (now - last_arrival_[0]).toSec() < 1.5;
  // Before any synchronized set, count from the first rgb message (a silent depth or mask topic).
  const double since_sync = last_sync_.isZero() ? (now - first_arrival_).toSec() : (now - last_sync_).toSec();
  if (rgb_recent && since_sync > sync_timeout_) {
    std::ostringstream msg;
    msg << "no synchronized input for " << format_fixed(since_sync, 1) << " s (~sync_timeout " << sync_timeout_
        << " s, ~max_interval " << max_interval_ << " s); last stamps:";
    const bool used[4] = {true, true, use_depth_, use_mask_};
    for (int i = 0; i < 4; ++i) {
      if (!used[i]) continue;
      msg << " " << kInputNames[i] << "=";
      if (last_arrival_[i].isZero()) msg << "never received";
      else msg << format_fixed(last_stamp_[i].toSec());
    }
    msg << " (topics: " << rgb_sub_.getTopic() << ", " << info_sub_.getTopic()
        << (use_depth_ ? ", " + depth_sub_.getTopic() : "") << (use_mask_ ? ", " + mask_sub_.getTopic() : "") << ")";
    errors_.error("sync", msg.str());
  }
  lock.unlock();  // (onDiagnostics takes it too)
  // force_update: this timer already paces it (1 s of wall time). update() gates on ros::Time, which under sim
  // time stops publishing after the clock jumps back (a looped bag) until it catches up again.
  if (diagnostics_) diagnostics_->force_update();
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
  // The worker serves ~refine calls before frames: while it does, streaming is paused (and says so).
  const bool on_request = mode_ == Mode::kOnRequest, serving = !s.serving_since.isZero();
  const std::string serving_for =
      serving ? format_fixed((ros::WallTime::now() - s.serving_since).toSec(), 1) + " s" : "";
  const std::string streaming = on_request ? (serving ? "off (mode on_request); serving a ~refine call for " + serving_for
                                                      : "off (mode on_request)")
                                           : (serving ? "paused for " + serving_for + ": serving a ~refine call"
                                                      : "running");
  if (!input_error_.empty()) stat.summary(diagnostic_msgs::DiagnosticStatus::ERROR, "no input subscribed: " + input_error_);
  else if (enabled == 0) stat.summary(diagnostic_msgs::DiagnosticStatus::ERROR, "no object can be refined: " + e.last_error);
  else if (recent_error) stat.summary(diagnostic_msgs::DiagnosticStatus::WARN, e.last_error);
  else stat.summary(diagnostic_msgs::DiagnosticStatus::OK, serving && !on_request ? "streaming " + streaming : "refining");
  stat.add("streaming", streaming);
  stat.add("inputs", input_error_.empty() ? "subscribed" : "none: " + input_error_);
  stat.add("objects enabled", std::to_string(enabled) + " of " + std::to_string(slots_.size()));
  stat.add("backend", refiner_ ? refiner_->backend() : std::string("none (configuration error)"));
  for (const auto& slot : slots_) {
    const int tracked = slot->tracking, n = slot->config.max_instances;
    std::string state = "disabled: " + slot->disabled_reason;
    if (slot->mesh && n == 1) state = tracked ? "tracking" : "waiting for a pose";
    else if (slot->mesh) state = "tracking " + std::to_string(tracked) + " of up to " + std::to_string(n) + " instances";
    stat.add("object " + slot->config.name, state);
  }
  {
    // Every message of every input: synchronized, malformed (dropped with its reason before the synchronizer), or
    // never matched by the other inputs (stamps too far apart, a silent topic; up to ~queue_size still waiting).
    std::lock_guard<std::mutex> lock(arrival_mutex_);
    const bool used[4] = {true, true, use_depth_, use_mask_};
    for (int i = 0; i < 4; ++i) {
      if (!used[i]) continue;
      const InputCounts& c = input_counts_[i];
      stat.add(std::string("input ") + kInputNames[i],
               "received " + std::to_string(c.received) + ", synchronized " + std::to_string(c.synchronized) +
                   ", malformed " + std::to_string(c.malformed) + ", unmatched " +
                   std::to_string(std::max(0L, c.received - c.synchronized - c.malformed)));
    }
  }
  if (!detections_topic_.empty()) {
    std::lock_guard<std::mutex> lock(arrival_mutex_);
    const DetectionArrayCounts& c = detection_array_counts_;
    stat.add("input detections (Detection3DArray)",
             "received " + std::to_string(c.received) + ", used " + std::to_string(c.used) + ", malformed " +
                 std::to_string(c.malformed) + ", unknown class ids " + std::to_string(c.unknown_class));
  }
  stat.add("frames synchronized", s.frames_synced);
  stat.add("frames refined", s.frames_refined);
  stat.add("frames skipped (worker busy)", s.frames_skipped);
  stat.add("objects refined", s.objects_refined);
  stat.add("implausible results", s.implausible);
  stat.add("detections beyond max_instances (ignored)", s.extra_detections);
  stat.add("refine rate (frames/s)", format_fixed(rate, 2));
  stat.add("last latency (s)", format_fixed(s.last_latency));
  stat.add("mean latency (s)", format_fixed(s.frames_refined ? s.latency_sum / s.frames_refined : -1.0));
  stat.add("last refine time (ms)", format_fixed(s.last_refine_ms, 1));
  stat.add("~refine calls succeeded", s.requests_succeeded);
  stat.add("~refine calls failed or refused", s.requests_failed);
  stat.add("estimated cost (ms per object and evaluation)",
           s.cost_measured ? format_fixed(s.ms_per_evaluation, 3) + " (measured)"
                           : format_fixed(1e3 * refine_time_.kPriorSecondsPerEvaluation, 3) + " (prior, nothing timed yet)");
  stat.add("last error", e.last_error);
  for (const auto& kv : e.error_counts) stat.add("errors: " + kv.first, kv.second);
  for (const auto& kv : e.warn_counts) stat.add("warnings: " + kv.first, kv.second);
}

}  // namespace diffdope_ros

PLUGINLIB_EXPORT_CLASS(diffdope_ros::RefinerNodelet, nodelet::Nodelet)
