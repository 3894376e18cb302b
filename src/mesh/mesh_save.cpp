// Writing meshes as ASCII PLY the way BOP models are stored: positions in file units, per-vertex texture_u/v,
// and the texture next to it named by `comment TextureFile`.
#include <filesystem>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <stdexcept>

#include "diffdope/mesh.hpp"

namespace diffdope {

void save_ply(const Mesh& mesh, const std::string& path, double units_per_metre) {
  namespace fs = std::filesystem;
  std::ofstream f(path);
  if (!f) throw std::runtime_error(path + ": cannot write");
  const bool textured = !mesh.textures.empty() && !mesh.uvs.empty();
  const std::string tex_name = fs::path(path).stem().string() + ".png";
  f << "ply\nformat ascii 1.0\n";
  if (textured) f << "comment TextureFile " << tex_name << "\n";
  f << "element vertex " << mesh.num_vertices() << "\nproperty float x\nproperty float y\nproperty float z\n";
  if (textured) f << "property float texture_u\nproperty float texture_v\n";
  else f << "property uchar red\nproperty uchar green\nproperty uchar blue\n";
  f << "element face " << mesh.num_triangles() << "\nproperty list uchar int vertex_indices\nend_header\n";
  for (int i = 0; i < mesh.num_vertices(); ++i) {
    const Vec3f& p = mesh.positions[i];
    f << p.x * units_per_metre << " " << p.y * units_per_metre << " " << p.z * units_per_metre;
    if (textured) {
      f << " " << mesh.uvs[i].x << " " << mesh.uvs[i].y << "\n";
    } else {
      const Vec3f& c = mesh.colors[i];
      f << " " << int(std::lround(255 * c.x)) << " " << int(std::lround(255 * c.y)) << " " << int(std::lround(255 * c.z)) << "\n";
    }
  }
  for (int t = 0; t < mesh.num_triangles(); ++t)
    f << "3 " << mesh.triangles[3 * t] << " " << mesh.triangles[3 * t + 1] << " " << mesh.triangles[3 * t + 2] << "\n";
  if (!f) throw std::runtime_error(path + ": write failed");
  if (textured) {
    const Texture& t = mesh.textures[0];
    cv::Mat rgb(t.height, t.width, CV_32FC3, const_cast<float*>(t.rgb.data())), bgr;
    cv::cvtColor(rgb, bgr, cv::COLOR_RGB2BGR);
    bgr.convertTo(bgr, CV_8UC3, 255.0);
    const std::string tex_path = (fs::path(path).parent_path() / tex_name).string();
    if (!cv::imwrite(tex_path, bgr)) throw std::runtime_error(tex_path + ": cannot write texture");
  }
}

}  // namespace diffdope
