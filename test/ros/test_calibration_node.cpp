// rostest (calibration.test, calibration_eye_in_hand.test): the calibration node on a bag of the generated arm
// holding still in four configurations and moving between them, watched by a camera on a stand or on its hand.
// Samples are refused while it moves or has not moved; four samples from a guess 5 cm / 10 degrees off
// calibrate the camera within 2 mm / 0.2 degrees; the static TF and the saved YAML carry the result; samples
// can be removed; a joint state the node cannot use is the cause its reply gives. ~mount_frame: the frame the result is in (base_link; link5 eye in hand).
#include <gtest/gtest.h>
#include <ros/ros.h>
#include <sensor_msgs/JointState.h>
#include <std_srvs/Trigger.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/static_transform_broadcaster.h>
#include <tf2_ros/transform_listener.h>

#include <fstream>
#include <sstream>

#include "diffdope_ros/ComputeCalibration.h"
#include "diffdope_ros/RemoveSample.h"
#include "diffdope_ros/conversions.hpp"

namespace {

const std::string kNode = "/diffdope_calibration/";

double angle_deg(const diffdope::Pose& a, const diffdope::Pose& b) {
  return Eigen::AngleAxisd(a.R * b.R.transpose()).angle() * 180.0 / M_PI;
}

}  // namespace

TEST(CalibrationNode, SamplesComputeTfAndSave) {
  ros::NodeHandle nh;
  const std::string mount = ros::NodeHandle("~").param<std::string>("mount_frame", "base_link");
  const bool eye_in_hand = mount != "base_link";
  ASSERT_TRUE(ros::service::waitForService(kNode + "take_sample", ros::Duration(30)));
  std::vector<double> truth;
  ASSERT_TRUE(nh.getParam("/truth", truth));
  ASSERT_EQ(truth.size(), 7u);
  const diffdope::Pose base_from_camera_true =
      diffdope::Pose::from_quaternion(truth[3], truth[4], truth[5], truth[6], Eigen::Vector3d(truth[0], truth[1], truth[2]));

  // Ask for a sample every 0.2 s while the bag plays: its four still phases give one each, the rest is refused.
  int taken = 0;
  std::vector<std::string> refusals;
  const ros::WallTime end = ros::WallTime::now() + ros::WallDuration(60);
  while (taken < 4 && ros::WallTime::now() < end) {
    std_srvs::Trigger t;
    ASSERT_TRUE(ros::service::call(kNode + "take_sample", t));
    if (t.response.success) ++taken;
    else refusals.push_back(t.response.message);
    ros::WallDuration(0.2).sleep();
  }
  ASSERT_EQ(taken, 4) << "samples taken; refusals: " << (refusals.empty() ? "" : refusals.back());
  bool moving = false, same = false;
  for (const auto& r : refusals) {
    moving = moving || r.find("the robot is moving") != std::string::npos;
    same = same || r.find("in the configuration of sample") != std::string::npos;
  }
  EXPECT_TRUE(moving) << "no sample was refused while the arm moved";
  EXPECT_TRUE(same) << "no sample was refused for repeating a configuration";

  diffdope_ros::ComputeCalibration c;
  ASSERT_TRUE(ros::service::call(kNode + "compute", c));
  ASSERT_TRUE(c.response.success) << c.response.message;
  EXPECT_TRUE(c.response.plausible);
  ASSERT_EQ(c.response.residuals.size(), 4u);
  const diffdope::Pose got = diffdope_ros::pose_from_transform(c.response.transform.transform, "result");
  const double mm = 1e3 * (got.t - base_from_camera_true.t).norm(), deg = angle_deg(got, base_from_camera_true);
  std::printf("calibration node: %s; error %.2f mm, %.3f deg\n", c.response.message.c_str(), mm, deg);
  EXPECT_LT(mm, 2.0);
  EXPECT_LT(deg, 0.2);
  EXPECT_EQ(c.response.transform.header.frame_id, mount);
  EXPECT_GT(c.response.position_std, 0);
  EXPECT_EQ(c.response.transform.child_frame_id, "camera_color_optical_frame");

  // The static TF carries it, published to the optical frame's parent (camera_link, the "driver's").
  EXPECT_NE(c.response.message.find("published on TF as " + mount + " -> camera_link"), std::string::npos)
      << c.response.message;
  tf2_ros::Buffer tf;
  tf2_ros::TransformListener listener(tf);
  // (Polled in wall time: the bag has ended, so simulated time no longer moves.)
  for (int i = 0; i < 50 && !tf.canTransform(mount, "camera_color_optical_frame", ros::Time(0)); ++i)
    ros::WallDuration(0.1).sleep();
  geometry_msgs::TransformStamped t;
  ASSERT_NO_THROW(t = tf.lookupTransform(mount, "camera_color_optical_frame", ros::Time(0)));
  const diffdope::Pose on_tf = diffdope_ros::pose_from_transform(t.transform, "tf");
  EXPECT_LT((on_tf.t - got.t).norm(), 1e-6);

  // Saved in easy_handeye's layout.
  std_srvs::Trigger save;
  ASSERT_TRUE(ros::service::call(kNode + "save", save));
  ASSERT_TRUE(save.response.success) << save.response.message;
  std::string file;
  ASSERT_TRUE(nh.getParam(kNode + "output_file", file));
  std::ifstream in(file);
  std::stringstream yaml;
  yaml << in.rdbuf();
  EXPECT_NE(yaml.str().find(eye_in_hand ? "eye_on_hand: true" : "eye_on_hand: false"), std::string::npos) << yaml.str();
  EXPECT_NE(yaml.str().find((eye_in_hand ? "robot_effector_frame: " : "robot_base_frame: ") + mount), std::string::npos)
      << yaml.str();
  EXPECT_NE(yaml.str().find("tracking_base_frame: camera_color_optical_frame"), std::string::npos) << yaml.str();

  diffdope_ros::RemoveSample remove;
  remove.request.index = -1;
  ASSERT_TRUE(ros::service::call(kNode + "remove_sample", remove));
  EXPECT_TRUE(remove.response.success);
  EXPECT_EQ(remove.response.remaining, 3);
  remove.request.index = 7;
  ASSERT_TRUE(ros::service::call(kNode + "remove_sample", remove));
  EXPECT_FALSE(remove.response.success);
  EXPECT_NE(remove.response.message.find("no sample 7"), std::string::npos);
}

// Joint states the node cannot use are named in ~take_sample's reply, not only in the log. First a reading of a
// joint the robot does not have, stamped at 1 s (the clock "went back": the history restarts and keeps
// nothing of it), then one with a NaN position: the reply says both that no usable state is there and why.
TEST(CalibrationNode, ARejectedJointStateIsTheCauseTheReplyGives) {
  ros::NodeHandle nh;
  ros::Publisher joints = nh.advertise<sensor_msgs::JointState>("/joint_states", 5);
  for (int i = 0; i < 100 && joints.getNumSubscribers() == 0; ++i) ros::WallDuration(0.05).sleep();
  ASSERT_GT(joints.getNumSubscribers(), 0u);
  ASSERT_GT(ros::Time::now().toSec(), 20.0) << "the bag's clock starts too early for this test";
  const ros::Time back(1.0);
  sensor_msgs::JointState ghost;
  ghost.header.stamp = back;
  ghost.name = {"ghost_joint"};
  ghost.position = {0.1};
  joints.publish(ghost);
  sensor_msgs::JointState broken;
  broken.header.stamp = back + ros::Duration(0.1);
  broken.name = {"joint1", "joint2"};
  broken.position = {0.2, std::numeric_limits<double>::quiet_NaN()};
  joints.publish(broken);
  std::string reply;
  for (int i = 0; i < 50 && reply.find("ignored") == std::string::npos; ++i) {
    ros::WallDuration(0.1).sleep();
    std_srvs::Trigger t;
    ASSERT_TRUE(ros::service::call(kNode + "take_sample", t));
    EXPECT_FALSE(t.response.success);
    reply = t.response.message;
  }
  EXPECT_NE(reply.find("no joint states received"), std::string::npos) << reply;
  EXPECT_NE(reply.find("the latest joint_states message was ignored: joint 'joint2' is not finite"), std::string::npos)
      << reply;
}

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_calibration_node");
  ros::NodeHandle nh;
  ros::AsyncSpinner spinner(1);
  spinner.start();
  // As a camera driver does: camera_link -> optical frame (REP 103: the optical z is camera_link's x). The node
  // must then publish the calibration as base_link (or the hand's link) -> camera_link. (Debian's tf2_ros has no
  // static_transform_publisher executable, so the test publishes it.)
  tf2_ros::StaticTransformBroadcaster driver;
  geometry_msgs::TransformStamped t;
  t.header.stamp = ros::Time::now();
  t.header.frame_id = "camera_link";
  t.child_frame_id = "camera_color_optical_frame";
  t.transform.translation.x = 0.01, t.transform.translation.y = 0.02;
  t.transform.rotation.x = -0.5, t.transform.rotation.y = 0.5, t.transform.rotation.z = -0.5, t.transform.rotation.w = 0.5;
  driver.sendTransform(t);
  return RUN_ALL_TESTS();
}
