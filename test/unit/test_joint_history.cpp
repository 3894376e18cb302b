// JointHistory (joint_history.hpp): the joints that go with an image, and refusing images taken while moving.
#include <gtest/gtest.h>

#include "diffdope/joint_history.hpp"

using namespace diffdope;

namespace {

JointReading reading(double t, double q, double v = 0, bool with_velocity = false) {
  JointReading r;
  r.stamp = t;
  r.position = {{"a", q}, {"b", 0.5}};
  if (with_velocity) r.velocity = {{"a", v}, {"b", 0.0}};
  return r;
}

}  // namespace

TEST(JointHistory, StillRobotGivesTheNearestPositions) {
  JointHistory h;
  for (int k = 0; k <= 100; ++k) h.add(reading(10.0 + 0.01 * k, 1.0 + 1e-5 * k));  // 0.001 rad/s: still
  std::string why;
  const auto q = h.still_at(10.5, &why);
  ASSERT_TRUE(q.has_value()) << why;
  EXPECT_NEAR(q->at("a"), 1.0005, 1e-9);
  EXPECT_DOUBLE_EQ(q->at("b"), 0.5);
}

TEST(JointHistory, RefusesWhatItCannotVouchFor) {
  JointHistory h;
  std::string why;
  EXPECT_FALSE(h.still_at(10.0, &why));
  EXPECT_NE(why.find("no joint states"), std::string::npos);
  // Moving at 0.5 rad/s (positions only), then still.
  for (int k = 0; k <= 100; ++k) h.add(reading(10.0 + 0.01 * k, k <= 50 ? 0.005 * k : 0.25));
  EXPECT_FALSE(h.still_at(10.3, &why));
  EXPECT_NE(why.find("moving: joint 'a' travelled"), std::string::npos) << why;
  EXPECT_TRUE(h.still_at(10.75, &why)) << why;
  // The window after the image is not covered yet.
  EXPECT_FALSE(h.still_at(10.95, &why));
  EXPECT_NE(why.find("do not yet cover"), std::string::npos) << why;
  // No reading near the stamp (another clock?).
  EXPECT_FALSE(h.still_at(20.0, &why));
  EXPECT_NE(why.find("no joint state within"), std::string::npos) << why;
  EXPECT_FALSE(h.still_at(5.0, &why));  // long before every reading
  EXPECT_NE(why.find("no state of joint 'a' within"), std::string::npos) << why;
}

TEST(JointHistory, ReportedVelocitiesCountAndOldReadingsGo) {
  StillnessOptions o;
  o.keep = 2.0;
  JointHistory h(o);
  for (int k = 0; k <= 100; ++k) h.add(reading(10.0 + 0.01 * k, 1.0, k == 50 ? 0.2 : 0.0, true));
  std::string why;
  EXPECT_FALSE(h.still_at(10.5, &why));
  EXPECT_NE(why.find("joint 'a' at 0.2"), std::string::npos) << why;
  h.add(reading(13.0, 1.0));  // three seconds later: all but the reading at 11.0 are dropped (two joints each)
  EXPECT_EQ(h.size(), 4u);
  h.add(reading(5.0, 1.0));  // time went back (a looped bag): the history starts afresh
  EXPECT_EQ(h.size(), 2u);
  o.max_velocity = 0;
  EXPECT_THROW(JointHistory{o}, std::invalid_argument);
}

TEST(JointHistory, SeveralPublishersEachWithTheirJoints) {
  // An arm ("a", "b") and a gripper ("g") publishing alternately; the arm moves at 0.2 rad/s.
  JointHistory h;
  for (int k = 0; k <= 100; ++k) {
    JointReading arm, gripper;
    arm.stamp = 10.0 + 0.01 * k;
    arm.position = {{"a", 0.002 * k}, {"b", 0.5}};
    gripper.stamp = arm.stamp + 0.005;
    gripper.position = {{"g", 0.02}};
    h.add(arm), h.add(gripper);
  }
  std::string why;
  EXPECT_FALSE(h.still_at(10.5, &why));
  EXPECT_NE(why.find("joint 'a'"), std::string::npos) << why;
  // Still: every joint's position comes back, whichever message carried it.
  JointHistory still;
  for (int k = 0; k <= 100; ++k) {
    JointReading arm, gripper;
    arm.stamp = 10.0 + 0.01 * k;
    arm.position = {{"a", 0.3}, {"b", 0.5}};
    gripper.stamp = arm.stamp + 0.005;
    gripper.position = {{"g", 0.02}};
    still.add(arm), still.add(gripper);
  }
  const auto q = still.still_at(10.5, &why);
  ASSERT_TRUE(q.has_value()) << why;
  EXPECT_EQ(q->size(), 3u);
  EXPECT_DOUBLE_EQ(q->at("g"), 0.02);
}

TEST(JointHistory, AJointOfAnotherRobotNeitherStopsNorStallsASample) {
  // A state of a joint the robot does not have, once: later readings of the robot's own joints stand alone.
  JointHistory h;
  h.keep_only({"a", "b"});
  JointReading stray;
  stray.stamp = 9.0;
  stray.position["gripper"] = 0.1;
  h.add(stray);
  for (int k = 0; k <= 100; ++k) h.add(reading(10.0 + 0.01 * k, 1.0));
  std::string why;
  const auto q = h.still_at(10.5, &why);
  ASSERT_TRUE(q.has_value()) << why;
  EXPECT_EQ(q->count("gripper"), 0u);
  EXPECT_EQ(q->size(), 2u);
}

TEST(JointHistory, ARejectedMessageIsNamedAsTheCause) {
  // Only NaN states so far: the refusal says so, not "no joint states received".
  JointHistory h;
  h.note_rejected(10.0, "joint 'a' is not finite");
  std::string why;
  EXPECT_FALSE(h.still_at(10.0, &why));
  EXPECT_NE(why.find("the latest joint_states message was ignored: joint 'a' is not finite"), std::string::npos)
      << why;
  // Good readings after it: the cause is gone.
  for (int k = 0; k <= 100; ++k) h.add(reading(10.0 + 0.01 * k, 1.0));
  EXPECT_TRUE(h.still_at(10.5, &why)) << why;
  EXPECT_FALSE(h.still_at(10.95, &why));
  EXPECT_EQ(why.find("ignored"), std::string::npos) << why;
}
