// Analytic pose gradients against central finite differences, per loss term and combined.
//
// Tolerance and why: the rendered loss is piecewise smooth. Pixel centres crossing triangle edges inside the
// object switch which texel feeds a pixel, L1 kinks, and the 1-pixel box filter at silhouettes are all
// continuous, but their derivatives jump, and a few pixel-level events (a blend switching direction at 45
// degree edges, silhouette corners) still add small jumps; finite differences straddle some of them. We
// average central differences over steps of 0.03 to 0.25 px (translation 5e-5 to 4e-4 m, rotation 1.25e-4 to
// 1e-3 rad at 0.5 m and f = 300 px). What remains is mostly below 5 % of the gradient's norm, with a few
// components up to ~9 % (depth at a sphere's limb, where the finite differences themselves still move by as
// much between step sizes). We require every component within 10 % of the norm and cosine > 0.99. A wrong
// sign, a missing term (e.g. no silhouette gradient: 100 %) or a wrong Jacobian fails by far more.
#include "test_scenes.hpp"

using namespace diffdope;
using namespace diffdope::test;

namespace {

struct Case {
  const char* name;
  Pose truth, test;
};

void check_gradients(const Mesh& mesh, const LossOptions& loss, const char* what, bool drop_rgb = false,
                     bool drop_depth = false, bool with_edges = false, bool with_texture = false) {
  const Camera cam = test_camera();
  auto r = make_cpu_renderer();
  const std::vector<Case> cases = {
      {"near", look_pose(0.3, 0.4, 0.1, 0.0, 0.0, 0.5), look_pose(0.33, 0.37, 0.12, 0.004, -0.003, 0.505)},
      {"far", look_pose(-0.6, 0.2, 0.9, 0.03, 0.02, 0.6), look_pose(-0.55, 0.25, 0.85, 0.02, 0.025, 0.61)},
      {"tilted", look_pose(1.1, -0.3, 0.4, -0.02, 0.01, 0.45), look_pose(1.05, -0.27, 0.42, -0.015, 0.006, 0.44)},
  };
  for (const Case& c : cases) {
    Observation obs = observe(*r, cam, mesh, c.truth);
    if (drop_rgb) obs.rgb.release();
    if (drop_depth) obs.depth.release();
    if (with_edges) obs.edges = observed_edges(obs.rgb);
    if (with_texture) obs.texture = observed_texture(obs.rgb, loss.texture_epsilon);
    std::vector<LossValue> v;
    r->evaluate(cam, mesh, obs, {c.test}, loss, true, v);
    const Vector6d g = v[0].gradient;
    const Vector6d fd = finite_difference(*r, cam, mesh, obs, c.test, loss, 1e-4, 2.5e-4);
    ASSERT_GT(fd.norm(), 1e-3) << what << " " << c.name << ": finite differences see no slope";
    const double cosine = g.dot(fd) / (g.norm() * fd.norm());
    EXPECT_GT(cosine, 0.99) << what << " " << c.name << "\n analytic " << g.transpose() << "\n finite   "
                            << fd.transpose();
    for (int k = 0; k < 6; ++k)
      EXPECT_NEAR(g[k], fd[k], 0.10 * fd.norm())
          << what << " " << c.name << " dof " << k << "\n analytic " << g.transpose() << "\n finite   "
          << fd.transpose();
  }
}

/// A texture that is continuous on a UV sphere: periodic in u, constant towards the poles. The UV sphere's
/// poles are texture singularities (every longitude meets in one point, so colour jumps across many edges
/// inside one pixel) that a pairwise 1-pixel blend cannot represent; there the rgb gradient is off by up to
/// ~20 % (measured with the generic pattern). Seams elsewhere (box creases, the L-block) are tested as they are.
Texture sphere_texture(int size) {
  Texture t;
  t.width = t.height = size;
  t.rgb.resize(3 * size * size);
  for (int y = 0; y < size; ++y)
    for (int x = 0; x < size; ++x) {
      const float u = (x + 0.5f) / size, v = 1.f - (y + 0.5f) / size, pole = std::pow(std::sin(float(M_PI) * v), 2.f);
      const float a = 0.5f + 0.2f * std::sin(6.283f * 2 * v) + 0.25f * pole * std::sin(6.283f * 3 * u);
      const float b = 0.5f + 0.3f * pole * std::cos(6.283f * 2 * u + 1.f);
      float* p = &t.rgb[3 * (y * size + x)];
      p[0] = a, p[1] = b, p[2] = 1.f - a;
    }
  return t;
}

LossOptions only(double rgb, double depth, double mask) {
  LossOptions l;
  l.weight_rgb = rgb;
  l.weight_depth = depth;
  l.weight_mask = mask;
  return l;
}

}  // namespace

class GradientCheck : public ::testing::TestWithParam<int> {
 protected:
  Mesh mesh() const {
    switch (GetParam()) {
      case 0: return make_box(Eigen::Vector3d(0.12, 0.08, 0.06), make_pattern_texture(128, 11));
      case 1: return make_l_block(0.12, make_pattern_texture(128, 12));
      default: return make_uv_sphere(0.05, 16, 32, sphere_texture(128));
    }
  }
};

TEST_P(GradientCheck, MaskTerm) { check_gradients(mesh(), only(0, 0, 1), "mask"); }
TEST_P(GradientCheck, RgbTerm) { check_gradients(mesh(), only(1, 0, 0), "rgb"); }
TEST_P(GradientCheck, DepthTerm) { check_gradients(mesh(), only(0, 1, 0), "depth"); }
TEST_P(GradientCheck, Combined) { check_gradients(mesh(), only(1, 1, 1), "combined"); }
TEST_P(GradientCheck, EdgeTerm) {
  // The chain (grey -> Sobel -> saturation -> silhouette blends) is checked on plain-coloured faces with a
  // large edge_scale. With textures, the render's Sobel response moves with the texture's second derivative,
  // which bilinear filtering makes discontinuous at every texel, and with the default scale |E_obs - E_render|
  // changes sign at thousands of pixels within a 0.1 px move: finite differences then average kinks (measured:
  // same direction, components off by up to ~40 %). Textured meshes with the default scale are checked combined
  // with the other terms (AllTermsWithEdges).
  Mesh m = mesh();
  for (Texture& t : m.textures) std::fill(t.rgb.begin(), t.rgb.end(), 0.6f);
  m.finalize();
  LossOptions l = only(0, 0, 0);
  l.weight_edges = 1;
  l.edge_scale = 100;
  check_gradients(m, l, "edges", false, false, true);
}
TEST_P(GradientCheck, AllTermsWithEdges) {
  LossOptions l = only(1, 1, 1);
  l.weight_edges = 1;
  check_gradients(mesh(), l, "all+edges", false, false, true);
}
TEST(Gradient, TextureTermAlone) {
  // The chain grey -> log -> Sobel -> L1 -> colour -> shading -> pose, on a textured wall that fills the view:
  // the term's weight (the smallest coverage and mask around a pixel, held constant by design: silhouettes are
  // the mask and depth terms' business) is then 1 everywhere whatever the pose, and the observed gradients are
  // offset far above the render's, so no pixel's |observed - render| changes sign within a step. (Near the
  // truth on small objects, thousands of pixels change sign within a finite-difference step, since the Sobel of
  // a bilinear texture is discontinuous at every texel, as for the edge term, and the weight moves at the
  // silhouette: there the directions agree only roughly, measured cosines 0.3-0.96; those cases are checked
  // combined with the other terms in AllTermsWithTexture.)
  const Camera cam = test_camera();
  auto r = make_cpu_renderer();
  const Mesh wall = make_box(Eigen::Vector3d(2.0, 2.0, 0.05), sphere_texture(256));
  const Pose truth = look_pose(0.1, -0.15, 0.05, 0.0, 0.0, 0.6), test = look_pose(0.12, -0.13, 0.06, 0.003, -0.002, 0.605);
  LossOptions l = only(0, 0, 0);
  l.weight_texture = 1;
  Observation obs = observe(*r, cam, wall, truth);
  obs.mask.release();
  obs.texture = observed_texture(obs.rgb, l.texture_epsilon) + cv::Scalar(10, 10);
  std::vector<LossValue> v;
  r->evaluate(cam, wall, obs, {test}, l, true, v);
  const Vector6d g = v[0].gradient, fd = finite_difference(*r, cam, wall, obs, test, l, 1e-4, 2.5e-4);
  ASSERT_GT(fd.norm(), 1e-3);
  EXPECT_GT(g.dot(fd) / (g.norm() * fd.norm()), 0.99) << "analytic " << g.transpose() << "\nfinite   " << fd.transpose();
  for (int k = 0; k < 6; ++k) EXPECT_NEAR(g[k], fd[k], 0.10 * fd.norm()) << "dof " << k;
}
TEST_P(GradientCheck, AllTermsWithTexture) {
  // Near the truth the texture term's kinks (TextureTermAlone) add noise to finite differences in proportion
  // to its weight: at 0.1 the sum is checked to the usual tolerance, every term in one call.
  LossOptions l = only(1, 1, 1);
  l.weight_texture = 0.1;
  check_gradients(mesh(), l, "all+texture", false, false, false, true);
}
TEST_P(GradientCheck, WithoutColourOrDepthImages) {
  check_gradients(mesh(), only(1, 1, 1), "mask+depth (no rgb image)", true, false);
  check_gradients(mesh(), only(1, 1, 1), "mask+rgb (no depth image)", false, true);
}

INSTANTIATE_TEST_SUITE_P(Meshes, GradientCheck, ::testing::Values(0, 1, 2),
                         [](const ::testing::TestParamInfo<int>& i) {
                           return std::string(i.param == 0 ? "Box" : i.param == 1 ? "LBlock" : "Sphere");
                         });

TEST(Gradient, SilhouetteGradientIsWhatMovesTheMaskTerm) {
  // A plain-coloured object has no interior gradient: everything the mask term knows comes from the edges.
  const Camera cam = test_camera();
  Texture flat;
  flat.width = flat.height = 2;
  flat.rgb.assign(12, 0.5f);
  const Mesh box = make_box(Eigen::Vector3d(0.1, 0.1, 0.1), flat);
  auto r = make_cpu_renderer();
  const Observation obs = observe(*r, cam, box, look_pose(0.2, 0.3, 0, 0, 0, 0.5));
  std::vector<LossValue> v;
  r->evaluate(cam, box, obs, {look_pose(0.2, 0.3, 0, 0.01, 0, 0.5)}, only(0, 0, 1), true, v);
  // Moving right by 1 cm: the mask loss wants the object back to the left (negative x gradient is a descent
  // direction along -x, so the gradient's x component is positive).
  EXPECT_GT(v[0].gradient[0], 0.0);
  EXPECT_GT(std::abs(v[0].gradient[0]), 5 * std::abs(v[0].gradient[1]));
}
