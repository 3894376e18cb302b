// The objects YAML (object_config.hpp): parsing, defaults, mesh path resolution, the error messages of every
// rejected input, and loading an object's mesh with its scale.
#include <gtest/gtest.h>

#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <string>

#include "diffdope/object_config.hpp"
#include "diffdope/procedural.hpp"

namespace fs = std::filesystem;
using namespace diffdope;

namespace {

/// A fresh directory under the system temp dir, removed with its contents at the end of the test.
struct ScratchDir {
  fs::path path;
  ScratchDir() {
    static std::atomic<int> counter{0};
    path = fs::temp_directory_path() /
           ("diffdope_object_config_" + std::to_string(::getpid()) + "_" +
            std::to_string(std::chrono::steady_clock::now().time_since_epoch().count()) + "_" +
            std::to_string(counter++));
    fs::create_directories(path);
  }
  ~ScratchDir() {
    std::error_code ec;
    fs::remove_all(path, ec);
  }
  std::string write(const std::string& name, const std::string& text) const {
    const fs::path p = path / name;
    std::ofstream(p) << text;
    return p.string();
  }
};

ObjectsConfig parse(const std::string& yaml, const PackageResolver& resolver = {}) {
  return parse_objects_config(yaml, "objects.yaml", "/base/dir", resolver);
}

/// The message of the runtime_error that parsing `yaml` throws ("" when it does not throw).
std::string parse_error(const std::string& yaml, const PackageResolver& resolver = {}) {
  try {
    parse(yaml, resolver);
  } catch (const std::runtime_error& e) {
    return e.what();
  }
  return "";
}

#define EXPECT_CONTAINS(haystack, needle)                                                    \
  do {                                                                                       \
    const std::string h_ = (haystack), n_ = (needle);                                        \
    EXPECT_NE(h_.find(n_), std::string::npos) << "'" << h_ << "' does not mention '" << n_ << "'"; \
  } while (0)

const char* kFullConfig = R"(
refiner:
  iterations: 7
  batch_size: 5
objects:
  - name: cracker_box
    mesh: meshes/cracker.ply
    mesh_scale: 0.01
    symmetric: false
    mask_label: 3
    pose_topic: /my_detector/cracker
    model_transform:
      translation: [0.01, -0.02, 0.03]
      rotation: [0, 0, 0.7071067811865476, 0.7071067811865476]
  - name: soup
    mesh: /abs/soup.obj
    symmetric: true
    max_instances: 3
)";

}  // namespace

TEST(ObjectConfig, ParsesEveryKey) {
  const ObjectsConfig cfg = parse(kFullConfig);
  ASSERT_EQ(cfg.objects.size(), 2u);
  const ObjectConfig& a = cfg.objects[0];
  EXPECT_EQ(a.name, "cracker_box");
  EXPECT_EQ(a.mesh, "meshes/cracker.ply");
  EXPECT_EQ(a.mesh_path, "/base/dir/meshes/cracker.ply");
  EXPECT_DOUBLE_EQ(a.mesh_scale, 0.01);
  EXPECT_FALSE(a.symmetric);
  EXPECT_EQ(a.mask_label, 3);
  EXPECT_EQ(a.pose_topic, "/my_detector/cracker");
  EXPECT_TRUE(a.model_transform.t.isApprox(Eigen::Vector3d(0.01, -0.02, 0.03)));
  // 90 degrees about z: x -> y.
  EXPECT_TRUE((a.model_transform.R * Eigen::Vector3d::UnitX()).isApprox(Eigen::Vector3d::UnitY(), 1e-9));
  EXPECT_TRUE(a.model_transform.is_valid());

  const ObjectConfig& b = cfg.objects[1];
  EXPECT_EQ(b.name, "soup");
  EXPECT_EQ(b.mesh_path, "/abs/soup.obj");
  EXPECT_TRUE(b.symmetric);
  EXPECT_EQ(b.max_instances, 3);
  EXPECT_EQ(instance_name(b, 0), "soup_0");
  EXPECT_EQ(instance_name(b, 2), "soup_2");
  EXPECT_EQ(instance_name(a, 0), "cracker_box");  // one instance: the object's own name

  // The refiner section overrides only the keys it names.
  EXPECT_EQ(cfg.refiner.iterations, 7);
  EXPECT_EQ(cfg.refiner.batch_size, 5);
  EXPECT_DOUBLE_EQ(cfg.refiner.lr_high, RefinerOptions().lr_high);
}

TEST(ObjectConfig, Defaults) {
  const ObjectsConfig cfg = parse("objects:\n  - name: thing\n    mesh: thing.ply\n");
  ASSERT_EQ(cfg.objects.size(), 1u);
  const ObjectConfig& o = cfg.objects[0];
  EXPECT_DOUBLE_EQ(o.mesh_scale, 1.0);
  EXPECT_FALSE(o.symmetric);
  EXPECT_EQ(o.mask_label, -1);
  EXPECT_EQ(o.max_instances, 1);
  EXPECT_TRUE(o.pose_topic.empty());
  EXPECT_TRUE(o.model_transform.R.isIdentity());
  EXPECT_TRUE(o.model_transform.t.isZero());
  const RefinerOptions d;
  EXPECT_EQ(cfg.refiner.iterations, d.iterations);
  EXPECT_EQ(cfg.refiner.batch_size, d.batch_size);
}

TEST(ObjectConfig, RefinerBaseSuppliesUnsetKeys) {
  RefinerOptions base;
  base.iterations = 11;
  base.batch_size = 3;
  const ObjectsConfig cfg =
      parse_objects_config("refiner:\n  iterations: 22\nobjects:\n  - {name: a, mesh: a.ply}\n", "x.yaml", "/d", {}, base);
  EXPECT_EQ(cfg.refiner.iterations, 22);
  EXPECT_EQ(cfg.refiner.batch_size, 3);
  const ObjectsConfig no_section = parse_objects_config("objects:\n  - {name: a, mesh: a.ply}\n", "x.yaml", "/d", {}, base);
  EXPECT_EQ(no_section.refiner.iterations, 11);
}

TEST(ObjectConfig, PartialModelTransform) {
  const ObjectsConfig t = parse("objects:\n  - name: a\n    mesh: a.ply\n    model_transform:\n      translation: [1, 2, 3]\n");
  EXPECT_TRUE(t.objects[0].model_transform.t.isApprox(Eigen::Vector3d(1, 2, 3)));
  EXPECT_TRUE(t.objects[0].model_transform.R.isIdentity());
  // Rotation first, translation second: both kept. Quaternions are normalised.
  const ObjectsConfig r = parse(
      "objects:\n  - name: a\n    mesh: a.ply\n    model_transform:\n      rotation: [0, 0, 2, 2]\n"
      "      translation: [1, 2, 3]\n");
  EXPECT_TRUE(r.objects[0].model_transform.t.isApprox(Eigen::Vector3d(1, 2, 3)));
  EXPECT_TRUE(r.objects[0].model_transform.is_valid());
  EXPECT_TRUE((r.objects[0].model_transform.R * Eigen::Vector3d::UnitX()).isApprox(Eigen::Vector3d::UnitY(), 1e-9));
  const ObjectsConfig tr = parse(
      "objects:\n  - name: a\n    mesh: a.ply\n    model_transform:\n      translation: [1, 2, 3]\n"
      "      rotation: [0, 0, 2, 2]\n");
  EXPECT_TRUE(tr.objects[0].model_transform.t.isApprox(Eigen::Vector3d(1, 2, 3)));
}

TEST(ObjectConfig, ResolveMeshPath) {
  EXPECT_EQ(resolve_mesh_path("m.ply", "/base/dir", {}), "/base/dir/m.ply");
  EXPECT_EQ(resolve_mesh_path("sub/../m.ply", "/base/dir", {}), "/base/dir/m.ply");
  EXPECT_EQ(resolve_mesh_path("../m.ply", "/base/dir", {}), "/base/m.ply");
  EXPECT_EQ(resolve_mesh_path("/abs/path/m.ply", "/base/dir", {}), "/abs/path/m.ply");
  EXPECT_EQ(resolve_mesh_path("/abs/./path/m.ply", "/base/dir", {}), "/abs/path/m.ply");
  EXPECT_EQ(resolve_mesh_path("file:///abs/m.ply", "/base/dir", {}), "/abs/m.ply");
}

TEST(ObjectConfig, ResolvePackageUrl) {
  std::string asked;
  const PackageResolver resolver = [&](const std::string& pkg) -> std::string {
    asked = pkg;
    if (pkg == "my_pkg") return "/opt/ws/src/my_pkg";
    return "";
  };
  EXPECT_EQ(resolve_mesh_path("package://my_pkg/meshes/a.ply", "/base", resolver), "/opt/ws/src/my_pkg/meshes/a.ply");
  EXPECT_EQ(asked, "my_pkg");

  try {
    resolve_mesh_path("package://other_pkg/a.ply", "/base", resolver);
    FAIL() << "unknown package accepted";
  } catch (const std::runtime_error& e) {
    EXPECT_CONTAINS(e.what(), "other_pkg");
  }
  try {
    resolve_mesh_path("package://my_pkg/a.ply", "/base", {});
    FAIL() << "package:// resolved without a resolver";
  } catch (const std::runtime_error& e) {
    EXPECT_CONTAINS(e.what(), "package://my_pkg/a.ply");
    EXPECT_CONTAINS(e.what(), "ROS");
  }
  EXPECT_THROW(resolve_mesh_path("package://my_pkg", "/base", resolver), std::runtime_error);
  EXPECT_THROW(resolve_mesh_path("package:///a.ply", "/base", resolver), std::runtime_error);
  // A resolver that throws itself: its error reaches the caller.
  const PackageResolver throwing = [](const std::string& pkg) -> std::string {
    throw std::runtime_error("no package " + pkg);
  };
  EXPECT_THROW(resolve_mesh_path("package://x/a.ply", "/base", throwing), std::runtime_error);
}

TEST(ObjectConfig, PackageUrlInConfig) {
  const PackageResolver resolver = [](const std::string& pkg) { return "/ws/" + pkg; };
  const ObjectsConfig cfg = parse("objects:\n  - name: a\n    mesh: package://p/m/a.ply\n", resolver);
  EXPECT_EQ(cfg.objects[0].mesh, "package://p/m/a.ply");
  EXPECT_EQ(cfg.objects[0].mesh_path, "/ws/p/m/a.ply");
  // Without a resolver the config is rejected, naming the file, the object and the URL.
  const std::string err = parse_error("objects:\n  - name: a\n    mesh: package://p/m/a.ply\n");
  EXPECT_CONTAINS(err, "objects.yaml");
  EXPECT_CONTAINS(err, "'a'");
  EXPECT_CONTAINS(err, "package://p/m/a.ply");
}

TEST(ObjectConfig, ErrorsNameTheProblem) {
  struct Case {
    const char* what;
    std::string yaml;
    std::vector<std::string> mentions;
  };
  const std::vector<Case> cases = {
      {"unknown object key", "objects:\n  - name: a\n    mesh: a.ply\n    colour: red\n", {"objects.yaml", "colour"}},
      {"unknown top-level key", "objects:\n  - {name: a, mesh: a.ply}\nobjets: []\n", {"objets"}},
      {"duplicate name", "objects:\n  - {name: a, mesh: a.ply}\n  - {name: a, mesh: b.ply}\n", {"'a'", "twice"}},
      {"name with a dash", "objects:\n  - {name: my-box, mesh: a.ply}\n", {"objects[0]", "name", "my-box"}},
      {"name with a space", "objects:\n  - {name: 'my box', mesh: a.ply}\n", {"name", "my box"}},
      {"name starting with a digit", "objects:\n  - {name: 1box, mesh: a.ply}\n", {"name", "1box"}},
      {"missing name", "objects:\n  - {mesh: a.ply}\n", {"objects[0]", "name"}},
      {"missing mesh", "objects:\n  - {name: a}\n", {"'a'", "mesh", "required"}},
      {"empty mesh", "objects:\n  - {name: a, mesh: ''}\n", {"'a'", "mesh"}},
      {"zero scale", "objects:\n  - {name: a, mesh: a.ply, mesh_scale: 0}\n", {"'a'", "mesh_scale"}},
      {"negative scale", "objects:\n  - {name: a, mesh: a.ply, mesh_scale: -1}\n", {"'a'", "mesh_scale"}},
      {"NaN scale", "objects:\n  - {name: a, mesh: a.ply, mesh_scale: .nan}\n", {"'a'", "mesh_scale"}},
      {"text scale", "objects:\n  - {name: a, mesh: a.ply, mesh_scale: big}\n", {"objects[0]"}},
      {"bad mask label", "objects:\n  - {name: a, mesh: a.ply, mask_label: -2}\n", {"'a'", "mask_label"}},
      {"no instances", "objects:\n  - {name: a, mesh: a.ply, max_instances: 0}\n", {"'a'", "max_instances"}},
      {"too many instances", "objects:\n  - {name: a, mesh: a.ply, max_instances: 33}\n", {"'a'", "max_instances"}},
      {"instance name taken",
       "objects:\n  - {name: a, mesh: a.ply, max_instances: 2}\n  - {name: a_1, mesh: b.ply}\n",
       {"'a_1'", "instance 1 of 'a'"}},
      {"zero quaternion",
       "objects:\n  - name: a\n    mesh: a.ply\n    model_transform:\n      rotation: [0, 0, 0, 0]\n",
       {"objects[0]", "model_transform", "rotation", "zero quaternion"}},
      {"short quaternion",
       "objects:\n  - name: a\n    mesh: a.ply\n    model_transform:\n      rotation: [0, 0, 1]\n",
       {"model_transform", "rotation", "4"}},
      {"NaN quaternion",
       "objects:\n  - name: a\n    mesh: a.ply\n    model_transform:\n      rotation: [0, 0, .nan, 1]\n",
       {"model_transform", "rotation", "finite"}},
      {"short translation",
       "objects:\n  - name: a\n    mesh: a.ply\n    model_transform:\n      translation: [0, 1]\n",
       {"model_transform", "translation", "3"}},
      {"unknown transform key",
       "objects:\n  - name: a\n    mesh: a.ply\n    model_transform:\n      position: [0, 0, 0]\n",
       {"model_transform", "position"}},
      {"transform not a map", "objects:\n  - name: a\n    mesh: a.ply\n    model_transform: [0, 0, 0]\n",
       {"model_transform"}},
      {"objects not a list", "objects:\n  name: a\n  mesh: a.ply\n", {"objects.yaml", "objects", "list"}},
      {"objects a scalar", "objects: box\n", {"objects", "list"}},
      {"empty objects", "objects: []\n", {"objects", "list"}},
      {"no objects", "refiner:\n  iterations: 5\n", {"objects"}},
      {"object not a map", "objects:\n  - box\n", {"objects[0]", "mapping"}},
      {"root not a map", "- name: a\n", {"objects.yaml", "mapping"}},
      {"empty file", "", {"objects.yaml"}},
      {"invalid YAML", "objects: [\n", {"objects.yaml", "YAML"}},
      {"unknown refiner key", "refiner:\n  iteratons: 5\nobjects:\n  - {name: a, mesh: a.ply}\n",
       {"objects.yaml", "refiner", "iteratons"}},
      {"bad refiner value", "refiner:\n  iterations: many\nobjects:\n  - {name: a, mesh: a.ply}\n",
       {"objects.yaml", "refiner"}},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.what);
    const std::string err = parse_error(c.yaml);
    ASSERT_FALSE(err.empty()) << "accepted: " << c.yaml;
    for (const std::string& m : c.mentions) EXPECT_CONTAINS(err, m);
  }
}

TEST(ObjectConfig, LoadFromFileResolvesRelativeToIt) {
  ScratchDir dir;
  fs::create_directories(dir.path / "cfg");
  const std::string path = dir.write("cfg/objects.yaml",
                                     "refiner:\n  iterations: 9\nobjects:\n"
                                     "  - {name: a, mesh: meshes/a.ply}\n"
                                     "  - {name: b, mesh: ../b.ply}\n"
                                     "  - {name: c, mesh: /elsewhere/c.ply}\n"
                                     "  - {name: d, mesh: 'file:///x/d.ply'}\n");
  const ObjectsConfig cfg = load_objects_config(path);
  ASSERT_EQ(cfg.objects.size(), 4u);
  EXPECT_EQ(fs::path(cfg.objects[0].mesh_path), (dir.path / "cfg" / "meshes" / "a.ply").lexically_normal());
  EXPECT_EQ(fs::path(cfg.objects[1].mesh_path), (dir.path / "b.ply").lexically_normal());
  EXPECT_EQ(cfg.objects[2].mesh_path, "/elsewhere/c.ply");
  EXPECT_EQ(cfg.objects[3].mesh_path, "/x/d.ply");
  EXPECT_EQ(cfg.refiner.iterations, 9);
  // Mesh files are not opened while loading the config (a missing mesh disables one object, not all).
  EXPECT_FALSE(fs::exists(cfg.objects[0].mesh_path));
}

TEST(ObjectConfig, LoadErrorsNameTheFile) {
  ScratchDir dir;
  const std::string missing = (dir.path / "nope.yaml").string();
  try {
    load_objects_config(missing);
    FAIL() << "missing file accepted";
  } catch (const std::runtime_error& e) {
    EXPECT_CONTAINS(e.what(), missing);
  }
  const std::string bad = dir.write("bad.yaml", "objects:\n  - {name: a, mesh: a.ply, colour: red}\n");
  try {
    load_objects_config(bad);
    FAIL() << "unknown key accepted";
  } catch (const std::runtime_error& e) {
    EXPECT_CONTAINS(e.what(), bad);
    EXPECT_CONTAINS(e.what(), "colour");
  }
}

TEST(ObjectConfig, LoadObjectMeshAppliesScale) {
  ScratchDir dir;
  const Mesh box = make_box(Eigen::Vector3d(0.10, 0.05, 0.14), make_label_texture(64, 3));
  fs::create_directories(dir.path / "meshes");
  save_ply(box, (dir.path / "meshes" / "box.ply").string(), 1000.0);  // millimetres
  EXPECT_TRUE(fs::exists(dir.path / "meshes" / "box.png"));
  const std::string path = dir.write("objects.yaml",
                                     "objects:\n"
                                     "  - {name: box_mm, mesh: meshes/box.ply, mesh_scale: 0.001}\n"
                                     "  - {name: box_raw, mesh: meshes/box.ply}\n"
                                     "  - {name: gone, mesh: meshes/missing.ply}\n");
  const ObjectsConfig cfg = load_objects_config(path);
  const Mesh mm = load_object_mesh(cfg.objects[0]);
  EXPECT_NEAR(mm.diameter(), box.diameter(), 1e-6);
  EXPECT_TRUE(mm.has_texture());
  EXPECT_TRUE((mm.bbox_max() - mm.bbox_min()).isApprox(Eigen::Vector3d(0.10, 0.05, 0.14), 1e-5));
  const Mesh raw = load_object_mesh(cfg.objects[1]);
  EXPECT_NEAR(raw.diameter(), 1000.0 * box.diameter(), 1e-3);
  try {
    load_object_mesh(cfg.objects[2]);
    FAIL() << "missing mesh loaded";
  } catch (const std::runtime_error& e) {
    EXPECT_CONTAINS(e.what(), "missing.ply");
  }
}

TEST(ObjectConfig, ReadsDopesOwnConfigPose) {
  // DOPE's config_pose.yaml as DOPE ships it (abridged): the objects are those with a mesh; DOPE's own keys are
  // left to it; its model_transforms are already in the pose it publishes.
  const PackageResolver resolver = [](const std::string& pkg) { return "/ws/" + pkg; };
  const std::string dope = R"(
topic_camera: "/dope/webcam/image_raw"
topic_camera_info: "/dope/webcam/camera_info"
topic_publishing: "dope"
input_is_rectified: True
downscale_height: 400
weights: {"cracker": "package://dope/weights/cracker_60.pth", "soup": "package://dope/weights/soup_60.pth"}
architectures: {"cracker": "dope", "soup": "dope"}
dimensions: {"cracker": [16.4, 21.3, 7.2], "soup": [6.7, 10.2, 6.8]}
class_ids: {"cracker": 1, "soup": 3}
draw_colors: {"cracker": [13, 255, 128], "soup": [0, 0, 255]}
model_transforms: {"cracker": [[0, 0, 1, 0], [0, -1, 0, 0], [1, 0, 0, 0], [0, 0, 0, 1]]}
meshes: {"cracker": "file:///meshes/cracker/textured.obj", "soup": "package://dope/meshes/soup/textured.obj"}
mesh_scales: {"cracker": 0.01, "soup": 0.01}
thresh_angle: 0.5
)";
  const ObjectsConfig cfg = parse(dope, resolver);
  ASSERT_EQ(cfg.objects.size(), 2u);
  const ObjectConfig& cracker = cfg.objects[0];
  EXPECT_EQ(cracker.name, "cracker");
  EXPECT_EQ(cracker.mesh_path, "/meshes/cracker/textured.obj");
  EXPECT_DOUBLE_EQ(cracker.mesh_scale, 0.01);
  EXPECT_EQ(cracker.class_id, 1);
  EXPECT_EQ(cracker.pose_topic, "/dope/pose_cracker");
  EXPECT_TRUE(cracker.model_transform.R.isIdentity());  // DOPE applied it already
  EXPECT_EQ(cfg.objects[1].mesh_path, "/ws/dope/meshes/soup/textured.obj");
  EXPECT_EQ(cfg.objects[1].class_id, 3);
  const RefinerOptions d;
  EXPECT_EQ(cfg.refiner.iterations, d.iterations);
  // Another publishing namespace, no scales or ids: defaults.
  const ObjectsConfig other = parse("topic_publishing: my_dope\nmeshes: {box: box.ply}\n");
  EXPECT_EQ(other.objects[0].pose_topic, "/my_dope/pose_box");
  EXPECT_DOUBLE_EQ(other.objects[0].mesh_scale, 1.0);
  EXPECT_EQ(other.objects[0].class_id, -1);
  // Its values are checked as ours are, naming the file and the entry.
  EXPECT_CONTAINS(parse_error("meshes: {box: box.ply}\nmesh_scales: {box: -1}\n"), "'mesh_scale' must be positive");
  EXPECT_CONTAINS(parse_error("meshes: {box: box.ply}\nmesh_scales: {box: big}\n"), "meshes.box");
  EXPECT_CONTAINS(parse_error("meshes: {bad-name: box.ply}\n"), "'name' must be a non-empty identifier");
  EXPECT_CONTAINS(parse_error("meshes: [box.ply]\n"), "DOPE's 'meshes' must map");
  // Our own layout takes a class id too.
  EXPECT_EQ(parse("objects:\n  - {name: a, mesh: a.ply, class_id: 7}\n").objects[0].class_id, 7);
}
