#include "diffdope/synthetic.hpp"

#include <opencv2/imgproc.hpp>

#include "diffdope/procedural.hpp"

namespace diffdope {

Observation synthesize_observation(Renderer& renderer, const Camera& cam, const Mesh& mesh, const Pose& pose,
                                   const SyntheticNoise& noise, uint32_t seed) {
  const RenderImage img = renderer.render(cam, mesh, {pose})[0];
  std::mt19937 rng(seed);
  // Background: a smooth colourful texture stretched over the image.
  const Texture bg_tex = make_label_texture(256, seed + 1000);
  cv::Mat bg(bg_tex.height, bg_tex.width, CV_32FC3, const_cast<float*>(bg_tex.rgb.data()));
  cv::Mat background;
  cv::resize(bg, background, cv::Size(cam.width, cam.height), 0, 0, cv::INTER_LINEAR);

  Observation o;
  o.rgb = cv::Mat(cam.height, cam.width, CV_32FC3);
  o.depth = cv::Mat(cam.height, cam.width, CV_32FC1);
  std::normal_distribution<float> n01(0.f, 1.f);
  for (int y = 0; y < cam.height; ++y) {
    for (int x = 0; x < cam.width; ++x) {
      const float cov = img.coverage.at<float>(y, x);
      const cv::Vec3f c = img.color.at<cv::Vec3f>(y, x) * float(noise.brightness);
      const cv::Vec3f b = background.at<cv::Vec3f>(y, x);
      cv::Vec3f px = c + (1.f - std::min(1.f, std::max(0.f, cov))) * b;
      for (int ch = 0; ch < 3; ++ch) px[ch] = std::min(1.f, std::max(0.f, px[ch] + float(noise.rgb_sigma) * n01(rng)));
      o.rgb.at<cv::Vec3f>(y, x) = px;
      const float z = img.depth.at<float>(y, x) > 0 ? img.depth.at<float>(y, x) : float(noise.background_depth);
      o.depth.at<float>(y, x) = z + float(noise.depth_sigma_at_1m) * z * z * n01(rng);
    }
  }
  // Holes: random blobs, and the object's silhouette border (where real sensors fail most).
  cv::Mat holes = cv::Mat::zeros(cam.height, cam.width, CV_8U);
  std::uniform_real_distribution<float> U(0.f, 1.f);
  const double target = noise.hole_fraction * cam.width * cam.height;
  for (int i = 0; i < 1000 && cv::countNonZero(holes) < target; ++i)
    cv::circle(holes, cv::Point(int(U(rng) * cam.width), int(U(rng) * cam.height)),
               1 + int(U(rng) * 0.02 * cam.width), cv::Scalar(255), cv::FILLED);
  cv::Mat edge;
  cv::Mat covered = img.coverage > 0.f, inner;
  cv::erode(covered, inner, cv::Mat::ones(3, 3, CV_8U));
  edge = covered & ~inner;
  holes |= edge;
  o.depth.setTo(0.f, holes);
  o.mask = cv::Mat(img.coverage >= 0.5f) / 255;
  o.mask.convertTo(o.mask, CV_32F);
  return o;
}

Pose perturb_pose(const Pose& pose, const Eigen::Vector3d& centre, double angle, double distance, std::mt19937_64& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  Eigen::Vector3d axis(n(rng), n(rng), n(rng)), dir(n(rng), n(rng), n(rng));
  axis.normalize();
  dir.normalize();
  // Rotation about the object's centre, expressed in the camera frame: R' = dR R, keep the centre fixed.
  const Eigen::Matrix3d dR = so3_exp(axis * angle);
  const Eigen::Vector3d c_cam = pose * centre;
  Pose out(dR * pose.R, Eigen::Vector3d::Zero());
  out.t = c_cam - out.R * centre + distance * dir;
  return out;
}

}  // namespace diffdope
