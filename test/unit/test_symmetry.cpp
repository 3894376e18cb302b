// Declared symmetries (symmetry.hpp): canonical poses, what the refiner skips, how they are read.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>

#include "diffdope/device.hpp"
#include "diffdope/object_config.hpp"
#include "diffdope/procedural.hpp"
#include "diffdope/refiner.hpp"
#include "diffdope/synthetic.hpp"
#include "labelled_can.hpp"

using namespace diffdope;

namespace {

Eigen::Matrix3d rot(double deg, const Eigen::Vector3d& axis) {
  return Eigen::AngleAxisd(deg * M_PI / 180, axis.normalized()).toRotationMatrix();
}
double deg(double rad) { return rad * 180 / M_PI; }

ObjectSymmetry about_z() {
  ObjectSymmetry s;
  s.continuous.push_back({Eigen::Vector3d::UnitZ(), Eigen::Vector3d::Zero()});
  return s;
}

}  // namespace

TEST(Symmetry, ContinuousAxisEveryTurnHasOneCanonicalPose) {
  const ObjectSymmetry sym = about_z();
  const Pose p(rot(50, {1, 2, 0.5}), Eigen::Vector3d(0.1, 0, 0.6));
  const Pose canonical = sym.nearest_equivalent(p, ObjectSymmetry::canonical_reference());
  for (const double turn : {17.0, 90.0, 181.0, -123.0}) {
    const Pose q = p * Pose(rot(turn, Eigen::Vector3d::UnitZ()), Eigen::Vector3d::Zero());
    const Pose c = sym.nearest_equivalent(q, ObjectSymmetry::canonical_reference());
    EXPECT_LT(deg(rotation_angle(c.R, canonical.R)), 1e-4) << turn;  // (acos's own precision)
    EXPECT_LT((c.t - q.t).norm(), 1e-12);  // the axis passes through the origin: the position stays
    EXPECT_LT((c.R.col(2) - q.R.col(2)).norm(), 1e-9);  // the same axis in the camera: an equivalent pose
  }
  // Nearest to a reference (a track's last pose): a pose turned about the axis comes back to it.
  const Pose turned = p * Pose(rot(140, Eigen::Vector3d::UnitZ()), Eigen::Vector3d::Zero());
  EXPECT_LT(deg(rotation_angle(sym.nearest_equivalent(turned, p.R).R, p.R)), 1e-4);
}

TEST(Symmetry, AnOffsetAxisTurnsAboutItsOwnLine) {
  ObjectSymmetry sym;
  sym.continuous.push_back({Eigen::Vector3d::UnitZ(), Eigen::Vector3d(0.02, 0, 0)});
  const Pose p(rot(20, {0, 1, 0}), Eigen::Vector3d(0, 0, 0.5));
  const Pose turned = p * Pose(rot(90, Eigen::Vector3d::UnitZ()), Eigen::Vector3d(0.02, -0.02, 0));  // about (0.02, 0, z)
  const Pose back = sym.nearest_equivalent(turned, p.R);
  EXPECT_LT(deg(rotation_angle(back.R, p.R)), 1e-4);
  EXPECT_LT((back.t - p.t).norm(), 1e-9);
}

TEST(Symmetry, DiscreteFlipsPickTheNearestAndContainsKnowsThem) {
  ObjectSymmetry sym;
  sym.discrete.push_back(Pose(rot(180, Eigen::Vector3d::UnitX()), Eigen::Vector3d::Zero()));
  const Pose p(rot(30, {0, 0, 1}), Eigen::Vector3d(0, 0, 0.5));
  const Pose flipped = p * sym.discrete[0];
  EXPECT_LT(deg(rotation_angle(sym.nearest_equivalent(flipped, p.R).R, p.R)), 1e-4);
  EXPECT_LT(deg(rotation_angle(sym.nearest_equivalent(p, flipped.R).R, flipped.R)), 1e-4);
  EXPECT_TRUE(sym.contains(sym.discrete[0], 0.1, 0.001, 0.1));
  EXPECT_FALSE(sym.contains(Pose(rot(180, Eigen::Vector3d::UnitY()), Eigen::Vector3d::Zero()), 0.1, 0.001, 0.1));
  EXPECT_FALSE(sym.contains(Pose(rot(30, Eigen::Vector3d::UnitX()), Eigen::Vector3d::Zero()), 0.1, 0.001, 0.1));
  const ObjectSymmetry z = about_z();
  EXPECT_TRUE(z.contains(Pose(rot(30, Eigen::Vector3d::UnitZ()), Eigen::Vector3d::Zero()), 0.1, 0.001, 0.1));
  EXPECT_FALSE(z.contains(Pose(rot(180, Eigen::Vector3d::UnitX()), Eigen::Vector3d::Zero()), 0.1, 0.001, 0.1));
}

TEST(Symmetry, MalformedDeclarationsAreRefusedByName) {
  ObjectSymmetry zero;
  zero.continuous.push_back({Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero()});
  EXPECT_THROW(zero.validate_and_normalise("obj"), std::invalid_argument);
  ObjectSymmetry sheared;
  Eigen::Matrix3d M = Eigen::Matrix3d::Identity();
  M(0, 1) = 0.5;
  sheared.discrete.push_back(Pose(M, Eigen::Vector3d::Zero()));
  EXPECT_THROW(sheared.validate_and_normalise("obj"), std::invalid_argument);
  ObjectSymmetry nan;
  nan.continuous.push_back({Eigen::Vector3d(0, 0, NAN), Eigen::Vector3d::Zero()});
  EXPECT_THROW(nan.validate_and_normalise("obj"), std::invalid_argument);
  ObjectSymmetry ok;
  ok.continuous.push_back({Eigen::Vector3d(0, 0, 2), Eigen::Vector3d::Zero()});
  ok.validate_and_normalise("obj");
  EXPECT_DOUBLE_EQ(ok.continuous[0].direction.norm(), 1.0);
}

TEST(Symmetry, TheObjectsConfigDeclaresThem) {
  const std::string yaml = R"(objects:
  - name: can
    mesh: /nonexistent/can.ply
    symmetries:
      continuous: [{axis: [0, 0, 1], offset: [0, 0, 0.05]}]
      discrete: [{translation: [0, 0, 0.1], rotation: [1, 0, 0, 0]}]
)";
  const ObjectsConfig c = parse_objects_config(yaml, "test.yaml", "/tmp");
  ASSERT_EQ(c.objects.size(), 1u);
  const ObjectSymmetry& s = c.objects[0].symmetries;
  ASSERT_EQ(s.continuous.size(), 1u);
  ASSERT_EQ(s.discrete.size(), 1u);
  EXPECT_TRUE(c.objects[0].symmetric);  // declared symmetries are scored with ADD-S
  EXPECT_NEAR(s.continuous[0].offset.z(), 0.05, 1e-12);
  EXPECT_NEAR(deg(rotation_angle(s.discrete[0].R, Eigen::Matrix3d::Identity())), 180, 1e-9);
  const auto refused = [](const std::string& body, const std::string& says) {
    const std::string y = "objects:\n  - name: can\n    mesh: /x.ply\n    symmetries: " + body + "\n";
    try {
      parse_objects_config(y, "test.yaml", "/tmp");
      ADD_FAILURE() << body;
    } catch (const std::runtime_error& e) {
      EXPECT_NE(std::string(e.what()).find(says), std::string::npos) << e.what();
    }
  };
  refused("{continuous: [{axis: [0, 0, 0]}]}", "non-zero");
  refused("{continuous: [{axis: [0, 0]}]}", "3 numbers");
  refused("{continous: []}", "unknown key 'continous'");
  refused("{discrete: [{rotation: [0, 0, 0, 0]}]}", "zero quaternion");
  refused("[1, 2]", "expected continuous");
}

TEST(Symmetry, TheRefinerDoesNotScanDeclaredTurnsAndReportsTheTurnNearestItsStart) {
  // A labelled can started half a turn off about its axis (undeclared, the scan turns it to its label:
  // Refiner.ARollOnlyTheLabelShowsIsFoundByTheShapeScan). Declared symmetric (about its axis, and end over end),
  // no turn is tried and the result keeps the start's turn (a track does not spin), while its axis and position
  // are still refined.
  test::LabelledCan s = test::labelled_can();
  const Pose half_turn = s.truth * test::about_can_axis(180);
  RefinerOptions o;
  o.batch_size = 16;
  o.iterations = 40;
  o.image_scale = 1.0;
  s.can.symmetry = about_z();
  s.can.symmetry.discrete.push_back(Pose(rot(180, Eigen::Vector3d::UnitX()), Eigen::Vector3d::Zero()));
  // Off by 4 degrees (not about the axis) and 4 mm.
  const Pose start(rot(4, {1, 1, 0}) * half_turn.R, half_turn.t + Eigen::Vector3d(0.004, 0, 0));
  const RefineResult declared = Refiner(o).refine(s.cam, s.obs, s.can, start);
  EXPECT_EQ(declared.scan_turns, 0);
  EXPECT_LT(deg(rotation_angle(declared.pose.R, half_turn.R)), 5.0);
  EXPECT_LT(deg(std::acos(std::min(1.0, declared.pose.R.col(2).dot(s.truth.R.col(2))))), 1.5);  // the axis
  EXPECT_LT((declared.pose.t - s.truth.t).norm(), 0.002);
}
