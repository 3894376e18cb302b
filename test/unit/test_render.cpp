// Forward rendering against analytic cases, ROI and thread-count invariance, and robustness cases.
#include <opencv2/imgproc.hpp>

#include "test_scenes.hpp"

using namespace diffdope;
using namespace diffdope::test;

namespace {

/// Texture whose red channel is the texel column and green the texel row (linear ramps: bilinear filtering
/// reproduces them exactly, so a rendered colour tells which texel position was sampled).
Texture ramp_texture(int w, int h) {
  Texture t;
  t.width = w;
  t.height = h;
  t.rgb.resize(3 * w * h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      float* p = &t.rgb[3 * (y * w + x)];
      p[0] = (x + 0.5f) / w;
      p[1] = (y + 0.5f) / h;
      p[2] = 0.25f;
    }
  return t;
}

double silhouette_area(const Camera& cam, const Mesh& mesh, const Pose& pose) {
  // A convex object's silhouette is the convex hull of its projected vertices.
  std::vector<cv::Point2f> pts;
  for (const auto& c : mesh.bbox_corners()) {
    const Eigen::Vector3d X = pose * c;
    pts.emplace_back(float(cam.fx * X.x() / X.z() + cam.cx), float(cam.fy * X.y() / X.z() + cam.cy));
  }
  std::vector<cv::Point2f> hull;
  cv::convexHull(pts, hull);
  return cv::contourArea(hull);
}

}  // namespace

TEST(Render, BoxFacingCameraCoversExpectedAreaAndDepth) {
  auto r = make_cpu_renderer();
  const Camera cam = test_camera();
  const Mesh box = make_box(Eigen::Vector3d(0.1, 0.1, 0.1), make_pattern_texture(64, 1));
  const Pose pose(Eigen::Matrix3d::Identity(), Eigen::Vector3d(0, 0, 0.5));
  const RenderImage img = r->render(cam, box, {pose})[0];
  const double side = cam.fx * 0.1 / 0.45;  // front face at z = 0.45
  EXPECT_NEAR(cv::sum(img.coverage)[0], side * side, 0.01 * side * side);
  // Watertight coverage: the front face is two triangles whose shared diagonal runs through pixel centres;
  // every pixel centre inside the face's square is covered exactly (no hole along the diagonal).
  int inside = 0;
  for (int y = 0; y < cam.height; ++y)
    for (int x = 0; x < cam.width; ++x)
      inside += std::abs(x - cam.cx) < side / 2 && std::abs(y - cam.cy) < side / 2;
  EXPECT_EQ(cv::countNonZero(img.triangle >= 0), inside);
  EXPECT_NEAR(img.depth.at<float>(120, 160), 0.45f, 1e-5f);
  EXPECT_EQ(img.depth.at<float>(5, 5), 0.f);
  EXPECT_EQ(img.coverage.at<float>(5, 5), 0.f);
  EXPECT_EQ(img.coverage.at<float>(120, 160), 1.f);
}

TEST(Render, RotatedBoxCoversItsProjectedHull) {
  auto r = make_cpu_renderer();
  const Camera cam = test_camera();
  const Mesh box = make_box(Eigen::Vector3d(0.12, 0.08, 0.05), make_pattern_texture(64, 2));
  for (const Pose& pose : {look_pose(0.3, 0.5, 0.2, 0.02, -0.01, 0.45), look_pose(-0.7, 0.2, 1.1, -0.05, 0.03, 0.6),
                           look_pose(1.2, -0.4, 0.0, 0.0, 0.0, 0.35)}) {
    const RenderImage img = r->render(cam, box, {pose})[0];
    const double area = silhouette_area(cam, box, pose);
    EXPECT_NEAR(cv::sum(img.coverage)[0], area, 0.01 * area);
  }
}

TEST(Render, TextureLookupLandsOnExpectedTexel) {
  auto r = make_cpu_renderer();
  const Camera cam = test_camera();
  const int TW = 96, TH = 64;
  Mesh box = make_box(Eigen::Vector3d(0.1, 0.1, 0.1), ramp_texture(TW, TH));
  const Pose pose(Eigen::Matrix3d::Identity(), Eigen::Vector3d(0, 0, 0.5));
  const RenderImage img = r->render(cam, box, {pose})[0];
  // The visible face is the box's -z face (atlas cell 2 of row 1).
  const float u0 = 2.f / 3.f, v0 = 0.5f, du = 1.f / 3.f, dv = 0.5f, e = 0.01f;
  for (const cv::Point px : {cv::Point(160, 120), cv::Point(140, 110), cv::Point(175, 131)}) {
    const double X = (px.x - cam.cx) / cam.fx * 0.45, Y = (px.y - cam.cy) / cam.fy * 0.45;  // on the face
    const double a = (X + 0.05) / 0.1, b = (Y + 0.05) / 0.1;                                // face coords
    // -z face corners in make_box: c0 (lo,lo) uv(u0+e, v0+e), c3 (lo,hi) uv(u0+du-e, v0+e),
    // c2 (hi,hi) uv(u0+du-e, v0+dv-e), c1 (hi,lo) uv(u0+e, v0+dv-e): u follows y, v follows x.
    const double uu = u0 + e + b * (du - 2 * e), vv = v0 + e + a * (dv - 2 * e);
    const cv::Vec3f c = img.color.at<cv::Vec3f>(px);
    EXPECT_NEAR(c[0] * TW - 0.5, uu * TW - 0.5, 0.02) << px;          // texel column
    EXPECT_NEAR(c[1] * TH - 0.5, (1 - vv) * TH - 0.5, 0.02) << px;    // texel row (v up, row 0 on top)
  }
}

TEST(Render, RegionOfInterestMatchesFullFrame) {
  const Camera cam = test_camera();
  const Mesh mesh = make_l_block(0.12, make_pattern_texture(128, 3));
  RenderOptions full;
  full.use_roi = false;
  auto r_roi = make_cpu_renderer();
  auto r_full = make_cpu_renderer(full);
  const Pose truth = look_pose(0.4, -0.3, 0.2, 0.01, 0.0, 0.5);
  const Observation obs = observe(*r_full, cam, mesh, truth);
  const std::vector<Pose> poses = {look_pose(0.45, -0.25, 0.22, 0.015, -0.01, 0.51), truth,
                                   look_pose(0.1, 0.2, -0.3, -0.05, 0.04, 0.45)};
  std::vector<LossValue> a, b;
  r_roi->evaluate(cam, mesh, obs, poses, LossOptions(), true, a);
  r_full->evaluate(cam, mesh, obs, poses, LossOptions(), true, b);
  for (size_t i = 0; i < poses.size(); ++i) {
    EXPECT_DOUBLE_EQ(a[i].total, b[i].total);
    for (int k = 0; k < 6; ++k) EXPECT_DOUBLE_EQ(a[i].gradient[k], b[i].gradient[k]);
  }
  const auto ia = r_roi->render(cam, mesh, poses), ib = r_full->render(cam, mesh, poses);
  for (size_t i = 0; i < poses.size(); ++i) {
    EXPECT_LT(ia[i].roi.area(), ib[i].roi.area());
    EXPECT_EQ(cv::norm(ia[i].coverage, ib[i].coverage, cv::NORM_INF), 0.0);
    EXPECT_EQ(cv::norm(ia[i].color, ib[i].color, cv::NORM_INF), 0.0);
    EXPECT_EQ(cv::norm(ia[i].depth, ib[i].depth, cv::NORM_INF), 0.0);
  }
}

TEST(Render, ResultsDoNotDependOnThreadCount) {
  const Camera cam = test_camera();
  const Mesh mesh = make_uv_sphere(0.06, 24, 48, make_pattern_texture(128, 4));
  RenderOptions one, two;
  one.threads = 1;
  two.threads = 2;
  auto r1 = make_cpu_renderer(one), r2 = make_cpu_renderer(two);
  const Observation obs = observe(*r1, cam, mesh, look_pose(0.1, 0.2, 0.3, 0.0, 0.0, 0.4));
  std::vector<Pose> poses;
  for (int i = 0; i < 9; ++i) poses.push_back(look_pose(0.1 + 0.02 * i, 0.2, 0.3, 0.002 * i, -0.001 * i, 0.4));
  std::vector<LossValue> a, b;
  r1->evaluate(cam, mesh, obs, poses, LossOptions(), true, a);
  r2->evaluate(cam, mesh, obs, poses, LossOptions(), true, b);
  for (size_t i = 0; i < poses.size(); ++i) {
    EXPECT_EQ(a[i].total, b[i].total);
    EXPECT_EQ(a[i].gradient, b[i].gradient);
  }
}

TEST(Render, NearPlaneNeverProducesNaN) {
  const Camera cam = test_camera();
  const Mesh box = make_box(Eigen::Vector3d(0.2, 0.2, 0.2), make_pattern_texture(64, 5));
  auto r = make_cpu_renderer();
  const Observation obs = observe(*r, cam, box, look_pose(0, 0, 0, 0, 0, 0.6));
  // Straddling the camera plane, just in front of it, and fully behind it.
  const std::vector<Pose> poses = {look_pose(0.2, 0.1, 0, 0, 0, 0.0), look_pose(0.2, 0.1, 0, 0.01, 0, 0.105),
                                   look_pose(0, 0, 0, 0, 0, -0.5), look_pose(0.3, 0.3, 0.3, 0.0, 0.0, 0.09)};
  std::vector<LossValue> v;
  r->evaluate(cam, box, obs, poses, LossOptions(), true, v);
  for (const auto& l : v) {
    EXPECT_TRUE(std::isfinite(l.total));
    EXPECT_TRUE(l.gradient.allFinite());
    EXPECT_LT(l.gradient.norm(), 1e6);
  }
  const auto imgs = r->render(cam, box, poses);
  for (const auto& img : imgs) {
    EXPECT_TRUE(cv::checkRange(img.color) && cv::checkRange(img.depth) && cv::checkRange(img.coverage));
    double mn, mx;
    cv::minMaxLoc(img.depth, &mn, &mx);
    EXPECT_GE(mn, 0.0);
    EXPECT_LT(mx, 10.0);
  }
  EXPECT_EQ(cv::countNonZero(imgs[2].coverage), 0);  // behind the camera: nothing drawn
}

TEST(Render, InvalidPoseGetsInfiniteLossNotACrash) {
  const Camera cam = test_camera();
  const Mesh box = make_box(Eigen::Vector3d(0.1, 0.1, 0.1), make_pattern_texture(32, 5));
  auto r = make_cpu_renderer();
  const Observation obs = observe(*r, cam, box, look_pose(0, 0, 0, 0, 0, 0.6));
  Pose bad = look_pose(0, 0, 0, 0, 0, 0.6);
  bad.t.x() = std::nan("");
  std::vector<LossValue> v;
  r->evaluate(cam, box, obs, {bad}, LossOptions(), true, v);
  EXPECT_TRUE(std::isinf(v[0].total));
  EXPECT_TRUE(v[0].gradient.isZero());
}

TEST(Render, DegenerateTrianglesChangeNothing) {
  const Camera cam = test_camera();
  Mesh box = make_box(Eigen::Vector3d(0.1, 0.1, 0.1), make_pattern_texture(64, 6));
  Mesh with_junk = box;
  // A zero-area triangle on a front edge and a needle with two identical vertices.
  with_junk.triangles.insert(with_junk.triangles.end(), {0, 1, 1, 2, 2, 2});
  with_junk.tri_texture.insert(with_junk.tri_texture.end(), {0, 0});
  with_junk.finalize();
  auto r = make_cpu_renderer();
  const Pose pose = look_pose(0.5, 0.6, 0.1, 0, 0, 0.45);
  const auto a = r->render(cam, box, {pose})[0], b = r->render(cam, with_junk, {pose})[0];
  EXPECT_EQ(cv::norm(a.coverage, b.coverage, cv::NORM_INF), 0.0);
  EXPECT_EQ(cv::norm(a.color, b.color, cv::NORM_INF), 0.0);
}

TEST(Render, UvSeamsDoNotCreateFalseSilhouettes) {
  // make_box duplicates vertices along every cube edge (each face has its own UVs). Seen from a corner, three
  // faces meet at seams inside the silhouette: no pixel there may be blended.
  const Camera cam = test_camera();
  const Mesh box = make_box(Eigen::Vector3d(0.1, 0.1, 0.1), make_pattern_texture(64, 7));
  auto r = make_cpu_renderer();
  const RenderImage img = r->render(cam, box, {look_pose(0.6, 0.7, 0.2, 0, 0, 0.5)})[0];
  cv::Mat covered = img.triangle >= 0, interior;
  cv::erode(covered, interior, cv::Mat::ones(3, 3, CV_8U));
  ASSERT_GT(cv::countNonZero(interior), 2000);
  int blended = 0;
  for (int y = 0; y < img.coverage.rows; ++y)
    for (int x = 0; x < img.coverage.cols; ++x)
      if (interior.at<uchar>(y, x) && img.coverage.at<float>(y, x) != 1.f) ++blended;
  EXPECT_EQ(blended, 0);
  // ...while the outer silhouette is antialiased.
  EXPECT_GT(cv::countNonZero((img.coverage > 0.f) & (img.coverage < 1.f)), 100);
}

TEST(Render, AutoCullingOfClosedMeshesChangesNothing) {
  const Camera cam = test_camera();
  const Mesh box = make_box(Eigen::Vector3d(0.1, 0.07, 0.05), make_pattern_texture(64, 9));
  const Mesh sphere = make_uv_sphere(0.05, 12, 24, make_pattern_texture(64, 10));
  EXPECT_TRUE(box.closed_and_outward());
  EXPECT_TRUE(sphere.closed_and_outward());
  EXPECT_TRUE(make_cylinder(0.03, 0.1, 16, make_pattern_texture(16, 1)).closed_and_outward());
  Mesh open = box;  // one face removed
  open.triangles.resize(open.triangles.size() - 6);
  open.tri_texture.resize(open.tri_texture.size() - 2);
  open.finalize();
  EXPECT_FALSE(open.closed_and_outward());
  Mesh inside_out = box;  // every triangle wound the other way: normals point inwards
  for (size_t t = 0; t < inside_out.triangles.size(); t += 3) std::swap(inside_out.triangles[t + 1], inside_out.triangles[t + 2]);
  inside_out.finalize();
  EXPECT_FALSE(inside_out.closed_and_outward());

  RenderOptions no_cull;
  no_cull.auto_cull_closed = false;
  auto culled = make_cpu_renderer(), plain = make_cpu_renderer(no_cull);
  for (const Mesh* m : {&box, &sphere}) {
    const Pose truth = look_pose(0.4, 0.3, 0.2, 0.0, 0.0, 0.5);
    const Observation obs = observe(*plain, cam, *m, truth);
    const std::vector<Pose> poses = {look_pose(0.45, 0.25, 0.25, 0.005, 0.0, 0.51), look_pose(1.5, -0.4, 0.0, 0.0, 0.01, 0.45)};
    const auto a = culled->render(cam, *m, poses), b = plain->render(cam, *m, poses);
    for (size_t i = 0; i < poses.size(); ++i) {
      EXPECT_EQ(cv::norm(a[i].coverage, b[i].coverage, cv::NORM_INF), 0.0);
      EXPECT_EQ(cv::norm(a[i].color, b[i].color, cv::NORM_INF), 0.0);
    }
    std::vector<LossValue> la, lb;
    culled->evaluate(cam, *m, obs, poses, LossOptions(), true, la);
    plain->evaluate(cam, *m, obs, poses, LossOptions(), true, lb);
    for (size_t i = 0; i < poses.size(); ++i) {
      EXPECT_DOUBLE_EQ(la[i].total, lb[i].total);
      EXPECT_LT((la[i].gradient - lb[i].gradient).norm(), 1e-9 * (1 + lb[i].gradient.norm()));
    }
  }
}
