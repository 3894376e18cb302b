// bench_tracking: the refiner node's tracking loop, offline and deterministic, on the demo's scene
// (demo_scene.hpp: the ROS demo bag's objects, camera, motion and noisy DOPE-like detections). Every K-th frame is
// refined, as a node that refines at a fraction of the camera's rate does; a detection stamped at frame k arrives
// `latency` later and seeds the next refined frame, beside the track and its prediction (ObjectTrack), the loss
// deciding. Prints per refined frame and object the error of the start and of the result against the truth, then
// per object the mean and worst rotation and translation errors, the share of frames within 2 degrees, and the
// median time per refined frame.
//
//   bench_tracking [--objects 1|2|3] [--frames N (90)] [--rate HZ (30)] [--every K (2)] [--detector-every K (3)]
//                  [--latency S (0.15)] [--masks given|none] [--depth given|none] [--config FILE] [--seed S (1)]
//                  [--track-budget B,I (TrackOptions': 4,10)] [--quiet]
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <map>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "diffdope/demo_scene.hpp"
#include "diffdope/metrics.hpp"
#include "diffdope/object_track.hpp"
#include "diffdope/refiner.hpp"
#include "diffdope/synthetic.hpp"

using namespace diffdope;
using namespace diffdope::demo;

namespace {

struct Args {
  std::string objects = "1";
  int frames = 90;
  double rate = 30;
  int every = 2;
  int detector_every = 3;
  double latency = 0.15;
  bool masks = true;
  bool depth = true;  // none: colour alone, as a node with use_depth false
  std::string config;
  uint64_t seed = 1;
  int track_batch = TrackOptions().batch_size, track_iterations = TrackOptions().iterations;
  bool quiet = false;
};

[[noreturn]] void usage(const std::string& why) {
  std::cerr << "bench_tracking: " << why << "\n"
            << "usage: bench_tracking [--objects 1|2|3] [--frames N (90)] [--rate HZ (30)] [--every K (2)]\n"
               "                      [--detector-every K (3)] [--latency S (0.15)] [--masks given|none]\n"
               "                      [--depth given|none] [--config FILE] [--seed S (1)] [--track-budget B,I (4,10)]\n"
               "                      [--quiet]\n";
  std::exit(2);
}

Args parse(int argc, char** argv) {
  Args a;
  for (int i = 1; i < argc; ++i) {
    const std::string opt = argv[i];
    if (opt == "--quiet") {
      a.quiet = true;
      continue;
    }
    if (i + 1 >= argc) usage(opt + ": missing value");
    const std::string v = argv[++i];
    try {
      if (opt == "--objects") a.objects = v;
      else if (opt == "--frames") a.frames = std::stoi(v);
      else if (opt == "--rate") a.rate = std::stod(v);
      else if (opt == "--every") a.every = std::stoi(v);
      else if (opt == "--detector-every") a.detector_every = std::stoi(v);
      else if (opt == "--latency") a.latency = std::stod(v);
      else if (opt == "--masks" && (v == "given" || v == "none")) a.masks = v == "given";
      else if (opt == "--depth" && (v == "given" || v == "none")) a.depth = v == "given";
      else if (opt == "--config") a.config = v;
      else if (opt == "--seed") a.seed = std::stoull(v);
      else if (opt == "--track-budget" && v.find(',') != std::string::npos)
        a.track_batch = std::stoi(v.substr(0, v.find(','))), a.track_iterations = std::stoi(v.substr(v.find(',') + 1));
      else usage("unknown option or value: " + opt + " " + v);
    } catch (const std::logic_error&) {
      usage(opt + ": not a number: " + v);
    }
  }
  if (a.frames < 1 || a.every < 1 || a.detector_every < 1 || !(a.rate > 0) || !(a.latency >= 0))
    usage("frames, every, detector-every and rate must be positive, latency not negative");
  return a;
}

double rotation_deg(const Pose& a, const Pose& b) {
  return Eigen::AngleAxisd(a.R.transpose() * b.R).angle() * 180.0 / M_PI;
}

struct Errors {
  std::vector<double> rotation_deg, centre_mm;
};

}  // namespace

int main(int argc, char** argv) {
  const Args args = parse(argc, argv);
  try {
    const std::vector<DemoObject> objects = demo_objects(args.objects);
    const Camera cam = demo_camera(640, 480);
    const DemoLayout layout = choose_layout(objects, cam, args.frames, args.rate, args.seed);
    // The demo's objects file: 16 runs of 40 iterations; a steady track gets TrackOptions' budget.
    RefinerOptions options = args.config.empty() ? RefinerOptions() : RefinerOptions::from_yaml_file(args.config);
    if (args.config.empty()) options.batch_size = 16, options.iterations = 40;
    TrackOptions track_options;
    track_options.batch_size = args.track_batch;
    track_options.iterations = args.track_iterations;
    track_options.validate();
    Refiner refiner(options);
    auto renderer = make_cpu_renderer();
    std::vector<ObjectTrack> tracks;
    for (const DemoObject& o : objects) tracks.emplace_back(track_options, o.mesh.center());
    std::vector<std::vector<Eigen::Vector3d>> points;
    for (const DemoObject& o : objects) points.push_back(metric_points(o.mesh));

    std::mt19937_64 detector_rng(args.seed * 0xD1B54A32D192ED03ull + 7);
    const uint32_t scene_seed = uint32_t(args.seed * 2654435761u + 17);
    const int latency_frames = int(std::ceil(args.latency * args.rate - 1e-9));
    std::multimap<int, std::pair<size_t, Seed>> in_flight;  // arrival frame -> (object, detection)
    std::map<size_t, Errors> errors;
    std::vector<double> frame_ms;
    for (int k = 0; k < args.frames; ++k) {
      const double stamp = double(k) / args.rate;
      std::vector<Pose> truth;
      std::vector<SceneObject> scene_objects;
      for (size_t i = 0; i < objects.size(); ++i) {
        truth.push_back(layout.motions[i].at(stamp, objects[i].mesh.center()));
        scene_objects.push_back({&objects[i].mesh, truth.back()});
      }
      if (k % args.detector_every == 0)
        for (size_t i = 0; i < objects.size(); ++i) {
          const Pose noisy = perturb_pose(truth[i], objects[i].mesh.center(), 5.0 * M_PI / 180.0, 0.01, detector_rng);
          in_flight.emplace(k + latency_frames, std::make_pair(i, Seed{noisy, SeedSource::kDetector, stamp}));
        }
      for (auto it = in_flight.begin(); it != in_flight.end() && it->first <= k;) {
        tracks[it->second.first].add_detection(it->second.second.pose, it->second.second.stamp);
        it = in_flight.erase(it);
      }
      if (k % args.every != 0) continue;

      const SyntheticScene scene = synthesize_scene(*renderer, cam, scene_objects, SyntheticNoise(), scene_seed);
      Observation frame;
      frame.rgb = scene.rgb;
      if (args.depth) frame.depth = scene.depth;
      std::vector<ObjectTarget> targets;
      std::vector<size_t> target_object;
      std::vector<std::vector<Seed>> target_starts;
      std::vector<bool> steady;
      for (size_t i = 0; i < objects.size(); ++i) {
        std::vector<Seed> starts = tracks[i].seeds_for(stamp);
        if (starts.empty()) continue;
        ObjectTarget t;
        t.mesh = &objects[i].mesh;
        t.initial = starts.front().pose;
        for (size_t j = 1; j < starts.size(); ++j) t.alternatives.push_back(starts[j].pose);
        t.start_kind = start_kind(starts);
        if (t.start_kind == StartKind::kTracked) t.carried_curvature = tracks[i].carried_curvature();
        if (args.masks) t.mask = scene.visible_masks[i];
        steady.push_back(t.start_kind == StartKind::kTracked && tracks[i].steady(stamp));
        if (steady.back()) t.budget = tracked_budget(track_options);
        targets.push_back(t);
        target_object.push_back(i);
        target_starts.push_back(starts);
      }
      if (targets.empty()) continue;
      const auto t0 = std::chrono::steady_clock::now();
      const std::vector<RefineResult> results = refiner.refine_all(cam, frame, targets, options);
      frame_ms.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
      for (size_t n = 0; n < results.size(); ++n) {
        const size_t i = target_object[n];
        const Pose reported = tracks[i].reported_pose(results[n].pose, objects[i].mesh.symmetry);
        tracks[i].report(reported, results[n].plausible, stamp);
        tracks[i].note_curvature(results[n].curvature, results[n].curvature_carried, reported);
        const double rot = rotation_deg(reported, truth[i]);
        const Eigen::AngleAxisd err(truth[i].R.transpose() * reported.R);  // in the model's frame
        const double about_z = err.angle() * err.axis().z() * 180.0 / M_PI;
        const double centre = 1e3 * (reported * objects[i].mesh.center() - truth[i] * objects[i].mesh.center()).norm();
        errors[i].rotation_deg.push_back(rot);
        errors[i].centre_mm.push_back(centre);
        if (!args.quiet)
          std::printf("frame %3d %-7s start %-10s %5.2f deg %5.1f mm -> %5.2f deg (%5.2f about z) %5.2f mm  ADD %5.2f mm  print turn %.2f deg, %d Newton steps%s%s\n", k,
                      objects[i].name.c_str(), to_string(target_starts[n].front().source),
                      rotation_deg(targets[n].initial, truth[i]),
                      1e3 * (targets[n].initial * objects[i].mesh.center() - truth[i] * objects[i].mesh.center()).norm(),
                      rot, about_z, centre, 1e3 * add_error(points[i], reported, truth[i]), results[n].print_turn * 180 / M_PI, results[n].newton_steps, results[n].plausible ? "" : "  implausible",
                      steady[n] ? "  (track budget)" : "");
      }
    }
    std::sort(frame_ms.begin(), frame_ms.end());
    std::printf("\n%zu refined frames of %d (every %d at %.0f Hz), masks %s, depth %s; median %.0f ms per frame\n",
                frame_ms.size(), args.frames, args.every, args.rate, args.masks ? "given" : "none",
                args.depth ? "given" : "none",
                frame_ms.empty() ? 0.0 : frame_ms[frame_ms.size() / 2]);
    for (const auto& [i, e] : errors) {
      const auto mean = [](const std::vector<double>& v) {
        double s = 0;
        for (double x : v) s += x;
        return v.empty() ? 0.0 : s / double(v.size());
      };
      const double within = double(std::count_if(e.rotation_deg.begin(), e.rotation_deg.end(), [](double r) { return r <= 2.0; }));
      std::printf("%-7s rotation mean %.2f max %.2f deg, within 2 deg %.0f %%; centre mean %.2f max %.2f mm\n",
                  objects[i].name.c_str(), mean(e.rotation_deg), *std::max_element(e.rotation_deg.begin(), e.rotation_deg.end()),
                  100.0 * within / double(e.rotation_deg.size()), mean(e.centre_mm),
                  *std::max_element(e.centre_mm.begin(), e.centre_mm.end()));
    }
  } catch (const std::exception& e) {
    std::cerr << "bench_tracking: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
