// diffdope_make_bag: writes the demo / test data of the ROS layer: a bag of generated camera frames with noisy
// DOPE-like detections, the objects' meshes and the objects YAML the refiner nodelet reads.
//
//   diffdope_make_bag --out DIR [--frames N] [--rate HZ] [--detector-every K] [--detector-latency S]
//                     [--objects 1|2|3|can|twins] [--seed S] [--width W] [--height H] [--depth-encoding 16UC1|32FC1]
//                     [--rot-noise-deg D] [--trans-noise-m M] [--compression none|lz4|bz2] [--dope TOPIC]
//
// DIR/demo.bag, DIR/meshes/<name>.ply (+ <name>.png texture; metres), DIR/objects.yaml (object_config.hpp);
// with --dope also DIR/config_pose.yaml, the same objects in DOPE's own layout (class ids 1, 2, 3 in order).
// Objects: a scan-like bottle alone (--objects 1), or a low-poly printed box, the bottle and a scan-like mug (labels
// 1, 2, 3 in the mask; scan-like: 15k triangles, UV atlas, 2048^2 print), or a striped can alone (--objects can:
// symmetric about its axis, declared so in objects.yaml, its detections turned at random about it), or two
// instances of the printed box (--objects twins: one label, max_instances 2 in objects.yaml, detected together in
// one InitialPoseArray on /diffdope_refiner/initial_poses), side by side about 0.6 m in
// front of the camera, each turning slowly (~15 deg/s) about its own axis through its centre and drifting (~2 cm/s,
// a smooth back-and-forth of 3 cm amplitude so long bags stay in view). Frames are composed with
// synthesize_scene; the background (and the sensor noise pattern) is the same in every frame, as for a static
// camera. Topics (stamp t_k = 1000 s + k / rate, written at bag time t_k unless noted):
//   /camera/rgb/image_rect_color   sensor_msgs/Image rgb8
//   /camera/rgb/camera_info        sensor_msgs/CameraInfo (plumb_bob, no distortion)
//   /camera/depth/image_rect       sensor_msgs/Image 16UC1 millimetres (0 = no reading) or 32FC1 metres (NaN)
//   /camera/mask                   sensor_msgs/Image mono8: the visible object's mask_label, 0 = background
//   /ground_truth                  diffdope_ros/InitialPoseArray: true mesh poses in camera_color_optical_frame
//   /dope/pose_<name>              geometry_msgs/PoseStamped in camera_link, every K-th frame, stamped t_k and
//                                  written at t_k + detector latency (perturbed by the paper's rule)
//   /diffdope_refiner/initial_poses  (twins) diffdope_ros/InitialPoseArray: both boxes' detections, as above
//   TOPIC (--dope)                 vision_msgs/Detection3DArray as DOPE publishes it: the same detections, one
//                                  Detection3D each with its class id and a score, in camera_link
//   /tf_static                     tf2_msgs/TFMessage camera_link -> camera_color_optical_frame (latched)
#include <cv_bridge/cv_bridge.h>
#include <diffdope_ros/InitialPoseArray.h>
#include <geometry_msgs/PoseStamped.h>
#include <rosbag/bag.h>
#include <rosbag/exceptions.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/image_encodings.h>
#include <tf2_msgs/TFMessage.h>
#include <topic_tools/shape_shifter.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <deque>
#include <filesystem>
#include <functional>
#include <fstream>
#include <iostream>
#include <limits>
#include <opencv2/core.hpp>
#include <random>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "diffdope_ros/conversions.hpp"
#include "diffdope_ros/detection3d_array.hpp"
#include "diffdope/input_files.hpp"
#include "diffdope/object_config.hpp"
#include "diffdope/procedural.hpp"
#include "diffdope/synthetic.hpp"
#include "diffdope/demo_scene.hpp"

using namespace diffdope;
using namespace diffdope::demo;
namespace fs = std::filesystem;

namespace {

const char* const kOpticalFrame = "camera_color_optical_frame";
const char* const kLinkFrame = "camera_link";

struct Args {
  std::string out;
  int frames = 40;
  double rate = 10.0;
  int detector_every = 3;
  double detector_latency = 0.15;
  int detector_frames = -1;  // detections only on frames k < detector_frames (-1: all): then the detector is silent
  int objects = 3;
  bool can = false;  // --objects can: one striped can, declared symmetric about its axis
  bool twins = false;  // --objects twins: two instances of the box
  uint64_t seed = 1;
  int width = 640, height = 480;
  std::string depth_encoding = "16UC1";
  double rot_noise_deg = 5.0;
  double trans_noise_m = 0.01;
  std::string compression = "lz4";
  std::string dope_topic;  // --dope: also DOPE's Detection3DArray on this topic, and DIR/config_pose.yaml
};

void usage(std::ostream& os) {
  os << "usage: diffdope_make_bag --out DIR [--frames N (40)] [--rate HZ (10)] [--detector-every K (3)]\n"
        "         [--detector-latency S (0.15)] [--objects 1|2|3|can|twins (3)] [--seed S (1)] [--width W (640)]\n"
        "         [--height H (480)] [--depth-encoding 16UC1|32FC1 (16UC1)] [--rot-noise-deg D (5)]\n"
        "         [--trans-noise-m M (0.01)] [--compression none|lz4|bz2 (lz4)]\n"
        "         [--detector-frames N (all): the detector goes silent from frame N on (tracking)]\n"
        "         [--dope TOPIC: also DOPE's Detection3DArray on TOPIC, and DIR/config_pose.yaml]\n"
        "Writes DIR/demo.bag, DIR/meshes/<name>.ply and DIR/objects.yaml (see the header of make_demo_bag.cpp).\n";
}

struct UsageError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

long long parse_int(const std::string& opt, const std::string& v, long long lo, long long hi) {
  try {
    return diffdope::parse_integer_arg(opt, v, lo, hi);
  } catch (const std::invalid_argument& e) {
    throw UsageError(e.what());
  }
}

double parse_double(const std::string& opt, const std::string& v, double lo, double hi, bool lo_inclusive) {
  double x = 0;
  try {
    x = diffdope::parse_number_arg(opt, v);
  } catch (const std::invalid_argument& e) {
    throw UsageError(e.what());
  }
  if ((lo_inclusive ? x < lo : x <= lo) || x > hi) {
    std::ostringstream s;
    s << opt << ": " << v << " is out of range " << (lo_inclusive ? "[" : "(") << lo << ", " << hi << "]";
    throw UsageError(s.str());
  }
  return x;
}

Args parse_args(int argc, char** argv) {
  Args a;
  for (int i = 1; i < argc; ++i) {
    const std::string opt = argv[i];
    if (opt == "-h" || opt == "--help") {
      usage(std::cout);
      std::exit(0);
    }
    if (opt.rfind("--", 0) != 0) throw UsageError("unexpected argument '" + opt + "'");
    if (i + 1 >= argc) throw UsageError(opt + ": missing value");
    const std::string v = argv[++i];
    if (opt == "--out") a.out = v;
    else if (opt == "--dope") a.dope_topic = v;
    else if (opt == "--frames") a.frames = int(parse_int(opt, v, 1, 100000));
    else if (opt == "--rate") a.rate = parse_double(opt, v, 0.0, 1000.0, false);
    else if (opt == "--detector-every") a.detector_every = int(parse_int(opt, v, 1, 100000));
    else if (opt == "--detector-frames") a.detector_frames = int(parse_int(opt, v, 0, 100000));
    else if (opt == "--detector-latency") a.detector_latency = parse_double(opt, v, 0.0, 60.0, true);
    else if (opt == "--objects" && v == "can") a.objects = 1, a.can = true;
    else if (opt == "--objects" && v == "twins") a.objects = 2, a.twins = true;
    else if (opt == "--objects") a.objects = int(parse_int(opt, v, 1, 3));
    else if (opt == "--seed") a.seed = uint64_t(parse_int(opt, v, 0, std::numeric_limits<long long>::max()));
    else if (opt == "--width") a.width = int(parse_int(opt, v, 32, 8192));
    else if (opt == "--height") a.height = int(parse_int(opt, v, 32, 8192));
    else if (opt == "--depth-encoding") {
      if (v != "16UC1" && v != "32FC1") throw UsageError(opt + ": expected 16UC1 or 32FC1, got '" + v + "'");
      a.depth_encoding = v;
    } else if (opt == "--rot-noise-deg") a.rot_noise_deg = parse_double(opt, v, 0.0, 180.0, true);
    else if (opt == "--trans-noise-m") a.trans_noise_m = parse_double(opt, v, 0.0, 1.0, true);
    else if (opt == "--compression") {
      if (v != "none" && v != "lz4" && v != "bz2") throw UsageError(opt + ": expected none, lz4 or bz2, got '" + v + "'");
      a.compression = v;
    } else throw UsageError("unknown option '" + opt + "'");
  }
  if (a.out.empty()) throw UsageError("--out DIR is required");
  return a;
}

// ---- Messages ----

std_msgs::Header header(const ros::Time& stamp, const std::string& frame, uint32_t seq) {
  std_msgs::Header h;
  h.stamp = stamp;
  h.frame_id = frame;
  h.seq = seq;
  return h;
}


sensor_msgs::ImagePtr image_msg(const std_msgs::Header& h, const std::string& encoding, const cv::Mat& m) {
  return cv_bridge::CvImage(h, encoding, m).toImageMsg();
}

/// Pose of camera_color_optical_frame in camera_link (REP 103/105: optical z forward = body x forward).
Pose link_from_optical() { return Pose::from_quaternion(-0.5, 0.5, -0.5, 0.5, Eigen::Vector3d::Zero()); }

template <class M>
boost::shared_ptr<ros::M_string> latched_connection_header(const std::string& topic) {
  auto h = boost::make_shared<ros::M_string>();
  (*h)["callerid"] = "/diffdope_make_bag";
  (*h)["topic"] = topic;
  (*h)["type"] = ros::message_traits::datatype<M>();
  (*h)["md5sum"] = ros::message_traits::md5sum<M>();
  (*h)["message_definition"] = ros::message_traits::definition<M>();
  (*h)["latching"] = "1";
  return h;
}

std::string yaml_quote(const std::string& s) { return "'" + s + "'"; }

}  // namespace

int main(int argc, char** argv) {
  Args args;
  try {
    args = parse_args(argc, argv);
  } catch (const UsageError& e) {
    std::cerr << "diffdope_make_bag: " << e.what() << "\n";
    usage(std::cerr);
    return 2;
  }

  try {
    // Sanity of the fixed optical -> link rotation: optical z (forward) is camera_link x, optical x (right) is -y.
    {
      const Pose T = link_from_optical();
      if (!(T.R * Eigen::Vector3d::UnitZ()).isApprox(Eigen::Vector3d::UnitX(), 1e-12) ||
          !(T.R * Eigen::Vector3d::UnitX()).isApprox(-Eigen::Vector3d::UnitY(), 1e-12))
        throw std::logic_error("camera_link <- optical rotation is wrong");
    }

    const fs::path out_dir = fs::absolute(args.out);
    std::error_code ec;
    fs::create_directories(out_dir / "meshes", ec);
    if (ec) throw std::runtime_error((out_dir / "meshes").string() + ": cannot create: " + ec.message());

    // Objects (demo_scene.hpp): the bottle; or the box, the bottle and the mug; or the can; or the twin boxes.
    const std::vector<DemoObject> objects =
        demo_objects(args.can ? "can" : args.twins ? "twins" : std::to_string(args.objects));
    const size_t n = objects.size();

    std::ostringstream yaml;
    yaml << "# Written by diffdope_make_bag: the objects of demo.bag (meshes in metres, next to this file).\n"
         << "refiner:\n  iterations: 40\n  batch_size: 16\nobjects:\n";
    std::vector<size_t> config_index;  // per scene object, its entry in objects.yaml (twins share one)
    for (size_t i = 0; i < objects.size(); ++i) {
      const DemoObject& o = objects[i];
      if (i > 0 && o.name == objects[i - 1].name) {
        config_index.push_back(config_index.back());
        continue;
      }
      config_index.push_back(i == 0 ? 0 : config_index.back() + 1);
      save_ply(o.mesh, (out_dir / "meshes" / (o.name + ".ply")).string(), 1.0);
      yaml << "  - name: " << o.name << "\n    mesh: " << yaml_quote("meshes/" + o.name + ".ply")
           << "\n    mesh_scale: 1\n    symmetric: " << (o.symmetric ? "true" : "false")
           << "\n    mask_label: " << o.label << "\n";
      if (args.twins) yaml << "    max_instances: 2\n";
      if (!o.declared.continuous.empty()) {
        yaml << "    symmetries: {continuous: [";
        for (size_t k = 0; k < o.declared.continuous.size(); ++k) {
          const ObjectSymmetry::Axis& a = o.declared.continuous[k];
          yaml << (k ? ", " : "") << "{axis: [" << a.direction.x() << ", " << a.direction.y() << ", "
               << a.direction.z() << "], offset: [" << a.offset.x() << ", " << a.offset.y() << ", " << a.offset.z()
               << "]}";
        }
        yaml << "]}\n";
      }
    }
    const std::string yaml_path = (out_dir / "objects.yaml").string();
    {
      std::ofstream f(yaml_path);
      f << yaml.str();
      if (!f) throw std::runtime_error(yaml_path + ": cannot write");
    }
    // Read back what the nodelet will read: the config and the meshes, at the same size.
    const ObjectsConfig cfg = load_objects_config(yaml_path);
    for (size_t i = 0; i < n; ++i) {
      const Mesh back = load_object_mesh(cfg.objects.at(config_index[i]));
      if (std::abs(back.diameter() - objects[i].mesh.diameter()) > 1e-4)
        throw std::runtime_error(cfg.objects.at(config_index[i]).mesh_path + ": mesh reads back at a different size");
    }

    if (!args.dope_topic.empty()) {  // DOPE's layout: its own keys too, which the refiner leaves to DOPE
      std::ostringstream dope;
      dope << "# Written by diffdope_make_bag --dope: the objects of demo.bag in DOPE's config_pose.yaml layout.\n"
           << "topic_camera: \"/camera/color/image_raw\"\ntopic_camera_info: \"/camera/color/camera_info\"\n"
           << "topic_publishing: \"dope\"\ninput_is_rectified: True\ndownscale_height: 400\n";
      const auto map = [&](const char* key, const std::function<std::string(const ObjectConfig&, size_t)>& value) {
        dope << key << ": {";
        for (size_t k = 0; k < cfg.objects.size(); ++k)
          dope << (k ? ", " : "") << cfg.objects[k].name << ": " << value(cfg.objects[k], k);
        dope << "}\n";
      };
      map("weights", [](const ObjectConfig& o, size_t) { return "\"package://dope/weights/" + o.name + ".pth\""; });
      map("model_transforms", [](const ObjectConfig&, size_t) { return "[[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]"; });
      map("meshes", [](const ObjectConfig& o, size_t) { return "\"file://" + o.mesh_path + "\""; });
      map("mesh_scales", [](const ObjectConfig&, size_t) { return std::string("1.0"); });
      map("dimensions", [](const ObjectConfig& o, size_t) {  // the cuboid DOPE fits, in centimetres
        const Mesh m = load_object_mesh(o);
        const Eigen::Vector3d cm = 100.0 * (m.bbox_max() - m.bbox_min());
        std::ostringstream s;
        s << "[" << cm.x() << ", " << cm.y() << ", " << cm.z() << "]";
        return s.str();
      });
      map("class_ids", [](const ObjectConfig&, size_t k) { return std::to_string(k + 1); });
      dope << "thresh_angle: 0.5\nthresh_map: 0.01\nsigma: 3\nthresh_points: 0.1\n";
      const std::string dope_path = (out_dir / "config_pose.yaml").string();
      std::ofstream f(dope_path);
      f << dope.str();
      if (!f) throw std::runtime_error(dope_path + ": cannot write");
      f.close();
      if (load_objects_config(dope_path).objects.size() != cfg.objects.size())
        throw std::logic_error(dope_path + ": reads back with another number of objects");
    }

    // Camera and scene layout.
    const Camera cam = demo_camera(args.width, args.height);
    auto renderer = make_cpu_renderer();
    const DemoLayout layout = choose_layout(objects, cam, args.frames, args.rate, args.seed);
    const std::vector<Motion>& motions = layout.motions;
    if (!layout.inside || layout.min_visible < 0.7)
      std::fprintf(stderr, "diffdope_make_bag: warning: no layout kept every object in view and >= 70 %% visible "
                           "(best: %s, min visible %.2f); using it anyway\n",
                   layout.inside ? "in view" : "an object leaves the image", layout.min_visible);

    // The bag.
    const std::string bag_path = (out_dir / "demo.bag").string();
    rosbag::Bag bag;
    bag.open(bag_path, rosbag::bagmode::Write);
    if (args.compression == "lz4") bag.setCompression(rosbag::compression::LZ4);
    else if (args.compression == "bz2") bag.setCompression(rosbag::compression::BZ2);

    const ros::Time t0(1000.0);
    auto stamp_of = [&](int k) { return t0 + ros::Duration(double(k) / args.rate); };

    // Static transform, latched, at the first stamp.
    tf2_msgs::TFMessage tf;
    {
      geometry_msgs::TransformStamped ts;
      ts.header = header(t0, kLinkFrame, 0);
      ts.child_frame_id = kOpticalFrame;
      const auto q = link_from_optical().quaternion_xyzw();
      ts.transform.rotation.x = q[0];
      ts.transform.rotation.y = q[1];
      ts.transform.rotation.z = q[2];
      ts.transform.rotation.w = q[3];
      tf.transforms.push_back(ts);
    }
    bag.write("/tf_static", t0, tf, latched_connection_header<tf2_msgs::TFMessage>("/tf_static"));

    struct Pending {
      ros::Time write_time;
      std::string topic;
      geometry_msgs::PoseStamped msg;
    };
    std::deque<Pending> pending;  // detections waiting for their arrival time (constant latency: FIFO)
    std::deque<std::pair<ros::Time, diffdope_ros::InitialPoseArray>> pending_arrays;  // (twins)
    std::deque<std::pair<ros::Time, diffdope_ros::DecodedDetectionArray>> pending_dope;  // (--dope)
    auto flush = [&](const ros::Time* until) {
      while (!pending.empty() && (!until || pending.front().write_time <= *until)) {
        bag.write(pending.front().topic, pending.front().write_time, pending.front().msg);
        pending.pop_front();
      }
      while (!pending_arrays.empty() && (!until || pending_arrays.front().first <= *until)) {
        bag.write("/diffdope_refiner/initial_poses", pending_arrays.front().first, pending_arrays.front().second);
        pending_arrays.pop_front();
      }
      while (!pending_dope.empty() && (!until || pending_dope.front().first <= *until)) {
        std::vector<uint8_t> bytes = diffdope_ros::encode_detection3d_array(pending_dope.front().second);
        topic_tools::ShapeShifter m;
        m.morph(diffdope_ros::kDetection3DArrayMd5, diffdope_ros::kDetection3DArrayType, "", "");
        ros::serialization::IStream in(bytes.data(), uint32_t(bytes.size()));
        m.read(in);
        bag.write(args.dope_topic, pending_dope.front().first, m);
        pending_dope.pop_front();
      }
    };

    std::mt19937_64 detector_rng(args.seed * 0xD1B54A32D192ED03ull + 7);
    const uint32_t scene_seed = uint32_t(args.seed * 2654435761u + 17);  // one background for the whole bag
    const Pose T_link_optical = link_from_optical();
    const bool depth16 = args.depth_encoding == "16UC1";
    int detections = 0;
    double min_visible = 1.0;
    for (int k = 0; k < args.frames; ++k) {
      const ros::Time t = stamp_of(k);
      flush(&t);
      const double tau = double(k) / args.rate;
      std::vector<SceneObject> objs;
      std::vector<Pose> poses;
      for (size_t i = 0; i < n; ++i) {
        poses.push_back(motions[i].at(tau, objects[i].mesh.center()));
        objs.push_back({&objects[i].mesh, poses.back()});
      }
      const SyntheticScene scene = synthesize_scene(*renderer, cam, objs, SyntheticNoise(), scene_seed);
      for (double v : scene.visible_fraction) min_visible = std::min(min_visible, v);

      const std_msgs::Header h = header(t, kOpticalFrame, uint32_t(k));
      cv::Mat rgb8;
      scene.rgb.convertTo(rgb8, CV_8UC3, 255.0);
      bag.write("/camera/rgb/image_rect_color", t, image_msg(h, sensor_msgs::image_encodings::RGB8, rgb8));
      bag.write("/camera/rgb/camera_info", t, diffdope_ros::camera_info_from_camera(cam, h));
      cv::Mat depth;
      if (depth16) {
        scene.depth.convertTo(depth, CV_16U, 1000.0);  // millimetres, rounded; 0 stays "no reading"
        bag.write("/camera/depth/image_rect", t, image_msg(h, sensor_msgs::image_encodings::TYPE_16UC1, depth));
      } else {
        depth = scene.depth.clone();
        depth.setTo(std::numeric_limits<float>::quiet_NaN(), scene.depth <= 0.f);  // REP 118: NaN = no reading
        bag.write("/camera/depth/image_rect", t, image_msg(h, sensor_msgs::image_encodings::TYPE_32FC1, depth));
      }
      cv::Mat labels = cv::Mat::zeros(cam.height, cam.width, CV_8U);
      for (size_t i = 0; i < n; ++i) labels.setTo(objects[i].label, scene.visible_masks[i] >= 0.5f);
      bag.write("/camera/mask", t, image_msg(h, sensor_msgs::image_encodings::MONO8, labels));

      diffdope_ros::InitialPoseArray gt;
      gt.header = h;
      for (size_t i = 0; i < n; ++i) {
        diffdope_ros::InitialPose p;
        p.name = objects[i].name;
        p.pose.header = h;
        p.pose.pose = diffdope_ros::pose_to_msg(poses[i]);
        gt.poses.push_back(p);
      }
      bag.write("/ground_truth", t, gt);

      if (k % args.detector_every == 0 && (args.detector_frames < 0 || k < args.detector_frames)) {
        for (size_t i = 0; i < n; ++i) {
          Pose noisy = perturb_pose(poses[i], objects[i].mesh.center(), args.rot_noise_deg * M_PI / 180.0,
                                    args.trans_noise_m, detector_rng);
          // A detector cannot tell a symmetric object's turn about its axis: it reports any (as DOPE does).
          for (const ObjectSymmetry::Axis& a : objects[i].declared.continuous) {
            const double turn = std::uniform_real_distribution<double>(0.0, 2 * M_PI)(detector_rng);
            const Eigen::Matrix3d Rt = Eigen::AngleAxisd(turn, a.direction).toRotationMatrix();
            noisy = noisy * Pose(Rt, a.offset - Rt * a.offset);
          }
          Pending d;
          d.write_time = t + ros::Duration(args.detector_latency);
          d.topic = "/dope/pose_" + objects[i].name;
          d.msg.header = header(t, kLinkFrame, uint32_t(k / args.detector_every));
          d.msg.pose = diffdope_ros::pose_to_msg(T_link_optical * noisy);
          ++detections;
          if (!args.dope_topic.empty()) {  // the same detection in DOPE's array, with its class id
            if (pending_dope.empty() || pending_dope.back().first != d.write_time) {
              diffdope_ros::DecodedDetectionArray a;
              a.frame_id = kLinkFrame;
              a.stamp_sec = t.sec, a.stamp_nsec = t.nsec;
              pending_dope.emplace_back(d.write_time, a);
            }
            diffdope_ros::DecodedDetection det;
            det.frame_id = kLinkFrame;
            det.stamp_sec = t.sec, det.stamp_nsec = t.nsec;
            diffdope_ros::DecodedHypothesis h;
            h.class_id = int64_t(config_index[i]) + 1;
            h.score = 0.9;
            h.pose = T_link_optical * noisy;
            det.results.push_back(h);
            pending_dope.back().second.detections.push_back(det);
          }
          if (!args.twins) {
            pending.push_back(d);
            continue;
          }
          // Both instances in one message, in a random order (the node must not rely on it).
          if (pending_arrays.empty() || pending_arrays.back().first != d.write_time) {
            diffdope_ros::InitialPoseArray a;
            a.header = d.msg.header;
            pending_arrays.emplace_back(d.write_time, a);
          }
          diffdope_ros::InitialPose p;
          p.name = objects[i].name;
          p.pose = d.msg;
          auto& list = pending_arrays.back().second.poses;
          list.insert(std::uniform_int_distribution<int>(0, 1)(detector_rng) ? list.end() : list.begin(), p);
        }
      }
    }
    flush(nullptr);
    bag.close();

    const auto size = fs::file_size(bag_path);
    std::fprintf(stderr,
                 "diffdope_make_bag: %s: %d frames at %g Hz, %zu objects, %d detections, %s depth, min visible "
                 "%.2f, %.1f MB\n",
                 bag_path.c_str(), args.frames, args.rate, n, detections, args.depth_encoding.c_str(), min_visible,
                 double(size) / (1024.0 * 1024.0));
  } catch (const rosbag::BagException& e) {
    std::cerr << "diffdope_make_bag: bag: " << e.what() << "\n";
    return 1;
  } catch (const std::exception& e) {
    std::cerr << "diffdope_make_bag: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
