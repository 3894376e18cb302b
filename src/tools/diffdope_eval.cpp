// diffdope_eval: the paper's evaluation protocol on a BOP-format dataset.
//   diffdope_eval --bop ROOT --split NAME --perturbations DIR --out results.jsonl [--levels easy,medium,hard]
//                 [--config FILE] [--summary-json FILE] [--threads N] [--max-samples N] [--generate N [--seed S]]
//                 [--masks given|none|box|coarse[:SEED]] [--depth given|none] [--method refiner|icp]
// --generate N first writes perturbation files into DIR with the paper's rule (random axis, rotate by exactly
// the angle; random direction, translate by exactly the distance): easy (1 deg, 1 mm), medium (10 deg, 10 mm),
// hard (40 deg, 20 mm), N samples per level for every ground-truth instance of image 0 of each scene.
// Refines every perturbed initial pose, scores ADD (ADD-S for symmetric objects), writes one JSON line per
// refined instance and prints a table per level: AUC of ADD(-S) up to 50 mm for initial and refined poses,
// % under 10 mm and 5 mm, median ms per object; then the same per object and level (a rule that helps one
// object and hurts another shows there), and how often the verdict's `plausible` agrees with the error.
#include <algorithm>
#include <array>
#include <climits>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <limits>
#include <map>
#include <optional>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>

#include "diffdope/bop.hpp"
#include "diffdope/coarse_mask.hpp"
#include "diffdope/input_files.hpp"
#include "diffdope/metrics.hpp"
#include "diffdope/object_track.hpp"
#include "diffdope/refiner.hpp"
#include "diffdope/synthetic.hpp"
#include "icp_baseline.hpp"
#include <opencv2/imgproc.hpp>
#include <random>

using namespace diffdope;
namespace fs = std::filesystem;

namespace {

int usage(int rc) {
  std::cerr << "usage: diffdope_eval --bop ROOT --split NAME --perturbations DIR --out results.jsonl\n"
               "                     [--levels easy,medium,hard,tracking] [--config FILE] [--summary-json FILE]\n"
               "                     [--threads N] [--max-samples N] [--generate N [--seed S]] [--device auto|cpu|cuda]\n"
               "                     [--symmetric ID,ID,...|none]  (instead of ROOT/models/models_info.json)\n"
               "                     [--masks given|none|box|coarse[:SEED]]  given: the visible masks (default); none: no\n"
               "                     mask, as beside DOPE; box: only the visible mask's bounding rectangle, as a 2D\n"
               "                     detector's; coarse: a segmenter's version of it (grown or shrunk, its outline\n"
               "                     wandering, blobs; include/diffdope/coarse_mask.hpp)\n"
               "                     [--depth given|none]  none: the depth image is dropped (colour alone, as a\n"
               "                     node with use_depth false)\n"
               "                     [--method refiner|icp]  icp: the baseline, point-to-plane ICP on the depth near\n"
               "                     the start (the mask's, or the object's pixels derived there), no verdict\n"
               "                     [--track-budget B,I]  the tracking level's starts refined as the node refines a\n"
               "                     steady track's (B runs of I iterations, tracked_options(); 0: the refiner's)\n"
               "Exit status: 0 all samples evaluated, 1 an error or some samples skipped, 2 bad arguments.\n";
  return rc;
}

struct LevelStats {
  std::vector<double> init, refined, ms;
};

/// How often the verdict agrees with the error: results over 10 mm should be rejected, those under 5 mm not.
struct VerdictTally {
  int far = 0, rejected_far = 0, near = 0, rejected_near = 0;
  void add(double error, bool plausible) {
    if (error > 0.01) ++far, rejected_far += !plausible;
    if (error < 0.005) ++near, rejected_near += !plausible;
  }
};

double percent_below(const std::vector<double>& e, double thr) {
  if (e.empty()) return 0;
  return 100.0 * std::count_if(e.begin(), e.end(), [&](double v) { return v < thr; }) / e.size();
}

double median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

/// Returns the scenes it skipped (each reported): their images or camera cannot be used.
int write_perturbations(BopDataset& data, const std::string& dir, int samples, uint64_t seed) {
  int skipped = 0;
  std::mt19937_64 rng(seed);
  const struct {
    const char* file;
    double deg, mm;
  } levels[] = {{"scene_error_deg_001_trans_001.json", 1, 1},
                {"scene_error_deg_010_trans_010.json", 10, 10},
                {"scene_error_deg_040_trans_020.json", 40, 20}};
  for (int scene : data.scene_ids()) {
    char sname[16];
    std::snprintf(sname, sizeof sname, "%06d", scene);
    BopImage img;
    try {
      img = data.image(scene, 0);
    } catch (const std::exception& e) {
      std::cerr << "diffdope_eval: " << e.what() << "; scene " << scene << " skipped\n";
      ++skipped;
      continue;
    }
    fs::create_directories(fs::path(dir) / sname);
    for (const auto& l : levels) {
      nlohmann::json j = nlohmann::json::object();
      for (int s = 0; s < samples; ++s) {
        nlohmann::json list = nlohmann::json::array();
        for (const BopInstance& g : img.gt) {
          if (!data.has_model(g.obj_id)) continue;
          const Pose p = perturb_pose(g.pose, data.model(g.obj_id).center(), l.deg * M_PI / 180, l.mm * 1e-3, rng);
          const auto r = p.rotation_rowmajor();
          list.push_back({{"obj_id", g.obj_id},
                          {"cam_R_m2c", std::vector<double>(r.begin(), r.end())},
                          {"cam_t_m2c", {1e3 * p.t.x(), 1e3 * p.t.y(), 1e3 * p.t.z()}}});
        }
        j[std::to_string(s)] = list;
      }
      const std::string path = (fs::path(dir) / sname / l.file).string();
      std::ofstream f(path);
      if (!f) throw std::runtime_error(path + ": cannot write");
      f << j.dump(1) << "\n";
    }
  }
  return skipped;
}

/// --masks: what of the visible mask the refiner is given. "box": its bounding rectangle, as a 2D detector gives
/// it (an error when the scene has no mask to take it from); "coarse": a segmenter's version of it
/// (coarse_mask.hpp), the same for every start of the object in the image (`coarse_seed`); "none": nothing.
/// Returns the IoU of the mask given with the visible one (-1: none given or no visible mask).
double apply_mask_mode(Observation& obs, const std::string& mode, uint64_t coarse_seed) {
  if (mode == "given") return obs.has_mask() ? 1.0 : -1.0;
  if ((mode == "box" || mode == "coarse") && !obs.has_mask())
    throw std::runtime_error("--masks " + mode + ": the scene has no visible mask to take it from");
  if (mode == "coarse") {
    const cv::Mat exact = obs.mask >= 0.5f;
    obs.mask = coarse_mask(exact, coarse_seed);
    const cv::Mat given = obs.mask >= 0.5f;
    const double uni = cv::countNonZero(exact | given);
    return uni > 0 ? cv::countNonZero(exact & given) / uni : -1.0;
  }
  if (mode == "box") obs.box = cv::boundingRect(cv::Mat(obs.mask >= 0.5f));
  obs.mask = cv::Mat();
  return -1.0;
}

}  // namespace

int main(int argc, char** argv) {
  std::string root, split, pert_dir, out_path, config, summary_path, device, symmetric_arg, masks = "given",
                                                                                  method = "refiner", depth = "given";
  std::set<std::string> levels;
  int threads = 0, max_samples = -1, generate = 0;
  uint64_t seed = 1, coarse_seed = 1;
  std::optional<TrackOptions> track_budget;
  try {
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "-h" || a == "--help") return usage(0);
    if (i + 1 >= argc) {
      std::cerr << "diffdope_eval: " << a << " needs a value\n";
      return usage(2);
    }
    const std::string v = argv[++i];
    if (a == "--bop") root = v;
    else if (a == "--split") split = v;
    else if (a == "--perturbations") pert_dir = v;
    else if (a == "--out") out_path = v;
    else if (a == "--config") config = v;
    else if (a == "--summary-json") summary_path = v;
    else if (a == "--threads") threads = int(parse_integer_arg(a, v, 0, RenderOptions::kMaxThreads));
    else if (a == "--device") device = v;
    else if (a == "--max-samples") max_samples = int(parse_integer_arg(a, v, 0, 1000000));
    else if (a == "--generate") generate = int(parse_integer_arg(a, v, 0, 100000));
    else if (a == "--seed") seed = uint64_t(parse_integer_arg(a, v, 0, std::numeric_limits<long long>::max()));
    else if (a == "--symmetric") symmetric_arg = v;
    else if (a == "--masks") {
      masks = v.substr(0, v.find(':'));
      if (masks != "given" && masks != "none" && masks != "box" && masks != "coarse")
        throw std::invalid_argument("--masks: unknown mode '" + v + "' (given, none, box, coarse[:SEED])");
      if (v.find(':') != std::string::npos) {
        if (masks != "coarse") throw std::invalid_argument("--masks: only coarse takes a seed, got '" + v + "'");
        coarse_seed = uint64_t(parse_integer_arg("--masks coarse:SEED", v.substr(v.find(':') + 1), 0,
                                                 std::numeric_limits<long long>::max()));
      }
    }
    else if (a == "--depth") {
      if (v != "given" && v != "none") throw std::invalid_argument("--depth: unknown mode '" + v + "' (given, none)");
      depth = v;
    } else if (a == "--method") {
      if (v != "refiner" && v != "icp") throw std::invalid_argument("--method: unknown method '" + v + "' (refiner, icp)");
      method = v;
    } else if (a == "--track-budget") {
      const size_t comma = v.find(',');
      if (comma == std::string::npos) throw std::invalid_argument("--track-budget: expected B,I (e.g. 4,10)");
      track_budget.emplace();
      track_budget->batch_size = int(parse_integer_arg(a + " B", v.substr(0, comma), 0, RefinerOptions::kMaxBatchSize));
      track_budget->iterations =
          int(parse_integer_arg(a + " I", v.substr(comma + 1), 0, RefinerOptions::kMaxIterations));
    } else if (a == "--levels") {
      std::stringstream ss(v);
      for (std::string l; std::getline(ss, l, ',');) {
        if (l != "easy" && l != "medium" && l != "hard" && l != "tracking")
          throw std::invalid_argument("--levels: unknown level '" + l + "' (easy, medium, hard, tracking)");
        levels.insert(l);
      }
    } else {
      std::cerr << "diffdope_eval: unknown option " << a << "\n";
      return usage(2);
    }
  }
  } catch (const std::invalid_argument& e) {
    std::cerr << "diffdope_eval: " << e.what() << "\n";
    return 2;
  }
  if (root.empty() || split.empty() || pert_dir.empty() || out_path.empty()) return usage(2);
  if (method == "icp" && depth == "none") {
    std::cerr << "diffdope_eval: --method icp needs depth (--depth none given)\n";
    return 2;
  }

  try {
    RefinerOptions options = config.empty() ? RefinerOptions() : RefinerOptions::from_yaml_file(config);
    if (threads > 0) options.render.threads = threads;
    if (!device.empty()) options.device = device;
    options.validate();
    Refiner refiner(options);
    std::cerr << "diffdope_eval: " << (method == "icp" ? "point-to-plane ICP (the baseline)" : "backend " + refiner.backend())
              << ", masks " << masks << ", depth " << depth << "\n";
    const std::unique_ptr<Renderer> icp_renderer = method == "icp" ? make_cpu_renderer(options.render) : nullptr;
    std::set<int> symmetric_ids;  // --symmetric: instead of models_info.json
    if (!symmetric_arg.empty() && symmetric_arg != "none") {
      std::stringstream ss(symmetric_arg);
      for (std::string id; std::getline(ss, id, ',');) symmetric_ids.insert(int(parse_integer_arg("--symmetric", id, 0, INT_MAX)));
    }
    BopDataset data(root, split, symmetric_arg.empty() ? nullptr : &symmetric_ids);
    if (!fs::is_directory(pert_dir) && generate == 0) throw std::runtime_error(pert_dir + ": not a directory");
    int skipped = 0, skipped_scenes = 0, skipped_files = 0, perturbation_files = 0;
    if (generate > 0) skipped_scenes += write_perturbations(data, pert_dir, generate, seed);
    std::ofstream out(out_path);
    if (!out) throw std::runtime_error(out_path + ": cannot write");

    std::vector<double> given_ious;  // --masks coarse: per result, the mask given against the visible one
    int masks_checked = 0, masks_replaced = 0;  // given masks checked against depth, and replaced by its pixels
    // The covariance against the true error, over plausible results of objects without symmetry.
    int cov_checked = 0, cov_inside = 0, cov_two_sigma = 0;
    // Per object, of the given masks checked: their shift onto depth's edge (camera px), offset before and after.
    std::map<int, std::vector<std::array<double, 4>>> mask_shifts;
    // Where the evaluations went: per stage, the sum and the most one refinement made (retried results, which
    // hold two refinements' counts, are left out of the most).
    std::array<double, kRefineStages> stage_sum{};
    std::array<long, kRefineStages> stage_most{};
    long stage_results = 0;
    std::map<std::string, LevelStats> stats;
    std::map<int, std::map<std::string, LevelStats>> object_stats;  // by obj_id, then level
    VerdictTally verdicts;
    std::vector<std::string> level_order;
    for (int scene : data.scene_ids()) {
      char sname[16];
      std::snprintf(sname, sizeof sname, "%06d", scene);
      const fs::path pdir = fs::path(pert_dir) / sname;
      if (!fs::is_directory(pdir)) continue;
      std::vector<fs::path> files;
      for (const auto& e : fs::directory_iterator(pdir))
        if (e.path().extension() == ".json") files.push_back(e.path());
      std::sort(files.begin(), files.end());
      // A scene or a file that cannot be used is reported and skipped; the rest are still scored.
      BopImage img;
      try {
        img = data.image(scene, 0);
      } catch (const std::exception& e) {
        std::cerr << "\ndiffdope_eval: " << e.what() << "; scene " << scene << " skipped\n";
        ++skipped_scenes;
        continue;
      }
      for (const fs::path& file : files) {
        const std::string level = perturbation_level(file.string());
        if (!levels.empty() && !levels.count(level)) continue;
        ++perturbation_files;
        if (!stats.count(level)) level_order.push_back(level);
        LevelStats& st = stats[level];
        std::vector<Perturbation> perturbations;
        try {
          perturbations = read_perturbations(file.string());
        } catch (const std::exception& e) {
          std::cerr << "\ndiffdope_eval: " << e.what() << "; skipped\n";
          ++skipped_files;
          continue;
        }
        for (const Perturbation& p : perturbations) {
          if (max_samples >= 0 && p.sample >= max_samples) continue;
          const BopInstance* gt = nullptr;
          int k = 0;
          for (const auto& g : img.gt)
            if (g.obj_id == p.obj_id && k++ == p.occurrence) gt = &g;
          if (!gt) {
            std::cerr << "\ndiffdope_eval: " << file.string() << " sample " << p.sample << ": obj " << p.obj_id
                      << " has no ground truth in scene " << scene << "; skipped\n";
            ++skipped;
            continue;
          }
          if (!data.has_model(p.obj_id)) {
            std::cerr << "\ndiffdope_eval: " << file.string() << " sample " << p.sample << ": no model for obj "
                      << p.obj_id << " in " << root << "/models; skipped\n";
            ++skipped;
            continue;
          }
          const Mesh* mesh_ptr = nullptr;
          Observation obs;
          double mask_iou_given = -1;
          try {
            mesh_ptr = &data.model(p.obj_id);
            obs = data.observation(img, gt->inst);
            if (depth == "none") obs.depth = cv::Mat();
            // One segmenter's mask per object and image, whatever the start.
            mask_iou_given = apply_mask_mode(obs, masks, coarse_seed * 0x9E3779B97F4A7C15ull +
                                                             uint64_t(scene) * 1000003ull + uint64_t(gt->inst));
          } catch (const std::exception& e) {
            std::cerr << "\ndiffdope_eval: " << file.string() << " sample " << p.sample << ": " << e.what()
                      << "; skipped\n";
            ++skipped;
            continue;
          }
          const Mesh& mesh = *mesh_ptr;
          RefineResult r;
          if (icp_renderer) {  // the baseline: a pose and its time, no verdict (plausible and judged false)
            const IcpResult icp = icp_refine(*icp_renderer, img.camera, obs, mesh, p.pose);
            r.pose = icp.pose, r.time_ms = icp.time_ms, r.error = icp.error, r.learning_rates = {0.0}, r.winner = 0;
          } else {
            if (track_budget && level == "tracking") {  // as the node refines a steady track
              ObjectTarget t;
              t.mesh = &mesh;
              t.initial = p.pose;
              t.mask = obs.mask;
              t.box = obs.box;
              t.start_kind = StartKind::kTracked;
              r = refiner.refine_all(img.camera, obs, {t}, tracked_options(options, *track_budget)).front();
            } else {
              r = refiner.refine(img.camera, obs, mesh, p.pose);
            }
          }
          if (!r.error.empty()) {
            std::cerr << "\ndiffdope_eval: " << file.string() << " sample " << p.sample << ": obj " << p.obj_id
                      << " in scene " << scene << ": " << r.error << "; skipped\n";
            ++skipped;
            continue;
          }
          const auto pts = metric_points(mesh);
          const bool sym = data.symmetric(p.obj_id);
          const double e0 = sym ? adds_error(pts, p.pose, gt->pose) : add_error(pts, p.pose, gt->pose);
          const double e1 = sym ? adds_error(pts, r.pose, gt->pose) : add_error(pts, r.pose, gt->pose);
          for (LevelStats* s : {&st, &object_stats[p.obj_id][level]}) {
            s->init.push_back(e0);
            s->refined.push_back(e1);
            s->ms.push_back(r.time_ms);
          }
          verdicts.add(e1, r.plausible);
          nlohmann::json line = {{"scene_id", scene}, {"im_id", 0}, {"obj_id", p.obj_id}, {"inst", gt->inst},
                                 {"level", level}, {"sample", p.sample}, {"R", r.pose.rotation_rowmajor()},
                                 {"t", {1e3 * r.pose.t.x(), 1e3 * r.pose.t.y(), 1e3 * r.pose.t.z()}},
                                 {"init_R", p.pose.rotation_rowmajor()},
                                 {"init_t", {1e3 * p.pose.t.x(), 1e3 * p.pose.t.y(), 1e3 * p.pose.t.z()}},
                                 {"time_ms", r.time_ms}, {"loss", r.loss.total}, {"error_init_mm", 1e3 * e0},
                                 {"error_mm", 1e3 * e1}, {"metric", sym ? "ADD-S" : "ADD"},
                                 {"mask_iou", r.mask_iou}, {"plausible", r.plausible}, {"judged", r.judged},
                                 {"winner_lr", r.learning_rates[r.winner]}};
          line["depth_inliers"] = r.depth_inliers;
          line["depth_noise"] = r.depth_noise;
          line["confidence"] = r.confidence;
          line["loss_terms"] = {{"rgb", r.loss.rgb}, {"depth", r.loss.depth}, {"mask", r.loss.mask}};
          line["terms"] = used_terms(r.loss_used);
          line["scan_turns"] = r.scan_turns;
          line["scan_taken"] = r.scan_taken;
          line["print_turn_deg"] = r.print_turn * 180.0 / M_PI;
          line["shape_turn_deg"] = r.shape_turn * 180.0 / M_PI;
          if (std::isfinite(r.rival_print)) line["rival_print"] = r.rival_print;
          line["retried"] = r.retried;
          line["polish_iterations"] = r.polish_iterations;
          line["newton_steps"] = r.newton_steps;
          line["evaluations"] = r.evaluations;
          for (size_t stage = 0; stage < size_t(kRefineStages); ++stage) {
            const long made = r.stage_evaluations[stage];
            line["stage_evaluations"][to_string(RefineStage(stage))] = made;
            stage_sum[stage] += double(made);
            if (!r.retried) stage_most[stage] = std::max(stage_most[stage], made);
          }
          ++stage_results;
          line["given_mask_iou"] = mask_iou_given;  // the mask given against the visible one (-1: none given)
          line["given_mask_offset"] = r.given_mask_offset;
          line["given_mask_replaced"] = r.given_mask_replaced;
          if (masks == "coarse") given_ious.push_back(mask_iou_given);
          line["given_mask_shift"] = r.given_mask_shift;
          line["given_mask_shifted_offset"] = r.given_mask_shifted_offset;
          masks_checked += r.given_mask_offset >= 0, masks_replaced += r.given_mask_replaced;
          if (r.given_mask_shifted_offset >= 0)
            mask_shifts[p.obj_id].push_back({r.given_mask_shift[0], r.given_mask_shift[1], r.given_mask_offset,
                                              r.given_mask_shifted_offset});
          line["print"] = {{"ncc", r.print.ncc}, {"best_ncc", r.print.best_ncc}, {"best_dx", r.print.best_dx},
                           {"best_dy", r.print.best_dy}, {"far_mean", r.print.far_mean}, {"far_std", r.print.far_std},
                           {"pixels", r.print.pixels}, {"render_contrast", r.print.render_contrast}};
          if (r.curvature.valid) line["weakest_rise"] = r.curvature.weakest_rise;  // (pose_curvature.hpp)
          if (r.curvature.valid && !sym) {
            const CovarianceCheck c = check_covariance(pose_error_twist(r.pose, gt->pose, mesh.center()), r.covariance);
            line["covariance_mahalanobis2"] = c.mahalanobis2;
            line["covariance_within_two_sigma"] = c.within_two_sigma;
            if (r.plausible && std::isfinite(c.mahalanobis2)) {
              ++cov_checked;
              cov_inside += c.mahalanobis2 <= kChiSquared6At95;
              cov_two_sigma += c.within_two_sigma;
            }
          }
          // The best run that ended elsewhere (its pose's points > 1 cm from the winner's, ADD(-S)): how much
          // worse its loss is, relative (a diagnostic of ambiguity; absent when every run agrees).
          double rival = std::numeric_limits<double>::infinity();
          for (size_t i = 0; i < r.run_poses.size(); ++i) {
            if (int(i) == r.winner || !std::isfinite(r.run_losses[i])) continue;
            const double d = sym ? adds_error(pts, r.run_poses[i], r.pose) : add_error(pts, r.run_poses[i], r.pose);
            if (d > 0.01) rival = std::min(rival, r.run_losses[i]);
          }
          if (std::isfinite(rival) && r.loss.total > 0) line["rival_gap"] = rival / r.loss.total - 1.0;
          out << line.dump() << "\n";
          out.flush();
          std::fprintf(stderr, "\r%s scene %d sample %d: %.1f -> %.1f mm (%.0f ms)    ", level.c_str(), scene,
                       p.sample, 1e3 * e0, 1e3 * e1, r.time_ms);
        }
      }
    }
    std::fprintf(stderr, "\n");
    nlohmann::json summary = nlohmann::json::object();
    std::vector<double> all_ref;
    std::printf("%-8s %6s | %9s %9s | %8s %8s | %9s\n", "level", "n", "AUC init", "AUC ref", "<10mm %", "<5mm %",
                "median ms");
    // One line of the table (`indent` before the level's name) and its entry `name` in `into`.
    const auto row = [&](const std::string& name, const LevelStats& s, nlohmann::json& into, const char* indent = "") {
      const double ai = accuracy_auc(s.init, 0.05), ar = accuracy_auc(s.refined, 0.05);
      std::printf("%-8s %6zu | %9.2f %9.2f | %8.1f %8.1f | %9.0f\n", (indent + name).c_str(), s.init.size(), ai, ar,
                  percent_below(s.refined, 0.01), percent_below(s.refined, 0.005), median(s.ms));
      into[name] = {{"n", s.init.size()}, {"auc_initial", ai}, {"auc_refined", ar},
                    {"pct_below_10mm", percent_below(s.refined, 0.01)},
                    {"pct_below_5mm", percent_below(s.refined, 0.005)}, {"median_ms", median(s.ms)}};
    };
    const auto append = [](LevelStats& to, const LevelStats& from) {
      to.init.insert(to.init.end(), from.init.begin(), from.init.end());
      to.refined.insert(to.refined.end(), from.refined.begin(), from.refined.end());
      to.ms.insert(to.ms.end(), from.ms.begin(), from.ms.end());
    };
    LevelStats all;
    for (const auto& l : level_order) {
      row(l, stats[l], summary);
      append(all, stats[l]);
    }
    row("all", all, summary);
    all_ref = all.refined;
    // Per object: the same table, one block per obj_id.
    summary["objects"] = nlohmann::json::object();
    for (auto& [obj, by_level] : object_stats) {
      std::printf("obj %d\n", obj);
      nlohmann::json& o = summary["objects"][std::to_string(obj)];
      LevelStats obj_all;
      for (const auto& l : level_order)
        if (by_level.count(l)) {
          row(l, by_level[l], o, "  ");
          append(obj_all, by_level[l]);
        }
      row("all", obj_all, o, "  ");
    }
    std::printf("verdict: plausible false for %d of %d results over 10 mm, for %d of %d under 5 mm\n",
                verdicts.rejected_far, verdicts.far, verdicts.rejected_near, verdicts.near);
    summary["verdict"] = {{"over_10mm", verdicts.far}, {"over_10mm_rejected", verdicts.rejected_far},
                          {"under_5mm", verdicts.near}, {"under_5mm_rejected", verdicts.rejected_near}};
    if (cov_checked > 0) {
      std::printf("covariance: the true error within the 95 %% ellipsoid for %d of %d plausible results (%.1f %%), "
                  "every coordinate within 2 sigma for %d (%.1f %%)\n",
                  cov_inside, cov_checked, 100.0 * cov_inside / cov_checked, cov_two_sigma,
                  100.0 * cov_two_sigma / cov_checked);
      summary["covariance"] = {{"checked", cov_checked}, {"within_95_ellipsoid", cov_inside},
                               {"within_two_sigma", cov_two_sigma}};
    }
    if (!given_ious.empty()) {  // --masks coarse: how coarse the masks given were
      std::sort(given_ious.begin(), given_ious.end());
      const double lo = given_ious[given_ious.size() / 10], mid = given_ious[given_ious.size() / 2],
                   hi = given_ious[given_ious.size() * 9 / 10];
      std::printf("masks given: IoU with the visible masks, median %.3f (10-90 %%: %.3f-%.3f)\n", mid, lo, hi);
      summary["given_mask_iou"] = {{"median", mid}, {"p10", lo}, {"p90", hi}};
    }
    if (masks_checked > 0) {
      std::printf("masks given: %d of %d checked against depth replaced by its pixels\n", masks_replaced, masks_checked);
      summary["given_masks"] = {{"checked", masks_checked}, {"replaced", masks_replaced}};
      // A mask off the image as a whole (misregistered colour, labels from poses off the image) shows as a
      // shift that leaves little offset; a segmenter's coarse outline keeps its offset.
      for (auto& [obj, rows] : mask_shifts) {
        std::array<double, 4> mid{};
        for (size_t k = 0; k < mid.size(); ++k) {
          std::vector<double> v;
          for (const auto& r : rows) v.push_back(r[k]);
          std::nth_element(v.begin(), v.begin() + long(v.size() / 2), v.end());
          mid[k] = v[v.size() / 2];
        }
        std::printf("  obj %d: median shift onto depth's edge (%+.0f, %+.0f) camera px; outline offset %.2f, %.2f "
                    "after the shift (refining px)\n", obj, mid[0], mid[1], mid[2], mid[3]);
        summary["given_masks"]["objects"][std::to_string(obj)] = {
            {"median_shift_px", {mid[0], mid[1]}}, {"median_offset", mid[2]}, {"median_shifted_offset", mid[3]}};
      }
    }
    if (stage_results > 0) {
      std::printf("evaluations by stage, mean per object (retries included) / most in one refinement / planned:");
      for (size_t stage = 0; stage < size_t(kRefineStages); ++stage) {
        const RefineStage s = RefineStage(stage);
        const double mean = stage_sum[stage] / double(stage_results);
        const long planned = planned_evaluations(options, s);
        std::printf("%s %s %.0f / %ld / %ld", stage == 0 ? "" : ",", to_string(s), mean, stage_most[stage], planned);
        summary["stage_evaluations"][to_string(s)] = {{"mean", mean}, {"most", stage_most[stage]}, {"planned", planned}};
      }
      std::printf("\n");
    }
    if (!summary_path.empty()) std::ofstream(summary_path) << summary.dump(2) << "\n";
    if (all_ref.empty() && (skipped_scenes > 0 || skipped_files > 0))
      throw std::runtime_error("nothing was evaluated: " + std::to_string(skipped_scenes) + " scene(s) and " +
                               std::to_string(skipped_files) + " perturbation file(s) could not be used (see above)");
    if (all_ref.empty())
      throw std::runtime_error("nothing was evaluated: " +
                               (perturbation_files == 0 ? "no perturbation files (" + pert_dir +
                                                              "/<scene>/scene_error_*.json) for the scenes of " +
                                                              root + "/" + split +
                                                              (levels.empty() ? std::string() : " at the levels asked for")
                                                        : std::to_string(skipped) + " samples, all skipped"));
    if (skipped > 0 || skipped_scenes > 0 || skipped_files > 0) {
      std::cerr << "diffdope_eval: " << skipped << " of " << skipped + all_ref.size() << " samples were skipped";
      if (skipped_scenes > 0 || skipped_files > 0)
        std::cerr << ", and " << skipped_scenes << " scene(s) and " << skipped_files << " perturbation file(s)";
      std::cerr << " (see above); the figures leave them out\n";
      return 1;
    }
  } catch (const std::exception& e) {
    std::cerr << "diffdope_eval: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
