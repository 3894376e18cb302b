// DOPE's own config_pose.yaml as the objects file, as DOPE ships it and as users edit it: which classes are
// refined, duplicate class ids, the mesh against DOPE's cuboid (scale and axes), mesh paths, and one-line errors
// that name the file and the key for every malformed entry. The files here are written for the tests, in the
// shape of DOPE's.
#include <gtest/gtest.h>

#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <string>

#include "diffdope/object_config.hpp"
#include "diffdope/primitives.hpp"
#include "diffdope/procedural.hpp"

namespace fs = std::filesystem;
using namespace diffdope;

namespace {

ObjectsConfig parse(const std::string& yaml) { return parse_objects_config(yaml, "config_pose.yaml", "/cfg"); }

std::string parse_error(const std::string& yaml) {
  try {
    parse(yaml);
  } catch (const std::runtime_error& e) {
    return e.what();
  }
  return "";
}

#define EXPECT_CONTAINS(haystack, needle) \
  EXPECT_NE(std::string(haystack).find(needle), std::string::npos) << "'" << (haystack) << "' lacks '" << (needle) << "'"

// DOPE's keys, with the detector's settings around the object maps as its file has them.
const std::string kHead = R"(topic_camera: "/dope/webcam/image_raw"
topic_camera_info: "/dope/webcam/camera_info"
topic_publishing: "dope"
input_is_rectified: True
downscale_height: 400
)";
const std::string kWeights = R"(weights: {
    "cracker": "package://dope/weights/cracker_60.pth",
    "sugar": "package://dope/weights/sugar_60.pth",
    "dressing": "package://dope/weights/dressing_60.pth",
    "cheese": "package://dope/weights/cheese_60.pth",
}
dimensions: {
    "cracker": [16.4, 21.3, 7.2],
    "sugar": [9.3, 17.6, 4.5],
    "dressing": [6.7, 19.5, 6.6],
    "cheese": [10.0, 4.5, 5.0],
    "ketchup": [14.9, 6.5, 4.0],
}
class_ids: {"cracker": 1, "sugar": 2, "dressing": 20, "cheese": 20, "ketchup": 5}
thresh_points: 0.1
)";

}  // namespace

TEST(DopeConfig, AsShippedItSaysWhatIsMissingAndBothFixes) {
  // As DOPE ships it, every mesh line is commented out: `meshes:` is empty, or absent.
  for (const std::string& meshes : {std::string("meshes:\n#    \"cracker\": \"file://path/to/cracker.ply\"\n"),
                                    std::string("# meshes: {}\n")}) {
    const std::string e = parse_error(kHead + kWeights + meshes);
    EXPECT_CONTAINS(e, "config_pose.yaml");
    EXPECT_CONTAINS(e, "every 'meshes' line is commented out");
    EXPECT_CONTAINS(e, "uncomment 'meshes'");
    EXPECT_CONTAINS(e, "own layout");
    EXPECT_EQ(e.find('\n'), std::string::npos) << "one line: " << e;
  }
}

TEST(DopeConfig, ObjectsAreTheClassesWithWeightsAndAMesh) {
  const ObjectsConfig cfg = parse(kHead + kWeights + R"(meshes: {
    "sugar": "meshes/sugar.ply",
    "cracker": "/m/cracker.ply",
    "ketchup": "/m/ketchup.ply",
}
mesh_scales: {"cracker": 0.01, "sugar": 0.01, "ketchup": 0.01}
)");
  ASSERT_EQ(cfg.objects.size(), 2u);
  EXPECT_EQ(cfg.objects[0].name, "sugar");  // the file's order
  EXPECT_EQ(cfg.objects[0].mesh_path, "/cfg/meshes/sugar.ply");
  EXPECT_EQ(cfg.objects[1].name, "cracker");
  EXPECT_EQ(cfg.objects[1].class_id, 1);
  EXPECT_TRUE(cfg.objects[1].cuboid_extent.isApprox(Eigen::Vector3d(0.164, 0.213, 0.072)));
  EXPECT_EQ(cfg.detected_not_refined, (std::vector<std::string>{"cheese", "dressing"}));
  EXPECT_EQ(cfg.meshes_without_weights, (std::vector<std::string>{"ketchup"}));
  // Meshes but no class DOPE detects: an error naming both lists.
  const std::string e = parse_error(kHead + kWeights + "meshes: {ketchup: /m/ketchup.ply}\n");
  EXPECT_CONTAINS(e, "no object has both DOPE's weights");
  EXPECT_CONTAINS(e, "ketchup");
  EXPECT_CONTAINS(e, "cracker");
  // Without `weights` (a file trimmed to what the refiner needs) every mesh is refined.
  EXPECT_EQ(parse("meshes: {a: a.ply, b: b.ply}\n").objects.size(), 2u);
}

TEST(DopeConfig, DuplicateClassIdsAreAnErrorNamingBoth) {
  // dressing and cheese share id 20: refining either would take the other's detections.
  const std::string e = parse_error(kHead + kWeights + "meshes: {dressing: /m/d.ply}\n");
  EXPECT_CONTAINS(e, "config_pose.yaml");
  EXPECT_CONTAINS(e, "cheese, dressing share the id 20");
  // Refining neither, the shared id harms nothing.
  EXPECT_NO_THROW(parse(kHead + kWeights + "meshes: {cracker: /m/c.ply}\n"));
  // This package's own layout checks the same.
  const std::string ours = parse_error("objects:\n  - {name: a, mesh: a.ply, class_id: 3}\n"
                                       "  - {name: b, mesh: b.ply, class_id: 3}\n");
  EXPECT_CONTAINS(ours, "objects 'a' and 'b' share the class id 3");
}

TEST(DopeConfig, ANodesClassIdsOverrideTheFilesAndMayNotCollide) {
  const ObjectsConfig cfg = parse(kHead + kWeights + "meshes: {cracker: /m/c.ply, sugar: /m/s.ply}\n");
  const std::map<std::string, int64_t> ids = object_class_ids(cfg.objects, {}, "cfg");
  ASSERT_EQ(ids, (std::map<std::string, int64_t>{{"cracker", 1}, {"sugar", 2}}));
  // An override (the node's ~class_ids) wins over the file's id, and names may be of no object.
  const std::map<std::string, int64_t> moved = object_class_ids(cfg.objects, {{"cracker", 90}, {"other", 7}}, "cfg");
  EXPECT_EQ(moved.at("cracker"), 90);
  EXPECT_EQ(moved.at("sugar"), 2);
  EXPECT_EQ(moved.at("other"), 7);
  // One that gives a refined object the id of another is an error naming both and where the ids came from.
  try {
    object_class_ids(cfg.objects, {{"cracker", 2}}, "x.yaml with ~class_ids");
    FAIL() << "two objects with one id";
  } catch (const std::runtime_error& e) {
    EXPECT_CONTAINS(std::string(e.what()), "x.yaml with ~class_ids");
    EXPECT_CONTAINS(std::string(e.what()), "'cracker' and 'sugar' share the class id 2");
  }
}

TEST(DopeConfig, TheClassesNotRefinedAreSaidInOneLine) {
  // DOPE detects cheese and dressing (weights) without a mesh; a mesh of a class without weights is never detected.
  const ObjectsConfig cfg = parse(kHead + kWeights + "meshes: {cracker: /m/c.ply, ketchup: /m/k.ply}\n");
  EXPECT_EQ(unrefined_classes(cfg), "detected by DOPE but not refined (no mesh): cheese, dressing, sugar; meshes "
                                    "without weights (never detected, not refined): ketchup");
  EXPECT_EQ(unrefined_classes(parse("meshes: {a: a.ply}\n")), "") << "every class refined: nothing to say";
}

TEST(DopeConfig, FileUrlsAreAbsoluteAndRelativePathsFollowTheFile) {
  EXPECT_EQ(parse("meshes: {a: 'file:///m/a.ply'}\n").objects[0].mesh_path, "/m/a.ply");
  const std::string e = parse_error("meshes: {a: 'file://meshes/a.ply'}\n");
  EXPECT_CONTAINS(e, "config_pose.yaml");
  EXPECT_CONTAINS(e, "file:///path/to/mesh");
  EXPECT_CONTAINS(e, "without file://");
  // Relative to the file's folder, whatever the working directory.
  const fs::path before = fs::current_path();
  fs::current_path(fs::temp_directory_path());
  EXPECT_EQ(parse("meshes: {a: sub/a.ply}\n").objects[0].mesh_path, "/cfg/sub/a.ply");
  fs::current_path(before);
}

TEST(DopeConfig, MalformedEntriesGetOneLineNamingFileAndKey) {
  const std::string m = "meshes: {a: a.ply}\n";
  const struct {
    std::string yaml, key;
  } cases[] = {
      {m + "mesh_scales: {a: 0}\n", "'mesh_scale' must be positive"},
      {m + "mesh_scales: {a: .nan}\n", "'mesh_scale' must be positive"},
      {m + "mesh_scales: {a: [1]}\n", "meshes.a"},
      {m + "mesh_scales: [1]\n", "'mesh_scales' must map"},
      {m + "class_ids: {a: x}\n", "meshes.a"},
      {m + "dimensions: {a: [1, 2]}\n", "dimensions.a"},
      {m + "dimensions: {a: [1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12]}\n", "dimensions.a"},
      {m + "dimensions: {a: [1, 0, 3]}\n", "dimensions.a"},
      {m + "dimensions: {a: [1, .inf, 3]}\n", "dimensions.a"},
      {m + "dimensions: {a: [1, 1e9, 3]}\n", "dimensions.a"},
      {m + "dimensions: {a: 5}\n", "dimensions.a"},
      {m + "model_transforms: {a: [[1, 0, 0, 0], [0, 1, 0, 0]]}\n", "model_transforms.a"},
      {m + "model_transforms: {a: [[2, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]}\n", "not a rotation"},
      {m + "weights: [a]\n", "'weights' must map"},
      {"meshes: {a: [x]}\n", "meshes.a"},
      {"weights: {a: w.pth}\nmeshes: 3\n", "'meshes' must map"},
  };
  for (const auto& c : cases) {
    const std::string e = parse_error(c.yaml);
    EXPECT_CONTAINS(e, "config_pose.yaml");
    EXPECT_CONTAINS(e, c.key);
    EXPECT_EQ(e.find('\n'), std::string::npos) << c.yaml;
  }
}

namespace {
ObjectConfig with_cuboid(const Eigen::Vector3d& cm, double mesh_scale = 1.0) {
  ObjectConfig o;
  o.name = "cracker";
  o.mesh_scale = mesh_scale;
  o.cuboid_extent = cm / 100.0;
  return o;
}
}  // namespace

TEST(DopeConfig, AMeshWithinFifteenPercentOfItsCuboidFits) {
  const Eigen::Vector3d cm(16.4, 21.3, 7.2), m = cm / 100.0;
  // A handle, a cap, a scan's rough base: each side up to 15 % off, either way.
  for (const Eigen::Vector3d& f : {Eigen::Vector3d(1, 1, 1), Eigen::Vector3d(1.15, 0.87, 1.1),
                                   Eigen::Vector3d(0.87, 1.15, 0.9)})
    EXPECT_EQ(cuboid_mismatch(m.cwiseProduct(f), with_cuboid(cm)), "") << f.transpose();
  EXPECT_EQ(cuboid_mismatch(m, ObjectConfig()), "");  // no cuboid: nothing to check
  // Its model_transforms turns the mesh's axes into the cuboid's: a mesh with x and z swapped fits through it.
  ObjectConfig turned = with_cuboid(cm);
  turned.cuboid_from_mesh << 0, 0, 1, 0, -1, 0, 1, 0, 0;
  EXPECT_EQ(cuboid_mismatch(Eigen::Vector3d(m.z(), m.y(), m.x()), turned), "");
  EXPECT_NE(cuboid_mismatch(m, turned), "");
}

TEST(DopeConfig, AUnitMistakeNamesTheLikelyMeshScale) {
  const Eigen::Vector3d cm(16.4, 21.3, 7.2), m = cm / 100.0;
  // A centimetre mesh read as metres (mesh_scales forgotten): 100 times the cuboid.
  const std::string e = cuboid_mismatch(100.0 * m.cwiseProduct(Eigen::Vector3d(1.1, 0.9, 1.05)), with_cuboid(cm));
  EXPECT_CONTAINS(e, "object 'cracker'");
  EXPECT_CONTAINS(e, "100 times");
  EXPECT_CONTAINS(e, "mesh_scales: {cracker: 0.01}");
  EXPECT_CONTAINS(cuboid_mismatch(1000.0 * m, with_cuboid(cm)), "mesh_scales: {cracker: 0.001}");
  EXPECT_CONTAINS(cuboid_mismatch(0.1 * m, with_cuboid(cm, 0.01)), "mesh_scales: {cracker: 0.1}");
}

TEST(DopeConfig, AxesInAnotherOrderNameTheModelTransform) {
  const Eigen::Vector3d cm(16.4, 21.3, 7.2), m = cm / 100.0;
  const std::string e = cuboid_mismatch(Eigen::Vector3d(m.z(), m.x(), m.y()) * 1.05, with_cuboid(cm));
  EXPECT_CONTAINS(e, "in another order");
  EXPECT_CONTAINS(e, "model_transforms: {cracker: [[");
  // The matrix named makes the mesh fit.
  const size_t at = e.find("[[");
  ObjectConfig fixed = with_cuboid(cm);
  double v[16];
  ASSERT_EQ(std::sscanf(e.c_str() + at, "[[%lf, %lf, %lf, %lf], [%lf, %lf, %lf, %lf], [%lf, %lf, %lf, %lf], [%lf, %lf, %lf, %lf]]",
                        &v[0], &v[1], &v[2], &v[3], &v[4], &v[5], &v[6], &v[7], &v[8], &v[9], &v[10], &v[11], &v[12],
                        &v[13], &v[14], &v[15]), 16) << e;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) fixed.cuboid_from_mesh(r, c) = v[4 * r + c];
  EXPECT_NEAR(fixed.cuboid_from_mesh.determinant(), 1.0, 1e-12);
  EXPECT_EQ(cuboid_mismatch(Eigen::Vector3d(m.z(), m.x(), m.y()) * 1.05, fixed), "");
  // Anything else: both extents, and what to check.
  const std::string other = cuboid_mismatch(Eigen::Vector3d(0.5, 0.2, 0.07), with_cuboid(cm));
  EXPECT_CONTAINS(other, "dimensions 0.164 x 0.213 x 0.072 m");
  EXPECT_CONTAINS(other, "check the mesh");
}

TEST(DopeConfig, LoadingAMeshChecksItAgainstTheCuboid) {
  const fs::path dir = fs::temp_directory_path() / ("diffdope_dope_config_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  save_ply(make_box(Eigen::Vector3d(0.164, 0.213, 0.072), make_label_texture(32, 1)), (dir / "box.ply").string(),
           100.0);  // centimetres, as DOPE's own meshes
  const std::string yaml = "weights: {box: w.pth}\ndimensions: {box: [16.4, 21.3, 7.2]}\nmeshes: {box: box.ply}\n";
  const ObjectsConfig forgot = parse_objects_config(yaml, "config_pose.yaml", dir.string());
  try {
    load_object_mesh(forgot.objects[0]);
    ADD_FAILURE() << "a centimetre mesh read as metres loaded";
  } catch (const std::runtime_error& e) {
    EXPECT_CONTAINS(e.what(), (dir / "box.ply").string());
    EXPECT_CONTAINS(e.what(), "mesh_scales: {box: 0.01}");
  }
  const ObjectsConfig right =
      parse_objects_config(yaml + "mesh_scales: {box: 0.01}\n", "config_pose.yaml", dir.string());
  EXPECT_NO_THROW(load_object_mesh(right.objects[0]));
  fs::remove_all(dir);
}

// The file the error for DOPE's file as shipped points to reads as it says.
TEST(DopeConfig, TheExampleObjectsFileReads) {
  const ObjectsConfig cfg =
      load_objects_config(std::string(DIFFDOPE_SOURCE_DIR) + "/config/objects.example.yaml",
                          [](const std::string& pkg) { return "/ws/" + pkg; });
  ASSERT_EQ(cfg.objects.size(), 2u);
  EXPECT_EQ(cfg.objects[0].name, "cracker");
  EXPECT_DOUBLE_EQ(cfg.objects[0].mesh_scale, 0.01);
  EXPECT_EQ(cfg.objects[1].mesh_path, "/ws/my_meshes/mustard/textured.obj");
  EXPECT_EQ(cfg.objects[1].pose_topic, "/my_detector/mustard");
  EXPECT_EQ(cfg.refiner.iterations, 60);
}

TEST(DopeConfig, ReadsWhetherDopesInputIsRectified) {
  EXPECT_FALSE(parse("meshes: {a: a.ply}\n").input_is_rectified.has_value());
  EXPECT_EQ(parse("input_is_rectified: True\nmeshes: {a: a.ply}\n").input_is_rectified, std::optional<bool>(true));
  EXPECT_EQ(parse("input_is_rectified: False\nmeshes: {a: a.ply}\n").input_is_rectified, std::optional<bool>(false));
  const std::string e = parse_error("input_is_rectified: maybe\nmeshes: {a: a.ply}\n");
  EXPECT_CONTAINS(e, "config_pose.yaml");
  EXPECT_CONTAINS(e, "input_is_rectified");
  // This package's own layout has no such key.
  EXPECT_FALSE(parse_objects_config("objects:\n  - {name: a, mesh: a.ply}\n", "o.yaml", "/d").input_is_rectified);
}
