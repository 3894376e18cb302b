#include "diffdope/synthetic.hpp"

#include <algorithm>
#include <opencv2/imgproc.hpp>

#include "diffdope/procedural.hpp"

namespace diffdope {

SyntheticScene synthesize_scene(Renderer& renderer, const Camera& cam, const std::vector<SceneObject>& objects,
                                const SyntheticNoise& noise, uint32_t seed) {
  std::vector<RenderImage> imgs;
  for (const SceneObject& o : objects) imgs.push_back(renderer.render(cam, *o.mesh, {o.pose})[0]);
  std::mt19937 rng(seed);
  // Background: a colourful texture stretched over the image.
  const Texture bg_tex = make_label_texture(256, seed + 1000);
  cv::Mat bg(bg_tex.height, bg_tex.width, CV_32FC3, const_cast<float*>(bg_tex.rgb.data()));
  cv::Mat background;
  cv::resize(bg, background, cv::Size(cam.width, cam.height), 0, 0, cv::INTER_LINEAR);

  const size_t n = objects.size();
  SyntheticScene out;
  out.rgb = cv::Mat(cam.height, cam.width, CV_32FC3);
  out.depth = cv::Mat(cam.height, cam.width, CV_32FC1);
  for (size_t i = 0; i < n; ++i) {
    out.visible_masks.push_back(cv::Mat::zeros(cam.height, cam.width, CV_32F));
    out.full_masks.push_back(cv::Mat(imgs[i].coverage >= 0.5f) / 255);
    out.full_masks.back().convertTo(out.full_masks.back(), CV_32F);
  }
  std::normal_distribution<float> n01(0.f, 1.f);
  std::vector<int> order(n);
  for (int y = 0; y < cam.height; ++y) {
    for (int x = 0; x < cam.width; ++x) {
      // Front-to-back compositing of the premultiplied renders.
      for (size_t i = 0; i < n; ++i) order[i] = int(i);
      auto depth_of = [&](int i) {
        const float d = imgs[i].depth.at<float>(y, x);
        return d > 0.f ? d : 1e9f;
      };
      std::sort(order.begin(), order.end(), [&](int a, int b) { return depth_of(a) < depth_of(b); });
      cv::Vec3f acc(0, 0, 0);
      float remaining = 1.f;
      for (int i : order) {
        const float cov = std::min(1.f, std::max(0.f, imgs[i].coverage.at<float>(y, x)));
        acc += remaining * imgs[i].color.at<cv::Vec3f>(y, x) * float(noise.brightness);
        remaining *= 1.f - cov;
      }
      acc += remaining * background.at<cv::Vec3f>(y, x);
      for (int ch = 0; ch < 3; ++ch) acc[ch] = std::min(1.f, std::max(0.f, acc[ch] + float(noise.rgb_sigma) * n01(rng)));
      out.rgb.at<cv::Vec3f>(y, x) = acc;
      float z = float(noise.background_depth);
      for (int i : order) {  // the front object with coverage >= 0.5 owns the pixel
        if (imgs[i].coverage.at<float>(y, x) >= 0.5f) {
          if (imgs[i].depth.at<float>(y, x) > 0.f) z = imgs[i].depth.at<float>(y, x);
          out.visible_masks[i].at<float>(y, x) = 1.f;
          break;
        }
      }
      out.depth.at<float>(y, x) = z + float(noise.depth_sigma_at_1m) * z * z * n01(rng);
    }
  }
  // Holes: random blobs, and the objects' silhouette borders (where real sensors fail most).
  cv::Mat holes = cv::Mat::zeros(cam.height, cam.width, CV_8U);
  std::uniform_real_distribution<float> U(0.f, 1.f);
  const double target = noise.hole_fraction * cam.width * cam.height;
  for (int i = 0; i < 1000 && cv::countNonZero(holes) < target; ++i)
    cv::circle(holes, cv::Point(int(U(rng) * cam.width), int(U(rng) * cam.height)),
               1 + int(U(rng) * 0.02 * cam.width), cv::Scalar(255), cv::FILLED);
  for (const RenderImage& img : imgs) {
    cv::Mat covered = img.coverage > 0.f, inner;
    cv::erode(covered, inner, cv::Mat::ones(3, 3, CV_8U));
    holes |= covered & ~inner;
  }
  out.depth.setTo(0.f, holes);
  for (size_t i = 0; i < n; ++i) {
    const double full = cv::countNonZero(out.full_masks[i]);
    out.visible_fraction.push_back(full > 0 ? cv::countNonZero(out.visible_masks[i]) / full : 0.0);
  }
  return out;
}

Observation synthesize_observation(Renderer& renderer, const Camera& cam, const Mesh& mesh, const Pose& pose,
                                   const SyntheticNoise& noise, uint32_t seed) {
  SyntheticScene s = synthesize_scene(renderer, cam, {SceneObject{&mesh, pose}}, noise, seed);
  Observation o;
  o.rgb = s.rgb;
  o.depth = s.depth;
  o.mask = s.visible_masks[0];
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
