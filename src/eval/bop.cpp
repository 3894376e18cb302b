#include "diffdope/bop.hpp"

#include "diffdope/image_file.hpp"
#include "diffdope/input_files.hpp"
#include "diffdope/input_limits.hpp"

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <stdexcept>

namespace diffdope {
namespace fs = std::filesystem;
using nlohmann::json;

namespace {

json read_json(const std::string& path) {
  try {
    return parse_json_checked(read_text_file(path, "a BOP JSON file"), path);
  } catch (const InputFileError& e) {
    throw std::runtime_error(path + ": " + e.what());
  }
}

std::string scene_dir(const std::string& root, const std::string& split, int scene) {
  char buf[16];
  std::snprintf(buf, sizeof buf, "%06d", scene);
  return root + "/" + split + "/" + buf;
}

Pose pose_mm(const json& e, const std::string& where) {
  try {
    const auto R = e.at("cam_R_m2c").get<std::vector<double>>();
    const auto t = e.at("cam_t_m2c").get<std::vector<double>>();
    if (R.size() != 9 || t.size() != 3) throw std::runtime_error("cam_R_m2c needs 9 values, cam_t_m2c 3");
    std::array<double, 9> r;
    std::copy(R.begin(), R.end(), r.begin());
    Pose p = Pose::from_rotation_rowmajor(r, 0.001 * Eigen::Vector3d(t[0], t[1], t[2]));
    if (!p.is_valid(1e-3)) throw std::runtime_error("rotation is not orthonormal or values are not finite");
    p.orthonormalize();
    return p;
  } catch (const json::exception& ex) {
    throw std::runtime_error(where + ": " + ex.what());
  } catch (const std::runtime_error& ex) {
    throw std::runtime_error(where + ": " + ex.what());
  }
}

int object_id(const json& e, const std::string& where) {
  if (!e.is_object() || !e.contains("obj_id") || !e["obj_id"].is_number_integer())
    throw std::runtime_error(where + ": an entry without an integer obj_id");
  const long long id = e["obj_id"].get<long long>();
  if (id < 0 || id > std::numeric_limits<int>::max())
    throw std::runtime_error(where + ": obj_id " + std::to_string(id) + " is outside [0, " +
                             std::to_string(std::numeric_limits<int>::max()) + "]");
  return int(id);
}

cv::Mat imread_checked(const std::string& path, int flags, const std::string& kind) {
  try {
    return read_image_file(path, flags, kind, input_limits::kMaxImagePixels);
  } catch (const InputFileError& e) {
    throw std::runtime_error(path + ": " + e.what());
  }
}

/// A numeric array of `n` finite numbers at j[key] (or j itself when key is empty).
std::vector<double> numbers(const json& j, size_t n, const std::string& where) {
  if (!j.is_array() || j.size() != n) throw std::runtime_error(where + ": expected " + std::to_string(n) + " numbers");
  std::vector<double> out;
  for (const json& x : j) {
    if (!x.is_number() || !std::isfinite(x.get<double>())) throw std::runtime_error(where + ": not a finite number");
    out.push_back(x.get<double>());
  }
  return out;
}

/// BOP's declared symmetries of one models_info.json entry (lengths in mm).
ObjectSymmetry parse_bop_symmetry(const json& v, const std::string& where) {
  ObjectSymmetry sym;
  constexpr double kMetresPerMm = 1e-3;
  const auto list = [&](const char* key) {
    const json& l = v.contains(key) ? v[key] : json::array();
    if (!l.is_array()) throw std::runtime_error(where + ": " + key + " is not a list");
    return l;
  };
  const json cont = list("symmetries_continuous"), disc = list("symmetries_discrete");
  for (size_t i = 0; i < cont.size(); ++i) {
    const std::string w = where + ": symmetries_continuous[" + std::to_string(i) + "]";
    if (!cont[i].is_object() || !cont[i].contains("axis")) throw std::runtime_error(w + ": expected {axis, offset}");
    const std::vector<double> a = numbers(cont[i]["axis"], 3, w + ".axis");
    const std::vector<double> o = cont[i].contains("offset") ? numbers(cont[i]["offset"], 3, w + ".offset")
                                                             : std::vector<double>{0, 0, 0};
    sym.continuous.push_back({Eigen::Vector3d(a[0], a[1], a[2]), kMetresPerMm * Eigen::Vector3d(o[0], o[1], o[2])});
  }
  for (size_t i = 0; i < disc.size(); ++i) {
    const std::vector<double> m = numbers(disc[i], 16, where + ": symmetries_discrete[" + std::to_string(i) + "]");
    Eigen::Matrix4d T;
    for (int k = 0; k < 16; ++k) T(k / 4, k % 4) = m[k];
    T.topRightCorner<3, 1>() *= kMetresPerMm;
    sym.discrete.push_back(Pose(T.topLeftCorner<3, 3>(), T.topRightCorner<3, 1>()));
  }
  try {
    sym.validate_and_normalise(where);
  } catch (const std::invalid_argument& e) {
    throw std::runtime_error(e.what());
  }
  return sym;
}

}  // namespace

BopDataset::BopDataset(const std::string& root, const std::string& split, const std::set<int>* symmetric_ids)
    : root_(root), split_(split) {
  if (!fs::is_directory(root + "/models")) throw std::runtime_error(root + "/models: not a directory");
  if (!fs::is_directory(root + "/" + split)) throw std::runtime_error(root + "/" + split + ": not a directory");
  if (symmetric_ids) {
    for (int id : *symmetric_ids) symmetric_[id] = true;
    return;
  }
  // Without it a symmetric object would be scored with ADD (its symmetric poses counted as errors).
  const std::string info = root + "/models/models_info.json";
  if (!fs::exists(info))
    throw std::runtime_error(info + ": missing; it says which objects are symmetric (scored with ADD-S). Give "
                                    "the symmetric object ids another way (diffdope_eval --symmetric 1,5 or --symmetric none)");
  const json j = read_json(info);
  if (!j.is_object()) throw std::runtime_error(info + ": expected an object keyed by object id");
  for (const auto& [key, v] : j.items()) {
    size_t used = 0;
    int id = -1;
    try {
      id = std::stoi(key, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used != key.size() || id < 0) throw std::runtime_error(info + ": key '" + key + "' is not an object id");
    if (!v.is_object()) throw std::runtime_error(info + ": object " + key + " is not an object");
    symmetric_[id] = v.contains("symmetries_discrete") || v.contains("symmetries_continuous");
    symmetries_[id] = parse_bop_symmetry(v, info + ": object " + key);
  }
}

std::vector<int> BopDataset::scene_ids() const {
  std::vector<int> ids;
  for (const auto& e : fs::directory_iterator(root_ + "/" + split_))
    if (e.is_directory()) {
      try {
        ids.push_back(std::stoi(e.path().filename().string()));
      } catch (...) {
      }
    }
  std::sort(ids.begin(), ids.end());
  return ids;
}

BopImage BopDataset::image(int scene_id, int im_id) const {
  const std::string dir = scene_dir(root_, split_, scene_id);
  BopImage img;
  img.scene_id = scene_id;
  img.im_id = im_id;
  const std::string key = std::to_string(im_id);
  const json cams = read_json(dir + "/scene_camera.json");
  if (!cams.is_object() || !cams.contains(key))
    throw std::runtime_error(dir + "/scene_camera.json: no entry for image " + key);
  std::vector<double> K;
  try {
    K = cams[key].at("cam_K").get<std::vector<double>>();
    img.depth_scale = cams[key].value("depth_scale", 1.0);
  } catch (const json::exception& e) {
    throw std::runtime_error(dir + "/scene_camera.json (image " + key + "): " + e.what());
  }
  if (K.size() != 9) throw std::runtime_error(dir + "/scene_camera.json: cam_K needs 9 values");
  if (!(img.depth_scale > 0) || !std::isfinite(img.depth_scale))
    throw std::runtime_error(dir + "/scene_camera.json: depth_scale must be a positive number");
  char name[32];
  std::snprintf(name, sizeof name, "%06d.png", im_id);
  cv::Mat rgb = imread_checked(dir + "/rgb/" + name, cv::IMREAD_COLOR, "rgb");
  img.camera = Camera(K[0], K[4], K[2], K[5], rgb.cols, rgb.rows);
  try {
    img.camera.validate();
  } catch (const std::exception& e) {
    throw std::runtime_error(dir + "/scene_camera.json (image " + key + "): cam_K: " + e.what());
  }
  const json gts = read_json(dir + "/scene_gt.json");
  if (gts.is_object() && gts.contains(key)) {
    if (!gts[key].is_array()) throw std::runtime_error(dir + "/scene_gt.json: image " + key + " is not a list");
    int inst = 0;
    for (const auto& e : gts[key]) {
      BopInstance b;
      b.obj_id = object_id(e, dir + "/scene_gt.json (image " + key + ")");
      b.inst = inst++;
      b.pose = pose_mm(e, dir + "/scene_gt.json");
      img.gt.push_back(b);
    }
  }
  return img;
}

Observation BopDataset::observation(const BopImage& img, int inst) const {
  const std::string dir = scene_dir(root_, split_, img.scene_id);
  char name[32], mname[40];
  std::snprintf(name, sizeof name, "%06d.png", img.im_id);
  std::snprintf(mname, sizeof mname, "%06d_%06d.png", img.im_id, inst);
  Observation o;
  o.rgb = to_rgb_float(imread_checked(dir + "/rgb/" + name, cv::IMREAD_COLOR, "rgb"), true, dir + "/rgb/" + name);
  const std::string dpath = dir + "/depth/" + name;
  if (fs::exists(dpath)) o.depth = to_depth_metres(imread_checked(dpath, cv::IMREAD_ANYDEPTH, "depth"), 0.001 * img.depth_scale, dpath);
  const std::string mpath = dir + "/mask_visib/" + mname;
  if (fs::exists(mpath)) o.mask = to_mask_float(imread_checked(mpath, cv::IMREAD_GRAYSCALE, "mask"), mpath);
  try {
    o.validate(img.camera);
  } catch (const std::exception& e) {
    throw std::runtime_error(dir + " (image " + std::to_string(img.im_id) + ", instance " + std::to_string(inst) +
                             "): " + e.what());
  }
  return o;
}

bool BopDataset::has_model(int obj_id) const {
  char name[32];
  std::snprintf(name, sizeof name, "obj_%06d.ply", obj_id);
  return fs::exists(root_ + "/models/" + name);
}

const Mesh& BopDataset::model(int obj_id) {
  auto it = models_.find(obj_id);
  if (it != models_.end()) return *it->second;
  char name[32];
  std::snprintf(name, sizeof name, "obj_%06d.ply", obj_id);
  MeshLoadOptions opt;
  opt.scale = 0.001;
  auto mesh = std::make_unique<Mesh>(Mesh::load(root_ + "/models/" + name, opt));
  if (auto s = symmetries_.find(obj_id); s != symmetries_.end()) mesh->symmetry = s->second;
  return *(models_[obj_id] = std::move(mesh));
}

bool BopDataset::symmetric(int obj_id) const {
  auto it = symmetric_.find(obj_id);
  return it != symmetric_.end() && it->second;
}

std::vector<Perturbation> read_perturbations(const std::string& path) {
  const json j = read_json(path);
  if (!j.is_object()) throw std::runtime_error(path + ": expected an object keyed by sample index");
  std::vector<Perturbation> out;
  for (const auto& [key, list] : j.items()) {
    int sample = -1;
    size_t used = 0;
    try {
      sample = std::stoi(key, &used);
    } catch (...) {
      used = 0;
    }
    if (used != key.size() || sample < 0) throw std::runtime_error(path + ": key '" + key + "' is not a sample index");
    if (!list.is_array()) throw std::runtime_error(path + ": sample " + key + " is not a list");
    std::map<int, int> seen;
    for (const auto& e : list) {
      Perturbation p;
      p.sample = sample;
      p.obj_id = object_id(e, path + " (sample " + key + ")");
      p.occurrence = seen[p.obj_id]++;
      p.pose = pose_mm(e, path + " (sample " + key + ")");
      out.push_back(p);
    }
  }
  std::sort(out.begin(), out.end(), [](const Perturbation& a, const Perturbation& b) {
    return a.sample != b.sample ? a.sample < b.sample : a.obj_id != b.obj_id ? a.obj_id < b.obj_id : a.occurrence < b.occurrence;
  });
  return out;
}

std::string perturbation_level(const std::string& filename) {
  const std::string stem = fs::path(filename).stem().string();
  if (stem.rfind("scene_error_deg_001", 0) == 0) return "easy";
  if (stem.rfind("scene_error_deg_010", 0) == 0) return "medium";
  if (stem.rfind("scene_error_deg_040", 0) == 0) return "hard";
  return stem;
}

}  // namespace diffdope
