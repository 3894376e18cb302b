// The refiner's image inputs (input_sync.hpp): per-input checks, synchronization, counts and the sync watchdog.
#include "ros/refiner/input_sync.hpp"

#include <algorithm>
#include <sstream>

#include "diffdope_ros/conversions.hpp"

namespace diffdope_ros {
namespace {

const char* kInputNames[4] = {"rgb", "camera_info", "depth", "mask"};
/// An rgb message within this many seconds means the inputs are flowing (the watchdog's concern); a longer gap
/// is a pause.
constexpr double kRecentArrival = 1.5;

}  // namespace

void report_input_error(ErrorReporter& errors, const std::exception& e) {
  // Throttled per input, not one for all; the category is the input the message names first ("depth image is
  // 400x300 ..."), never the message itself: its sizes and values would make each message a category of its own.
  const std::string what = e.what();
  std::string input = "other";
  for (const char* name : kInputNames)
    if (what.rfind(name, 0) == 0) {
      input = name;
      break;
    }
  errors.error("input/" + input, "input frame dropped: " + what);
}

bool InputSync::used(int index) const {
  return index == kDepth ? settings_.use_depth : index == kMask ? settings_.use_mask : true;
}

void InputSync::start(ros::NodeHandle& nh, ros::NodeHandle& pnh, image_transport::ImageTransport& it,
                      FrameCallback on_frame) {
  on_frame_ = std::move(on_frame);
  const bool use_depth = settings_.use_depth, use_mask = settings_.use_mask;
  const int queue_size = settings_.queue_size;
  // Each image input has its own transport, as depth_image_proc does: a robot that records colour as
  // "compressed" needs "compressedDepth" (or raw) for depth, and a label mask must stay lossless.
  const image_transport::TransportHints hints("raw", ros::TransportHints(), pnh, "image_transport");
  const image_transport::TransportHints depth_hints("raw", ros::TransportHints(), pnh, "depth_image_transport");
  const image_transport::TransportHints mask_hints("raw", ros::TransportHints(), pnh, "mask_image_transport");
  error_ = unknown_transports(it.getLoadableTransports(),
                             {{"image_transport", hints.getTransport()},
                              {"depth_image_transport", use_depth ? depth_hints.getTransport() : "raw"},
                              {"mask_image_transport", use_mask ? mask_hints.getTransport() : "raw"}});
  if (!error_.empty()) {  // a clear error at start; the node stays up and says so in diagnostics
    errors_.error("transport", error_);
    return;
  }
  rgb_sub_.subscribe(it, "rgb/image_rect_color", queue_size, hints);
  info_sub_.subscribe(nh, "rgb/camera_info", queue_size);
  if (use_depth) depth_sub_.subscribe(it, "depth/image_rect", queue_size, depth_hints);
  if (use_mask) mask_sub_.subscribe(it, "mask", queue_size, mask_hints);
  using sensor_msgs::CameraInfo;
  using sensor_msgs::Image;
  const auto arrive = [this](int index) { return [this, index](const auto& m) { noteArrival(index, m.header); }; };
  const auto reject = [this](int index) { return [this, index](const std::string& why) { rejectInput(index, why); }; };
  rgb_in_.connect(rgb_sub_, arrive(kRgb), [](const Image& m) {
    if (m.header.frame_id.empty()) throw std::invalid_argument("rgb image: empty header.frame_id");
    check_rgb_image(m);
  }, reject(kRgb));
  info_in_.connect(info_sub_, arrive(kInfo), [](const CameraInfo& m) { camera_from_info(m); }, reject(kInfo));
  if (use_depth)
    depth_in_.connect(depth_sub_, arrive(kDepth), [](const Image& m) { check_depth_image(m); }, reject(kDepth));
  if (use_mask)
    mask_in_.connect(mask_sub_, arrive(kMask), [](const Image& m) { check_labels_image(m); }, reject(kMask));

  const double interval = settings_.max_interval;
  const ros::Duration max_interval(std::max(0.0, interval));
  if (use_depth && use_mask) {
    sync4_ = std::make_unique<message_filters::Synchronizer<Policy4>>(Policy4(queue_size), rgb_in_, info_in_,
                                                                       depth_in_, mask_in_);
    if (interval > 0) sync4_->setMaxIntervalDuration(max_interval);
    sync4_->registerCallback(&InputSync::onSync4, this);
  } else if (use_depth || use_mask) {
    sync3_ = std::make_unique<message_filters::Synchronizer<Policy3>>(Policy3(queue_size), rgb_in_, info_in_,
                                                                       use_depth ? depth_in_ : mask_in_);
    if (interval > 0) sync3_->setMaxIntervalDuration(max_interval);
    sync3_->registerCallback(&InputSync::onSync3, this);
  } else {
    sync2_ = std::make_unique<message_filters::Synchronizer<Policy2>>(Policy2(queue_size), rgb_in_, info_in_);
    if (interval > 0) sync2_->setMaxIntervalDuration(max_interval);
    sync2_->registerCallback(&InputSync::onSync2, this);
  }
}

void InputSync::shutdown() {
  rgb_in_.disconnect(), info_in_.disconnect(), depth_in_.disconnect(), mask_in_.disconnect();
  rgb_sub_.unsubscribe();
  info_sub_.unsubscribe();
  depth_sub_.unsubscribe();
  mask_sub_.unsubscribe();
  sync2_.reset();
  sync3_.reset();
  sync4_.reset();
}

void InputSync::noteArrival(int index, const std_msgs::Header& header) {
  std::lock_guard<std::mutex> lock(mutex_);
  ++counts_[index].received;
  const ros::WallTime now = ros::WallTime::now();
  if (index == kRgb && (last_arrival_[kRgb].isZero() || (now - last_arrival_[kRgb]).toSec() > kRecentArrival))
    arrivals_resumed_ = now;
  last_arrival_[index] = now;
  last_stamp_[index] = header.stamp;
}

void InputSync::rejectInput(int index, const std::string& reason) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    ++counts_[index].malformed;
    last_rejected_ = ros::WallTime::now();
  }
  // Throttled per input; reason reads "<input> image: problem".
  errors_.error(std::string("input/") + kInputNames[index], std::string(kInputNames[index]) + " message dropped: " + reason);
}

void InputSync::onSync2(const sensor_msgs::ImageConstPtr& rgb, const sensor_msgs::CameraInfoConstPtr& info) {
  onImages(rgb, info, nullptr, nullptr);
}

void InputSync::onSync3(const sensor_msgs::ImageConstPtr& rgb, const sensor_msgs::CameraInfoConstPtr& info,
                        const sensor_msgs::ImageConstPtr& third) {
  if (settings_.use_depth) onImages(rgb, info, third, nullptr);
  else onImages(rgb, info, nullptr, third);
}

void InputSync::onSync4(const sensor_msgs::ImageConstPtr& rgb, const sensor_msgs::CameraInfoConstPtr& info,
                        const sensor_msgs::ImageConstPtr& depth, const sensor_msgs::ImageConstPtr& mask) {
  onImages(rgb, info, depth, mask);
}

void InputSync::onImages(const sensor_msgs::ImageConstPtr& rgb, const sensor_msgs::CameraInfoConstPtr& info,
                         const sensor_msgs::ImageConstPtr& depth, const sensor_msgs::ImageConstPtr& mask) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    last_sync_ = ros::WallTime::now();
    ++counts_[kRgb].synchronized, ++counts_[kInfo].synchronized;
    if (depth) ++counts_[kDepth].synchronized;
    if (mask) ++counts_[kMask].synchronized;
  }
  auto frame = std::make_shared<Frame>();
  frame->received = ros::WallTime::now();
  frame->header = rgb->header;
  frame->rgb_msg = rgb;
  try {  // (each message passed its own checks before the synchronizer: CheckedInput)
    std::string warning;
    frame->camera = camera_from_info(*info, &warning);
    if (!warning.empty()) {  // each once: it holds for every frame
      bool first;
      {
        std::lock_guard<std::mutex> lock(mutex_);
        first = noted_.insert(warning).second;
      }
      if (first) errors_.warn("camera_info", warning);
    }
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
    report_input_error(errors_, e);
    return;
  }
  on_frame_(std::move(frame));
}

void InputSync::checkSynchronization() {
  // Inputs that arrive but never form a synchronized set (a silent topic, stamps too far apart) are an error.
  const ros::WallTime now = ros::WallTime::now();
  std::lock_guard<std::mutex> lock(mutex_);
  const bool rgb_recent = !last_arrival_[kRgb].isZero() && (now - last_arrival_[kRgb]).toSec() < kRecentArrival;
  // Since the inputs last paired, or since they resumed after a pause (before any set: a silent depth or mask
  // topic from the start).
  const double since_sync = (now - std::max(last_sync_, arrivals_resumed_)).toSec();
  if (!rgb_recent || !(since_sync > settings_.sync_timeout)) return;
  // A message dropped as malformed within that time already says why no set forms; it stays the last error.
  if (!last_rejected_.isZero() && (now - last_rejected_).toSec() < settings_.sync_timeout) return;
  std::ostringstream msg;
  msg << "no synchronized input for " << format_fixed(since_sync, 1) << " s (~sync_timeout " << settings_.sync_timeout
      << " s, ~max_interval " << settings_.max_interval << " s); last stamps:";
  for (int i = 0; i < kInputs; ++i) {
    if (!used(i)) continue;
    msg << " " << kInputNames[i] << "=";
    if (last_arrival_[i].isZero()) msg << "never received";
    else msg << format_fixed(last_stamp_[i].toSec());
  }
  msg << " (topics: " << rgb_sub_.getTopic() << ", " << info_sub_.getTopic()
      << (settings_.use_depth ? ", " + depth_sub_.getTopic() : "")
      << (settings_.use_mask ? ", " + mask_sub_.getTopic() : "") << ")";
  errors_.error("sync", msg.str());
}

void InputSync::addDiagnostics(diagnostic_updater::DiagnosticStatusWrapper& stat) {
  // Every message of every input: synchronized, malformed (dropped with its reason before the synchronizer), or
  // never matched by the other inputs (stamps too far apart, a silent topic; up to ~queue_size still waiting).
  std::lock_guard<std::mutex> lock(mutex_);
  for (int i = 0; i < kInputs; ++i) {
    if (!used(i)) continue;
    const Counts& c = counts_[i];
    stat.add(std::string("input ") + kInputNames[i],
             "received " + std::to_string(c.received) + ", synchronized " + std::to_string(c.synchronized) +
                 ", malformed " + std::to_string(c.malformed) + ", unmatched " +
                 std::to_string(std::max(0L, c.received - c.synchronized - c.malformed)));
  }
}

}  // namespace diffdope_ros
