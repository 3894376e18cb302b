// Levels of detail: the simplified surfaces Mesh::finalize() builds for dense meshes, and the renderer's choice
// of level from the projected size (RenderOptions::lod_pixel_error).
#include <gtest/gtest.h>

#include "diffdope/procedural.hpp"
#include "diffdope/renderer.hpp"
#include "test_scenes.hpp"

using namespace diffdope;
using namespace diffdope::test;

namespace {

Mesh dense_sphere() { return make_uv_sphere(0.05, 60, 120, make_label_texture(256, 7)); }  // 14,400 triangles

/// The same surface as a triangle soup (three own vertices per triangle, as many PLY exporters write meshes).
Mesh soup_of(const Mesh& m) {
  Mesh s;
  s.textures = m.textures;
  s.name = "soup";
  for (int t = 0; t < m.num_triangles(); ++t) {
    for (int c = 0; c < 3; ++c) {
      const int v = m.triangles[3 * t + c];
      s.positions.push_back(m.positions[v]);
      s.colors.push_back(m.colors[v]);
      if (!m.uvs.empty()) s.uvs.push_back(m.uvs[v]);
      s.triangles.push_back(3 * t + c);
    }
    s.tri_texture.push_back(m.tri_texture[t]);
  }
  s.finalize();
  return s;
}

int seam_edges(const std::vector<unsigned char>& seams) {
  int n = 0;
  for (unsigned char s : seams) n += s;
  return n;
}

}  // namespace

TEST(Lod, DenseMeshesGetAChainOfSimplerSurfaces) {
  if (!lods_built()) GTEST_SKIP() << "built without meshoptimizer";
  const Mesh m = dense_sphere();
  ASSERT_GE(m.lods().size(), 3u);
  int previous = m.num_triangles();
  double error = 0;
  for (const MeshLod& l : m.lods()) {
    EXPECT_LE(l.num_triangles(), previous * 3 / 4);
    EXPECT_GE(l.error, error);
    EXPECT_LT(l.error, 0.1 * m.diameter());
    previous = l.num_triangles();
    error = l.error;
    ASSERT_EQ(l.tri_texture.size(), size_t(l.num_triangles()));
    ASSERT_EQ(l.neighbors.size(), l.triangles.size());
    for (int v : l.triangles) ASSERT_TRUE(v >= 0 && v < l.num_vertices());
    EXPECT_EQ(l.uvs.size(), l.positions.size());
    EXPECT_GT(seam_edges(l.seams), 0) << "the sphere's UV seam is kept";
  }
  EXPECT_LT(m.lods().back().num_triangles(), 1000);
  EXPECT_TRUE(make_box(Eigen::Vector3d(0.1, 0.1, 0.1), make_label_texture(64, 1)).lods().empty());
}

TEST(Lod, TriangleSoupsAreMergedFirst) {
  if (!lods_built()) GTEST_SKIP() << "built without meshoptimizer";
  const Mesh full = dense_sphere();
  const Mesh soup = soup_of(full);
  ASSERT_FALSE(soup.lods().empty());
  const MeshLod& merged = soup.lods()[0];
  EXPECT_EQ(merged.num_triangles(), soup.num_triangles());
  EXPECT_EQ(merged.error, 0.0);
  EXPECT_LT(merged.num_vertices(), soup.num_vertices() / 4);
  ASSERT_GE(soup.lods().size(), 4u);  // and the soup simplifies like the shared-vertex mesh (1 / kLodStep a level)
  EXPECT_LT(soup.lods()[3].num_triangles(), soup.num_triangles() / 2.5);

  // The merged level draws what the soup draws.
  const Camera cam = test_camera();
  const Pose pose = look_pose(0.3, 0.2, 0.1, 0.0, 0.0, 0.4);
  RenderOptions exact;
  exact.lod_pixel_error = 0;
  const RenderImage a = make_cpu_renderer(exact)->render(cam, soup, {pose})[0];
  const RenderImage b = make_cpu_renderer()->render(cam, soup, {pose})[0];
  EXPECT_EQ(a.lod, 0);
  EXPECT_GE(b.lod, 1);
  EXPECT_LT(cv::norm(a.coverage, b.coverage, cv::NORM_L1) / cv::sum(a.coverage)[0], 0.01);
}

// Far away the renderer draws a coarse level that looks like the full mesh, and the loss barely changes; close
// up it keeps the detail.
TEST(Lod, FarObjectsAreDrawnCoarserAndLookTheSame) {
  if (!lods_built()) GTEST_SKIP() << "built without meshoptimizer";
  const Mesh m = dense_sphere();
  const Camera cam(600, 600, 319.5, 239.5, 640, 480);
  RenderOptions exact;
  exact.lod_pixel_error = 0;
  auto full = make_cpu_renderer(exact), lod = make_cpu_renderer();
  int far_level = 0, near_level = 0;
  for (const double z : {0.25, 1.2}) {
    const Pose pose = look_pose(0.3, 0.2, 0.1, 0.01, 0.0, z);
    const RenderImage a = full->render(cam, m, {pose})[0];
    const RenderImage b = lod->render(cam, m, {pose})[0];
    (z > 1 ? far_level : near_level) = b.lod;
    const double area = cv::sum(a.coverage)[0];
    EXPECT_LT(cv::norm(a.coverage, b.coverage, cv::NORM_L1) / area, 0.02) << "z " << z;
    cv::Mat diff;
    cv::absdiff(a.color, b.color, diff);
    EXPECT_LT(cv::sum(diff)[0] / (3 * area), 0.03) << "z " << z;
    // Loss and gradient against an observation of the full mesh, a little off the pose.
    const Observation obs = observe(*full, cam, m, pose);
    const Pose off = pose.updated((Vector6d() << 0.002, -0.001, 0.003, 0.02, 0.0, 0.01).finished());
    std::vector<LossValue> la, lb;
    full->evaluate(cam, m, obs, {off}, LossOptions(), true, la);
    lod->evaluate(cam, m, obs, {off}, LossOptions(), true, lb);
    EXPECT_NEAR(lb[0].total, la[0].total, 0.1 * la[0].total) << "z " << z;
    EXPECT_GT(lb[0].gradient.dot(la[0].gradient) / (lb[0].gradient.norm() * la[0].gradient.norm()), 0.95) << "z " << z;
  }
  EXPECT_GT(far_level, near_level);
  EXPECT_GE(far_level, 2);
  EXPECT_EQ(full->render(cam, m, {look_pose(0, 0, 0, 0, 0, 1.2)})[0].lod, 0) << "lod_pixel_error 0: the full mesh";
}

TEST(Lod, WithoutMeshoptimizerDenseMeshesAreDrawnWhole) {
  if (lods_built()) GTEST_SKIP() << "built with meshoptimizer (Lod.DenseMeshesGetAChainOfSimplerSurfaces)";
  const Mesh m = dense_sphere();
  EXPECT_TRUE(m.lods().empty());
  const Camera cam(600, 600, 319.5, 239.5, 640, 480);
  const RenderImage far = make_cpu_renderer()->render(cam, m, {look_pose(0, 0, 0, 0, 0, 1.2)})[0];
  EXPECT_EQ(far.lod, 0);
  EXPECT_GT(cv::countNonZero(far.coverage >= 0.5f), 100);
}
