#include "diffdope/synthetic.hpp"

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>
#include <stdexcept>
#include <string>

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
  cv::Mat clean_depth(cam.height, cam.width, CV_32FC1);  // before noise: the surfaces flying pixels mix
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
      clean_depth.at<float>(y, x) = z;
      out.depth.at<float>(y, x) = z + float(noise.depth_sigma_at_1m) * z * z * n01(rng);
    }
  }
  if (noise.depth_noise_grain_px > 0) {  // grained noise instead: a smoothed field with unit variance per pixel
    cv::Mat field(cam.height, cam.width, CV_32F);
    std::mt19937 grain_rng(seed + 7919);
    for (int y = 0; y < cam.height; ++y)
      for (int x = 0; x < cam.width; ++x) field.at<float>(y, x) = n01(grain_rng);
    const double g = noise.depth_noise_grain_px;
    const cv::Mat k = cv::getGaussianKernel(2 * int(std::ceil(3 * g)) + 1, g, CV_64F);
    cv::sepFilter2D(field, field, CV_32F, k, k, cv::Point(-1, -1), 0, cv::BORDER_REFLECT);
    const double kk = k.dot(k);  // the smoothed field's variance is (sum of squared weights)^2, separably
    field *= 1.0 / kk;
    out.depth = clean_depth + float(noise.depth_sigma_at_1m) * clean_depth.mul(clean_depth).mul(field);
  }
  // Holes: random blobs, and the objects' silhouette borders (where real sensors fail most).
  cv::Mat holes = cv::Mat::zeros(cam.height, cam.width, CV_8U), borders = holes.clone();
  std::uniform_real_distribution<float> U(0.f, 1.f);
  const double target = noise.hole_fraction * cam.width * cam.height;
  for (int i = 0; i < 1000 && cv::countNonZero(holes) < target; ++i)
    cv::circle(holes, cv::Point(int(U(rng) * cam.width), int(U(rng) * cam.height)),
               1 + int(U(rng) * 0.02 * cam.width), cv::Scalar(255), cv::FILLED);
  for (const RenderImage& img : imgs) {
    cv::Mat covered = img.coverage > 0.f, inner;
    cv::erode(covered, inner, cv::Mat::ones(3, 3, CV_8U));
    borders |= covered & ~inner;
  }
  out.depth.setTo(0.f, holes | borders);
  if (noise.flying_pixel_fraction > 0) {
    // A mixed reading lies anywhere between the nearest and the farthest surface around the pixel.
    cv::Mat near_z, far_z;
    cv::erode(clean_depth, near_z, cv::Mat::ones(3, 3, CV_8U));
    cv::dilate(clean_depth, far_z, cv::Mat::ones(3, 3, CV_8U));
    for (int y = 0; y < cam.height; ++y)
      for (int x = 0; x < cam.width; ++x) {
        if (!borders.at<uchar>(y, x) || holes.at<uchar>(y, x) || U(rng) >= noise.flying_pixel_fraction) continue;
        const float a = near_z.at<float>(y, x), b = far_z.at<float>(y, x);
        const float z = a + U(rng) * (b - a);
        out.depth.at<float>(y, x) = z + float(noise.depth_sigma_at_1m) * z * z * n01(rng);
      }
  }
  if (noise.colour_offset_x_px != 0 || noise.colour_offset_y_px != 0) {
    const double dx = noise.colour_offset_x_px, dy = noise.colour_offset_y_px;
    if (!(std::abs(dx) <= SyntheticNoise::kMaxColourOffset && std::abs(dy) <= SyntheticNoise::kMaxColourOffset))
      throw std::invalid_argument("synthesize_scene: colour offset beyond " +
                                  std::to_string(int(SyntheticNoise::kMaxColourOffset)) + " pixels");
    cv::Mat moved;  // (a fresh image: warpAffine does not work in place)
    cv::warpAffine(out.rgb, moved, cv::Matx23d(1, 0, dx, 0, 1, dy), out.rgb.size(), cv::INTER_LINEAR,
                   cv::BORDER_REPLICATE);
    out.rgb = moved;
  }
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
