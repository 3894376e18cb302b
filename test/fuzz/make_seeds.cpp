// Writes the seed corpora of the fuzz targets (scripts/fuzz): small valid inputs of every form each parser takes,
// made here so that the project needs no downloaded corpus. Usage: make_seeds OUT_DIR REPO_DIR
#include <cstdint>
#include <algorithm>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "../ros/detection3d_writer.hpp"

#include "fuzz_common.hpp"

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

std::string out_dir;

void seed(const std::string& target, const std::string& name, const std::string& bytes) {
  fs::create_directories(out_dir + "/" + target);
  std::ofstream(out_dir + "/" + target + "/" + name, std::ios::binary).write(bytes.data(), std::streamsize(bytes.size()));
}

template <typename T>
void put(std::string& s, T v) {
  s.append(reinterpret_cast<const char*>(&v), sizeof v);
}

std::string slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

const std::string kSplit = fuzz::kSplit;

// A unit box: 8 corners, 12 triangles.
const float kCorner[8][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, {0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}};
const int kTri[12][3] = {{0, 2, 1}, {0, 3, 2}, {4, 5, 6}, {4, 6, 7}, {0, 1, 5}, {0, 5, 4},
                         {2, 3, 7}, {2, 7, 6}, {1, 2, 6}, {1, 6, 5}, {0, 4, 7}, {0, 7, 3}};

void mesh_seeds() {
  std::ostringstream a;
  a << "ply\nformat ascii 1.0\ncomment TextureFile tex.png\nelement vertex 8\nproperty float x\nproperty float y\n"
       "property float z\nproperty float texture_u\nproperty float texture_v\nelement face 12\n"
       "property list uchar int vertex_indices\nend_header\n";
  for (auto& c : kCorner) a << c[0] << " " << c[1] << " " << c[2] << " " << 0.5 * c[0] << " " << 0.5 * c[1] << "\n";
  for (auto& t : kTri) a << "3 " << t[0] << " " << t[1] << " " << t[2] << "\n";
  seed("mesh_ply", "ascii_uv.ply", a.str());
  for (const char* fmt : {"binary_little_endian", "binary_big_endian"}) {
    std::string b = std::string("ply\nformat ") + fmt +
                    " 1.0\nelement vertex 8\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\n"
                    "property uchar green\nproperty uchar blue\nelement face 12\nproperty list uchar int vertex_indices\n"
                    "end_header\n";
    const bool big = fmt[7] == 'b';
    auto word = [&](auto v) {
      std::string w(reinterpret_cast<const char*>(&v), sizeof v);
      if (big) std::reverse(w.begin(), w.end());
      b += w;
    };
    for (auto& c : kCorner) {
      for (float x : c) word(x);
      for (uint8_t col : {uint8_t(200), uint8_t(100), uint8_t(50)}) b.push_back(char(col));
    }
    for (auto& t : kTri) {
      b.push_back(3);
      for (int i : t) word(int32_t(i));
    }
    seed("mesh_ply", std::string(fmt) + ".ply", b);
  }
  std::ostringstream o;
  o << "mtllib m.mtl\n";
  for (auto& c : kCorner) o << "v " << c[0] << " " << c[1] << " " << c[2] << "\n";
  o << "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvn 0 0 1\nusemtl red\n";
  for (auto& t : kTri) o << "f " << t[0] + 1 << "/1/1 " << t[1] + 1 << "/2/1 " << t[2] + 1 << "/3/1\n";
  seed("mesh_obj", "box_mtl.obj", o.str() + kSplit + "newmtl red\nKd 0.8 0.1 0.1\nNs 10\n");
  seed("mesh_obj", "quads.obj", "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\no second\nv 0 0 1\nf 5 1 2\n");
  // glTF 2.0: one indexed triangle, in a GLB and as JSON with a base64 buffer.
  std::string bin;
  for (float v : {0.f, 0.f, 0.f, 1.f, 0.f, 0.f, 0.f, 1.f, 0.f}) put(bin, v);
  for (float v : {0.f, 0.f, 1.f, 0.f, 0.f, 1.f}) put(bin, v);
  for (uint16_t i : {0, 1, 2, 0}) put(bin, i);
  json g = json::parse(R"({
    "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}],
    "nodes": [{"mesh": 0, "translation": [0, 0, 1]}],
    "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 1}, "indices": 2, "material": 0}]}],
    "materials": [{"pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.25, 1.0, 1.0]}}],
    "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 36}, {"buffer": 0, "byteOffset": 36, "byteLength": 24},
                    {"buffer": 0, "byteOffset": 60, "byteLength": 6}],
    "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]},
                  {"bufferView": 1, "componentType": 5126, "count": 3, "type": "VEC2"},
                  {"bufferView": 2, "componentType": 5123, "count": 3, "type": "SCALAR"}]})");
  json gb = g;
  gb["buffers"] = json::array({{{"byteLength", bin.size()}}});
  std::string js = gb.dump();
  while (js.size() % 4) js += ' ';
  std::string glb = "glTF";
  put(glb, uint32_t(2)), put(glb, uint32_t(12 + 8 + js.size() + 8 + bin.size()));
  put(glb, uint32_t(js.size())), glb += "JSON", glb += js;
  put(glb, uint32_t(bin.size())), glb += std::string("BIN\0", 4), glb += bin;
  seed("mesh_glb", "triangle.glb", glb);
  static const char* b64 = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string enc;
  for (size_t i = 0; i < bin.size(); i += 3) {
    const uint32_t n = uint32_t(uint8_t(bin[i])) << 16 | (i + 1 < bin.size() ? uint32_t(uint8_t(bin[i + 1])) << 8 : 0) |
                       (i + 2 < bin.size() ? uint8_t(bin[i + 2]) : 0);
    enc += b64[n >> 18 & 63], enc += b64[n >> 12 & 63];
    enc += i + 1 < bin.size() ? b64[n >> 6 & 63] : '=';
    enc += i + 2 < bin.size() ? b64[n & 63] : '=';
  }
  g["buffers"] = json::array({{{"byteLength", bin.size()}, {"uri", "data:application/octet-stream;base64," + enc}}});
  seed("mesh_gltf", "triangle.gltf", g.dump(1));
}

void text_seeds(const std::string& repo) {
  seed("refiner_options", "default.yaml", slurp(repo + "/config/default.yaml"));
  seed("refiner_options", "fast.yaml", slurp(repo + "/config/fast.yaml"));
  seed("refiner_options", "flow.yaml", "{batch_size: 8, loss: {weight_edges: 1, edge_scale: 0.2}, render: {threads: 2}}\n");
  for (const auto& e : fs::directory_iterator(repo + "/config"))
    if (e.path().filename().string().find("objects") != std::string::npos)
      seed("objects_config", e.path().filename().string(), slurp(e.path().string()));
  seed("objects_config", "two.yaml",
       "objects:\n  - name: mug\n    mesh: package://diffdope_ros/meshes/mug.ply\n    mesh_scale: 0.001\n"
       "    mask_label: 2\n    symmetric: true\n  - name: box\n    mesh: /tmp/box.obj\nrefiner:\n  batch_size: 8\n");
  seed("objects_config", "symmetries.yaml",
       "objects:\n  - name: can\n    mesh: /tmp/can.ply\n    symmetries:\n      continuous: [{axis: [0, 0, 1], "
       "offset: [0, 0, 0.05]}]\n      discrete: [{translation: [0, 0, 0.1], rotation: [1, 0, 0, 0]}]\n");
  const std::string dope_head =
      "topic_camera: \"/dope/webcam/image_raw\"\ntopic_publishing: \"dope\"\ninput_is_rectified: True\n"
      "weights: {\"cracker\": \"package://dope/w/cracker.pth\", \"sugar\": \"package://dope/w/sugar.pth\"}\n"
      "dimensions: {\"cracker\": [16.4, 21.3, 7.2], \"sugar\": [9.3, 17.6, 4.5]}\n"
      "class_ids: {\"cracker\": 1, \"sugar\": 2}\n";
  seed("dope_config", "as_shipped.yaml", dope_head + "meshes:\n#  \"cracker\": \"file:///m/cracker.ply\"\n");
  seed("dope_config", "edited.yaml",
       dope_head + "meshes: {\"cracker\": \"file:///m/cracker.ply\", \"sugar\": \"meshes/sugar.obj\"}\n"
                   "mesh_scales: {\"cracker\": 0.01, \"sugar\": 0.01}\n"
                   "model_transforms: {\"cracker\": [[0, 0, 1, 0], [0, -1, 0, 0], [1, 0, 0, 0], [0, 0, 0, 1]]}\n");
  seed("dope_config", "trimmed.yaml", "meshes: {box: box.ply}\nmesh_scales: {box: 0.001}\n");
  seed("urdf", "primitives.urdf",
       "<?xml version=\"1.0\"?>\n<robot name=\"arm\">\n  <material name=\"o\"><color rgba=\"0.9 0.5 0.1 1\"/></material>\n"
       "  <link name=\"base\"><visual><origin xyz=\"0 0 0.05\" rpy=\"0 0 0\"/><geometry><box size=\"0.2 0.2 0.1\"/>"
       "</geometry><material name=\"o\"/></visual></link>\n"
       "  <link name=\"upper\"><visual><geometry><cylinder radius=\"0.04\" length=\"0.3\"/></geometry></visual></link>\n"
       "  <link name=\"finger_a\"><visual><geometry><sphere radius=\"0.02\"/></geometry></visual></link>\n"
       "  <link name=\"finger_b\"><visual><geometry><sphere radius=\"0.02\"/></geometry></visual></link>\n"
       "  <joint name=\"shoulder\" type=\"revolute\"><parent link=\"base\"/><child link=\"upper\"/>"
       "<origin xyz=\"0 0 0.1\"/><axis xyz=\"0 1 0\"/><limit lower=\"-1\" upper=\"1\" effort=\"1\" velocity=\"1\"/></joint>\n"
       "  <joint name=\"grip\" type=\"prismatic\"><parent link=\"upper\"/><child link=\"finger_a\"/>"
       "<origin xyz=\"0 0.02 0.3\"/><axis xyz=\"0 1 0\"/><limit lower=\"0\" upper=\"0.04\" effort=\"1\" velocity=\"1\"/></joint>\n"
       "  <joint name=\"grip_mimic\" type=\"prismatic\"><parent link=\"upper\"/><child link=\"finger_b\"/>"
       "<origin xyz=\"0 -0.02 0.3\"/><axis xyz=\"0 -1 0\"/><limit lower=\"0\" upper=\"0.04\" effort=\"1\" velocity=\"1\"/>"
       "<mimic joint=\"grip\" multiplier=\"1\" offset=\"0\"/></joint>\n</robot>\n");
  seed("urdf", "mesh.urdf",
       "<robot name=\"m\"><link name=\"a\"><visual><geometry><mesh filename=\"package://x/a.stl\" scale=\"1 1 -1\"/>"
       "</geometry></visual></link></robot>\n");
  seed("camera_pose", "fxfy_R.txt",
       std::string("{\"fx\": 600, \"fy\": 600, \"cx\": 319.5, \"cy\": 239.5, \"width\": 640, \"height\": 480}") + kSplit +
           "camera_matrix:\n  rows: 3\n  cols: 3\n  data: [600, 0, 320, 0, 600, 240, 0, 0, 1]\nimage_width: 640\n"
           "image_height: 480\n" + kSplit + "{\"R\": [1, 0, 0, 0, 1, 0, 0, 0, 1], \"t\": [0, 0, 0.5]}");
  seed("camera_pose", "bop_quat.txt",
       std::string("{\"0\": {\"cam_K\": [572.4, 0, 325.3, 0, 573.6, 242.0, 0, 0, 1], \"depth_scale\": 1.0}}") + kSplit +
           "fx: 500\nfy: 500\ncx: 320\ncy: 240\n" + kSplit +
           "{\"quaternion\": [0, 0, 0.7071068, 0.7071068], \"t\": [0.1, 0, 0.6]}");
  seed("camera_pose", "matrix.txt", std::string("{\"K\": [[600, 0, 320], [0, 600, 240], [0, 0, 1]]}") + kSplit +
                                        "K: [600, 0, 320, 0, 600, 240, 0, 0, 1]\n" + kSplit +
                                        "{\"matrix\": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0.5], [0, 0, 0, 1]]}");
  const std::string pose = "\"cam_R_m2c\": [1, 0, 0, 0, 1, 0, 0, 0, 1], \"cam_t_m2c\": [0, 0, 500]";
  seed("bop", "scene.txt",
       std::string("{\"0\": {\"cam_K\": [8, 0, 3.5, 0, 8, 3.5, 0, 0, 1], \"depth_scale\": 0.1}}") + kSplit +
           "{\"0\": [{\"obj_id\": 1, " + pose + "}, {\"obj_id\": 2, " + pose + "}]}" + kSplit +
           "{\"1\": {\"diameter\": 100}, \"2\": {\"diameter\": 50, \"symmetries_continuous\": [{\"axis\": [0, 0, 1], "
           "\"offset\": [0, 0, 0]}], \"symmetries_discrete\": [[-1, 0, 0, 0, 0, -1, 0, 0, 0, 0, 1, 5, 0, 0, 0, 1]]}}" + kSplit + "{\"0\": [{\"obj_id\": 1, " + pose + "}], \"1\": [{\"obj_id\": 2, " +
           pose + "}]}");
}

/// DOPE's Detection3DArray: one detection with two hypotheses, and one with a point cloud.
void detection_seeds() {
  diffdope_ros::test::Writer w;
  w.header(1, 1000, 0, "camera_color_optical_frame");
  w.put<uint32_t>(2);
  w.header(1, 1000, 0, "camera_color_optical_frame");
  w.put<uint32_t>(2);
  w.hypothesis(1, 0.9, 0.1, 0, 1);
  w.hypothesis(2, 0.4, -0.1, 0, 1);
  w.box_and_empty_cloud();
  w.header(1, 1000, 0, "");
  w.put<uint32_t>(1);
  w.hypothesis(3, 0.7, 0.0, 0, 1);
  w.pose(0, 0, 0.5, 0, 0, 0, 1), w.put<double>(0.1), w.put<double>(0.1), w.put<double>(0.1);
  w.cloud(true);
  seed("detection3d_array", "two.bin", std::string(w.bytes.begin(), w.bytes.end()));
}

/// Small images in every format the image reader takes: 8-bit colour, 16-bit depth, float colour, grey.
void image_seeds() {
  cv::Mat colour(12, 17, CV_8UC3), depth(12, 17, CV_16UC1), grey(12, 17, CV_8UC1), fcolour(12, 17, CV_32FC3);
  cv::randu(colour, 0, 255), cv::randu(depth, 0, 4000), cv::randu(grey, 0, 255), cv::randu(fcolour, 0.f, 1.f);
  const auto add = [](const std::string& name, const cv::Mat& m) {
    std::vector<uchar> buf;
    if (cv::imencode(name.substr(name.rfind('.')), m, buf)) seed("image", name, std::string(buf.begin(), buf.end()));
  };
  for (const char* ext : {".png", ".jpg", ".bmp", ".tif", ".ppm"}) add(std::string("colour") + ext, colour);
  add("depth.png", depth);
  add("depth.tif", depth);
  add("grey.pgm", grey);
  add("float.tif", fcolour);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 3) {
    std::cerr << "usage: make_seeds OUT_DIR REPO_DIR\n";
    return 2;
  }
  out_dir = argv[1];
  mesh_seeds();
  text_seeds(argv[2]);
  detection_seeds();
  image_seeds();
  return 0;
}
