#pragma once
// Reading BOP-format datasets (models/, <split>/<scene:06d>/scene_camera.json, scene_gt.json, rgb/, depth/,
// mask_visib/) and Diff-DOPE perturbation files. Files are in millimetres; everything returned is in metres.
#include <map>
#include <memory>
#include <set>
#include <string>
#include <vector>

#include "diffdope/camera.hpp"
#include "diffdope/mesh.hpp"
#include "diffdope/observation.hpp"
#include "diffdope/pose.hpp"

namespace diffdope {

struct BopInstance {
  int obj_id = 0;
  int inst = 0;  // index in the image's scene_gt list (names mask_visib/<im>_<inst>.png)
  Pose pose;     // model -> camera, metres
};

struct BopImage {
  int scene_id = 0, im_id = 0;
  Camera camera;
  double depth_scale = 1.0;  // millimetres per depth unit (BOP's convention)
  std::vector<BopInstance> gt;
};

/// One initial pose from a perturbation file (`DIR/<scene:06d>/scene_error_deg_<DDD>_trans_<TTT>.json`).
struct Perturbation {
  int sample = 0;
  int obj_id = 0;
  int occurrence = 0;  // k-th entry of this obj_id within the sample: matched to the k-th gt of that obj_id
  Pose pose;           // metres
};

class BopDataset {
 public:
  /// Throws std::runtime_error naming the path when `root/models` or `root/split` is missing, or when
  /// `root/models/models_info.json` (which says which objects are symmetric) is missing or malformed.
  /// `symmetric_ids`: the symmetric objects given another way; models_info.json is then not read.
  BopDataset(const std::string& root, const std::string& split, const std::set<int>* symmetric_ids = nullptr);
  std::vector<int> scene_ids() const;
  /// Camera and ground truth of one image. Throws std::runtime_error naming the file on malformed JSON.
  BopImage image(int scene_id, int im_id) const;
  /// RGB, depth (metres) and the visible mask of one instance.
  Observation observation(const BopImage& img, int inst) const;
  bool has_model(int obj_id) const;
  /// The model in metres (loaded once, cached), with the symmetries models_info.json declares.
  const Mesh& model(int obj_id);
  /// True when models_info.json lists symmetries (discrete or continuous): score with ADD-S.
  bool symmetric(int obj_id) const;

 private:
  std::string root_, split_;
  std::map<int, bool> symmetric_;
  std::map<int, ObjectSymmetry> symmetries_;  // declared in models_info.json; given to model()'s meshes
  std::map<int, std::unique_ptr<Mesh>> models_;
};

/// Reads a perturbation file (keys = sample index; lists of {obj_id, cam_R_m2c, cam_t_m2c (mm)}).
std::vector<Perturbation> read_perturbations(const std::string& path);

/// Level name from a perturbation file name: deg 001 -> easy, 010 -> medium, 040 -> hard, else the stem.
std::string perturbation_level(const std::string& filename);

}  // namespace diffdope
