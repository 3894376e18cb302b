// RefinerNodelet set-up (refiner_nodelet.hpp): settings, objects, outputs, inputs, the worker; the hand-over of
// synchronized frames to the worker; the watchdog; teardown.
#include "ros/refiner/refiner_nodelet.hpp"

#include <geometry_msgs/PoseWithCovarianceStamped.h>
#include <pluginlib/class_list_macros.hpp>
#include <ros/package.h>
#include <std_msgs/Bool.h>
#include <visualization_msgs/MarkerArray.h>

#include <map>
#include <string>
#include <vector>

#include "diffdope_ros/conversions.hpp"

namespace diffdope_ros {

void RefinerNodelet::onInit() {
  ros::NodeHandle& nh = getNodeHandle();
  ros::NodeHandle& pnh = getPrivateNodeHandle();
  settings_ = load_refiner_settings(pnh, getName(), errors_);
  if (settings_.error.empty()) errors_.set_throttle_period(settings_.error_throttle);
  mode_ = settings_.mode;
  WorkerOptions options;
  options.track = settings_.track;
  options.publish_implausible = settings_.publish_implausible;

  publishers_.tf_buffer = std::make_unique<tf2_ros::Buffer>(ros::Duration(30.0));
  publishers_.tf_listener = std::make_unique<tf2_ros::TransformListener>(*publishers_.tf_buffer, nh);
  publishers_.tf_broadcaster = std::make_unique<tf2_ros::TransformBroadcaster>();
  publishers_.refined = pnh.advertise<diffdope_ros::RefinedPoseArray>("refined_poses", 10);
  publishers_.markers = pnh.advertise<visualization_msgs::MarkerArray>("markers", 1);
  inputs_.it = std::make_unique<image_transport::ImageTransport>(nh);
  image_transport::ImageTransport pit(pnh);
  publishers_.overlay = pit.advertise("overlay", 1);

  std::unique_ptr<diffdope::Refiner> refiner = loadObjects(options);
  // (Read now for ~ready and the log below: the worker takes the refiner.)
  const bool can_refine = refiner != nullptr;
  const std::string backend = refiner ? refiner->backend() : std::string("none");
  std::vector<DetectionInbox::Object> inbox_objects;
  for (const auto& slot : slots_)
    inbox_objects.push_back({slot->config.name, slot->config.max_instances, slot->config.pose_topic});
  inputs_.inbox = std::make_unique<DetectionInbox>(std::move(inbox_objects), settings_, errors_);

  publishers_.diagnostics = std::make_unique<diagnostic_updater::Updater>(nh, pnh, getName());
  publishers_.diagnostics->setHardwareID("diffdope_refiner");
  publishers_.diagnostics->add("refiner", this, &RefinerNodelet::onDiagnostics);

  setupReconfigure(options);
  worker_ = std::make_unique<Worker>(options, std::move(refiner), settings_, errors_, slots_, *inputs_.inbox,
                                     publishers_, handover_);
  worker_->start();
  inputs_.inbox->subscribe(nh, pnh);
  inputs_.sync.start(nh, pnh, *inputs_.it, [this](std::shared_ptr<Frame> frame) { onFrame(std::move(frame)); });
  // The service runs on its own queue and thread: a call waits for the worker without holding up the inputs or
  // the other nodelets of the manager. Calls are served one after the other (the worker refines one at a time).
  ros::NodeHandle service_nh(pnh);
  service_nh.setCallbackQueue(&inputs_.service_queue);
  inputs_.refine_service = service_nh.advertiseService("refine", &RefinerNodelet::onRefineService, this);
  inputs_.service_spinner = std::make_unique<ros::AsyncSpinner>(1, &inputs_.service_queue);
  inputs_.service_spinner->start();
  inputs_.watchdog = pnh.createWallTimer(ros::WallDuration(1.0), &RefinerNodelet::onWatchdog, this);
  // Latched: a launch or a bag player can wait for the meshes to be loaded and the inputs subscribed; false when
  // the configuration leaves nothing to refine (the error is logged and in diagnostics).
  publishers_.ready = pnh.advertise<std_msgs::Bool>("ready", 1, true);
  std_msgs::Bool ready;
  ready.data = can_refine;
  publishers_.ready.publish(ready);
  const diffdope::RefinerOptions& o = options.refiner;
  const diffdope::TrackOptions& t = options.track;
  NODELET_INFO_STREAM("diffdope refiner ready: mode "
                      << to_string(mode_) << ", inputs rgb" << (settings_.use_depth ? "+depth" : "")
                      << (settings_.use_mask ? "+mask" : "") << ", " << slots_.size() << " object(s), "
                      << o.batch_size << " runs x " << o.iterations << " iterations (steady tracks: "
                      << (t.batch_size > 0 ? t.batch_size : o.batch_size) << " x "
                      << (t.iterations > 0 ? t.iterations : o.iterations) << "), backend "
                      << backend);
}

std::unique_ptr<diffdope::Refiner> RefinerNodelet::loadObjects(WorkerOptions& options) {
  ros::NodeHandle& pnh = getPrivateNodeHandle();
  const diffdope::PackageResolver resolver = [](const std::string& pkg) { return ros::package::getPath(pkg); };
  diffdope::ObjectsConfig cfg;
  std::unique_ptr<diffdope::Refiner> refiner;
  try {
    if (!settings_.error.empty()) throw std::invalid_argument(settings_.error);
    if (settings_.objects_config.empty())
      throw std::runtime_error("~objects_config is not set (path to the objects YAML)");
    cfg = diffdope::load_objects_config(settings_.objects_config, resolver);
    // Class ids the objects file gives (DOPE's config_pose.yaml has them); ~class_ids, when set, wins. Two objects
    // with one id would take each other's detections (the file's own are checked as it is read).
    settings_.class_ids =
        diffdope::object_class_ids(cfg.objects, settings_.class_ids, settings_.objects_config + " with ~class_ids");
    const std::string unrefined = diffdope::unrefined_classes(cfg);
    if (!unrefined.empty() && cfg.meshes_without_weights.empty()) NODELET_INFO_STREAM(unrefined);
    else if (!unrefined.empty()) NODELET_WARN_STREAM(unrefined);
    if (cfg.input_is_rectified == false)
      NODELET_WARN_STREAM(settings_.objects_config
                          << ": input_is_rectified is False: this node projects with CameraInfo's P and never "
                             "undistorts, so raw images of a camera with distortion give poses off by it; rectify "
                             "them (image_proc's image_rect_color) for DOPE and the refiner alike");
    options.refiner = cfg.refiner;
    // The optional refiner file overrides the objects file's refiner section (launch-time tuning).
    if (!settings_.refiner_config.empty())
      options.refiner = diffdope::RefinerOptions::from_yaml_file(settings_.refiner_config, cfg.refiner);
    // Then the ~parameters of the runtime settings (cfg/Refiner.cfg: iterations, image_scale, loss weights...),
    // checked as the YAML's are.
    const RuntimeSettings launch_values{mode_, options.refiner, options.track, options.publish_implausible};
    RefinerConfig launch = to_config(launch_values);
    launch.__fromMessage__(settings_.runtime_parameters);  // (read with the other settings)
    launch.mode = to_string(mode_);  // (read with the settings, with its own message)
    const RuntimeSettings settings = from_config(launch, launch_values);
    // Said at start: a value set through dynamic_reconfigure stays on the parameter server, so a restarted node
    // takes it instead of the YAML's.
    const std::vector<ConfigChange> overrides = config_changes(to_config(launch_values), launch);
    if (!overrides.empty())
      NODELET_INFO_STREAM("~parameters override the YAML: " << describe(overrides)
                                                           << " (a value set through dynamic_reconfigure stays on "
                                                              "the parameter server until deleted)");
    const std::string bound = bound_warning(overrides);
    if (!bound.empty()) errors_.warn("parameters", "~parameter " + bound);
    options.refiner = settings.refiner;
    options.track = settings.track;
    if (!settings_.device.empty()) options.refiner.device = settings_.device;
    options.refiner.validate();
    // One refiner (and renderer: CUDA keeps the meshes on the device) for the node's life; "cuda" without a
    // device throws here, "auto" falls back to the CPU with one line.
    refiner = std::make_unique<diffdope::Refiner>(options.refiner);
    std::lock_guard<std::mutex> lock(handover_.mutex);
    handover_.stats.backend = refiner->backend();
  } catch (const std::exception& e) {
    errors_.error("config", std::string("configuration error, no object will be refined: ") + e.what());
    return nullptr;
  }
  if (settings_.use_mask) {  // several objects reading "any nonzero pixel" would all get the union of their masks
    int any = 0;
    for (const auto& o : cfg.objects) any += o.mask_label < 0;
    if (any > 1)
      errors_.warn("mask_labels", "~use_mask with " + std::to_string(any) +
                                      " objects without a mask_label: each gets every nonzero mask pixel; give "
                                      "each object its label");
  }
  for (const diffdope::ObjectConfig& config : cfg.objects) {
    auto slot = std::make_unique<Slot>();
    slot->config = config;
    try {
      slot->mesh = std::make_unique<diffdope::Mesh>(diffdope::load_object_mesh(slot->config));
      refiner->prepare(*slot->mesh);  // its first detection then pays no set-up
      // Detections within one diameter of an instance's last known centre are that instance's.
      slot->tracks = std::make_unique<diffdope::InstanceTracks>(
          slot->config.max_instances, options.track, slot->mesh->center().cast<double>(), slot->mesh->diameter());
      NODELET_INFO_STREAM("object '" << slot->config.name << "': " << slot->mesh->num_triangles() << " triangles, "
                                     << "diameter " << format_fixed(slot->mesh->diameter()) << " m, box centre ("
                                     << format_fixed(slot->mesh->center().x()) << ", "
                                     << format_fixed(slot->mesh->center().y()) << ", "
                                     << format_fixed(slot->mesh->center().z()) << ") m in the mesh's frame"
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
  return refiner;
}

void RefinerNodelet::onFrame(std::shared_ptr<Frame> frame) {
  {
    std::lock_guard<std::mutex> lock(handover_.mutex);
    ++handover_.stats.frames_synced;
    if (handover_.frame_pending) ++handover_.stats.frames_skipped;  // the worker was busy: streaming takes the newest frame
    handover_.latest_frame = std::move(frame);
    handover_.frame_pending = mode_ != StreamMode::kOnRequest;
  }
  handover_.cv.notify_one();
}

void RefinerNodelet::onWatchdog(const ros::WallTimerEvent&) {
  if (inputs_.inbox) inputs_.inbox->resubscribeIfNeeded();
  inputs_.sync.checkSynchronization();
  // force_update: this timer already paces it (1 s of wall time). update() gates on ros::Time, which under sim
  // time stops publishing after the clock jumps back (a looped bag) until it catches up again.
  if (publishers_.diagnostics) publishers_.diagnostics->force_update();
}

RefinerNodelet::~RefinerNodelet() {
  reconfigure_.server.reset();  // (its callback uses the members below)
  if (worker_) worker_->stop();  // answers the ~refine calls still waiting
  inputs_.watchdog.stop();
  if (inputs_.service_spinner) inputs_.service_spinner->stop();
  inputs_.refine_service.shutdown();
  inputs_.sync.shutdown();
  if (inputs_.inbox) inputs_.inbox->shutdown();
  publishers_.diagnostics.reset();
}

}  // namespace diffdope_ros

PLUGINLIB_EXPORT_CLASS(diffdope_ros::RefinerNodelet, nodelet::Nodelet)
