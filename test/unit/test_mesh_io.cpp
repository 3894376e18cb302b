// Mesh::load on small files written by the tests themselves: PLY (ASCII + binary, BOP-style TextureFile), OBJ+MTL,
// glTF/GLB, and the error paths.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <random>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "diffdope/mesh.hpp"

namespace fs = std::filesystem;
using diffdope::Mesh;
using diffdope::MeshLoadOptions;
using diffdope::Vec2f;
using diffdope::Vec3f;

namespace {

constexpr float kTol = 1e-6f;

class MeshIoTest : public ::testing::Test {
 protected:
  void SetUp() override {
    static std::atomic<int> counter{0};
    std::random_device rd;
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    std::ostringstream name;
    name << "diffdope_mesh_io_" << info->name() << "_" << std::chrono::steady_clock::now().time_since_epoch().count()
         << "_" << rd() << "_" << counter++;
    dir_ = fs::temp_directory_path() / name.str();
    fs::create_directories(dir_);
  }
  void TearDown() override {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }

  std::string file(const std::string& name) const { return (dir_ / name).string(); }

  void write_text(const std::string& name, const std::string& text) const {
    fs::create_directories((dir_ / name).parent_path());
    std::ofstream out(file(name), std::ios::binary);
    out << text;
    ASSERT_TRUE(out.good()) << name;
  }
  void write_bytes(const std::string& name, const std::vector<uint8_t>& bytes) const {
    std::ofstream out(file(name), std::ios::binary);
    out.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
    ASSERT_TRUE(out.good()) << name;
  }
  void write_image(const std::string& name, const cv::Mat& bgr) const {
    fs::create_directories((dir_ / name).parent_path());
    ASSERT_TRUE(cv::imwrite(file(name), bgr)) << name;
  }

  fs::path dir_;
};

// A 4 x 2 (w x h) BGR test image with distinct colours; kTexRgb lists them row-major (row 0 = top), in RGB.
const float kTexRgb[8][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {1, 1, 1},
                             {0, 0, 0}, {1, 1, 0}, {0, 1, 1}, {128 / 255.f, 64 / 255.f, 32 / 255.f}};
cv::Mat make_test_image() {
  cv::Mat img(2, 4, CV_8UC3);
  for (int y = 0; y < 2; ++y)
    for (int x = 0; x < 4; ++x) {
      const float* c = kTexRgb[4 * y + x];
      img.at<cv::Vec3b>(y, x) = cv::Vec3b(static_cast<uint8_t>(std::lround(c[2] * 255)),
                                          static_cast<uint8_t>(std::lround(c[1] * 255)),
                                          static_cast<uint8_t>(std::lround(c[0] * 255)));
    }
  return img;
}
void expect_test_texture(const diffdope::Texture& tex) {
  ASSERT_EQ(tex.width, 4);
  ASSERT_EQ(tex.height, 2);
  ASSERT_EQ(tex.rgb.size(), 3u * 4u * 2u);
  for (int i = 0; i < 8; ++i)
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(tex.rgb[3 * i + c], kTexRgb[i][c], 1e-6) << "texel " << i << " ch " << c;
}

// Index of the loaded vertex at position p (exactly one expected), or -1.
int find_vertex(const Mesh& m, Vec3f p, float tol = 1e-6f) {
  int found = -1;
  for (int i = 0; i < m.num_vertices(); ++i) {
    const Vec3f& q = m.positions[i];
    if (std::fabs(q.x - p.x) <= tol && std::fabs(q.y - p.y) <= tol && std::fabs(q.z - p.z) <= tol) {
      if (found >= 0) return -2;  // ambiguous
      found = i;
    }
  }
  return found;
}

void append_le(std::vector<uint8_t>* out, const void* p, size_t n) {
  // Test host is little-endian (x86 / ARM); PLY binary_little_endian and glTF are little-endian too.
  const auto* b = static_cast<const uint8_t*>(p);
  out->insert(out->end(), b, b + n);
}
template <class T>
void append(std::vector<uint8_t>* out, T v) {
  append_le(out, &v, sizeof(T));
}

std::string base64(const std::vector<uint8_t>& data) {
  static const char* tbl = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  size_t i = 0;
  for (; i + 2 < data.size(); i += 3) {
    const uint32_t v = (data[i] << 16) | (data[i + 1] << 8) | data[i + 2];
    out += tbl[(v >> 18) & 63];
    out += tbl[(v >> 12) & 63];
    out += tbl[(v >> 6) & 63];
    out += tbl[v & 63];
  }
  if (i + 1 == data.size()) {
    const uint32_t v = data[i] << 16;
    out += tbl[(v >> 18) & 63];
    out += tbl[(v >> 12) & 63];
    out += "==";
  } else if (i + 2 == data.size()) {
    const uint32_t v = (data[i] << 16) | (data[i + 1] << 8);
    out += tbl[(v >> 18) & 63];
    out += tbl[(v >> 12) & 63];
    out += tbl[(v >> 6) & 63];
    out += '=';
  }
  return out;
}

std::string load_error(const std::string& path) {
  try {
    Mesh::load(path);
  } catch (const std::runtime_error& e) {
    return e.what();
  }
  return "<no exception>";
}

// Box corners in millimetres, offset so that the centre is not the origin.
const float kBoxMm[8][3] = {{0, 0, 0},   {100, 0, 0},  {100, 60, 0},  {0, 60, 0},
                            {0, 0, 40},  {100, 0, 40}, {100, 60, 40}, {0, 60, 40}};
const int kBoxTris[12][3] = {{0, 2, 1}, {0, 3, 2}, {4, 5, 6}, {4, 6, 7}, {0, 1, 5}, {0, 5, 4},
                             {2, 3, 7}, {2, 7, 6}, {1, 2, 6}, {1, 6, 5}, {0, 4, 7}, {0, 7, 3}};
Vec2f box_uv(int i) { return {0.05f + 0.1f * i, 0.9f - 0.07f * i}; }

}  // namespace

TEST_F(MeshIoTest, PlyAsciiTexturedBoxMillimetres) {
  write_image("tex.png", make_test_image());
  std::ostringstream ply;
  ply << "ply\nformat ascii 1.0\ncomment made by test_mesh_io\ncomment TextureFile tex.png\n"
      << "element vertex 8\nproperty float x\nproperty float y\nproperty float z\n"
      << "property float texture_u\nproperty float texture_v\n"
      << "element face 12\nproperty list uchar int vertex_indices\nend_header\n";
  for (int i = 0; i < 8; ++i)
    ply << kBoxMm[i][0] << " " << kBoxMm[i][1] << " " << kBoxMm[i][2] << " " << box_uv(i).x << " " << box_uv(i).y
        << "\n";
  for (const auto& t : kBoxTris) ply << "3 " << t[0] << " " << t[1] << " " << t[2] << "\n";
  write_text("box.ply", ply.str());

  MeshLoadOptions opt;
  opt.scale = 0.001;
  opt.default_color = Eigen::Vector3f(0.25f, 0.5f, 0.75f);
  const Mesh m = Mesh::load(file("box.ply"), opt);

  EXPECT_EQ(m.name, file("box.ply"));
  ASSERT_EQ(m.num_vertices(), 8);
  ASSERT_EQ(m.num_triangles(), 12);
  ASSERT_EQ(m.uvs.size(), 8u);
  ASSERT_EQ(m.colors.size(), 8u);
  ASSERT_EQ(m.tri_texture.size(), 12u);

  // Positions in metres; UVs as in the file (v up, no flip); no vertex colours -> default colour.
  std::vector<int> file_of(8, -1);
  for (int i = 0; i < 8; ++i) {
    const int k = find_vertex(m, {kBoxMm[i][0] * 0.001f, kBoxMm[i][1] * 0.001f, kBoxMm[i][2] * 0.001f});
    ASSERT_GE(k, 0) << "file vertex " << i << " not found";
    file_of[k] = i;
    EXPECT_NEAR(m.uvs[k].x, box_uv(i).x, kTol);
    EXPECT_NEAR(m.uvs[k].y, box_uv(i).y, kTol);
    EXPECT_NEAR(m.colors[k].x, 0.25f, kTol);
    EXPECT_NEAR(m.colors[k].y, 0.5f, kTol);
    EXPECT_NEAR(m.colors[k].z, 0.75f, kTol);
  }
  // Same triangles, same winding (as cyclic vertex sequences).
  for (int t = 0; t < 12; ++t) {
    const int a = file_of[m.triangles[3 * t]], b = file_of[m.triangles[3 * t + 1]], c = file_of[m.triangles[3 * t + 2]];
    bool matched = false;
    for (const auto& f : kBoxTris)
      for (int r = 0; r < 3; ++r)
        matched = matched || (f[r] == a && f[(r + 1) % 3] == b && f[(r + 2) % 3] == c);
    EXPECT_TRUE(matched) << "triangle " << t << " (" << a << "," << b << "," << c << ") not in the file";
  }

  for (int t : m.tri_texture) EXPECT_EQ(t, 0);
  ASSERT_EQ(m.textures.size(), 1u);
  EXPECT_TRUE(m.has_texture());
  expect_test_texture(m.textures[0]);
  EXPECT_NE(m.textures[0].source.find("tex.png"), std::string::npos);

  // Geometry summaries: bbox centre and largest vertex distance (the box diagonal).
  EXPECT_NEAR(m.bbox_min().x(), 0.0, 1e-6);
  EXPECT_NEAR(m.bbox_min().y(), 0.0, 1e-6);
  EXPECT_NEAR(m.bbox_min().z(), 0.0, 1e-6);
  EXPECT_NEAR(m.bbox_max().x(), 0.1, 1e-6);
  EXPECT_NEAR(m.bbox_max().y(), 0.06, 1e-6);
  EXPECT_NEAR(m.bbox_max().z(), 0.04, 1e-6);
  EXPECT_NEAR(m.center().x(), 0.05, 1e-6);
  EXPECT_NEAR(m.center().y(), 0.03, 1e-6);
  EXPECT_NEAR(m.center().z(), 0.02, 1e-6);
  EXPECT_NEAR(m.diameter(), std::sqrt(0.1 * 0.1 + 0.06 * 0.06 + 0.04 * 0.04), 1e-6);
}

TEST_F(MeshIoTest, PlyTextureFileWithCrlfAndUppercaseExtension) {
  // Windows line endings and a .PLY extension: the texture name must not keep the '\r'.
  write_image("tex.png", make_test_image());
  std::string ply =
      "ply\nformat ascii 1.0\ncomment TextureFile tex.png\nelement vertex 3\nproperty float x\nproperty float y\n"
      "property float z\nproperty float s\nproperty float t\nelement face 1\n"
      "property list uchar int vertex_indices\nend_header\n0 0 0 0.125 0.25\n1 0 0 0.5 0.75\n0 1 0 1 0\n3 0 1 2\n";
  std::string crlf;
  for (char c : ply) crlf += (c == '\n') ? std::string("\r\n") : std::string(1, c);
  write_text("tri.PLY", crlf);
  const Mesh m = Mesh::load(file("tri.PLY"));
  ASSERT_EQ(m.num_triangles(), 1);
  ASSERT_EQ(m.textures.size(), 1u);
  expect_test_texture(m.textures[0]);
  EXPECT_EQ(m.tri_texture[0], 0);
  const int k = find_vertex(m, {1, 0, 0});
  ASSERT_GE(k, 0);
  EXPECT_NEAR(m.uvs[k].x, 0.5f, kTol);
  EXPECT_NEAR(m.uvs[k].y, 0.75f, kTol);
}

TEST_F(MeshIoTest, PlyBinaryVertexColors) {
  const float pos[4][3] = {{0, 0, 0}, {1, 0, 0}, {0, 2, 0}, {0, 0, 3}};
  const uint8_t col[4][3] = {{255, 0, 0}, {0, 255, 0}, {0, 0, 255}, {10, 128, 200}};
  const int tris[4][3] = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  std::string header =
      "ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
      "property float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nelement face 4\n"
      "property list uchar int vertex_indices\nend_header\n";
  std::vector<uint8_t> bytes(header.begin(), header.end());
  for (int i = 0; i < 4; ++i) {
    for (float v : pos[i]) append(&bytes, v);
    for (uint8_t c : col[i]) append(&bytes, c);
  }
  for (const auto& t : tris) {
    append(&bytes, static_cast<uint8_t>(3));
    for (int v : t) append(&bytes, static_cast<int32_t>(v));
  }
  write_bytes("tet.ply", bytes);

  MeshLoadOptions opt;
  opt.scale = 0.5;
  const Mesh m = Mesh::load(file("tet.ply"), opt);
  ASSERT_EQ(m.num_vertices(), 4);
  ASSERT_EQ(m.num_triangles(), 4);
  EXPECT_TRUE(m.uvs.empty());
  EXPECT_TRUE(m.textures.empty());
  EXPECT_FALSE(m.has_texture());
  ASSERT_EQ(m.tri_texture.size(), 4u);
  for (int t : m.tri_texture) EXPECT_EQ(t, -1);
  ASSERT_EQ(m.colors.size(), 4u);
  for (int i = 0; i < 4; ++i) {
    const int k = find_vertex(m, {0.5f * pos[i][0], 0.5f * pos[i][1], 0.5f * pos[i][2]});
    ASSERT_GE(k, 0) << "vertex " << i;
    EXPECT_NEAR(m.colors[k].x, col[i][0] / 255.f, kTol) << i;
    EXPECT_NEAR(m.colors[k].y, col[i][1] / 255.f, kTol) << i;
    EXPECT_NEAR(m.colors[k].z, col[i][2] / 255.f, kTol) << i;
  }
  EXPECT_NEAR(m.diameter(), 0.5 * std::sqrt(4.0 + 9.0), 1e-6);  // between (0,2,0) and (0,0,3)
}

TEST_F(MeshIoTest, PlyWithoutColorsUsesDefaultColor) {
  write_text("tri.ply",
             "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
             "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
  MeshLoadOptions opt;
  opt.default_color = Eigen::Vector3f(0.1f, 0.2f, 0.3f);
  const Mesh m = Mesh::load(file("tri.ply"), opt);
  ASSERT_EQ(m.num_vertices(), 3);
  ASSERT_EQ(m.colors.size(), 3u);
  for (const Vec3f& c : m.colors) {
    EXPECT_NEAR(c.x, 0.1f, kTol);
    EXPECT_NEAR(c.y, 0.2f, kTol);
    EXPECT_NEAR(c.z, 0.3f, kTol);
  }
  EXPECT_TRUE(m.uvs.empty());
  EXPECT_EQ(m.tri_texture, std::vector<int>{-1});
}

TEST_F(MeshIoTest, ObjMtlDiffuseTexture) {
  write_image("textures/tex.png", make_test_image());
  write_text("quad.mtl", "newmtl textured\nKd 1 1 1\nmap_Kd textures/tex.png\n");
  write_text("quad.obj",
             "mtllib quad.mtl\n"
             "v 0 0 0\nv 2 0 0\nv 2 1 0\nv 0 1 0\n"
             "vt 0.125 0.25\nvt 0.875 0.25\nvt 0.875 0.75\nvt 0.125 0.75\n"
             "usemtl textured\nf 1/1 2/2 3/3\nf 1/1 3/3 4/4\n");
  const Mesh m = Mesh::load(file("quad.obj"));
  ASSERT_EQ(m.num_vertices(), 4);
  ASSERT_EQ(m.num_triangles(), 2);
  ASSERT_EQ(m.uvs.size(), 4u);
  const Vec3f p[4] = {{0, 0, 0}, {2, 0, 0}, {2, 1, 0}, {0, 1, 0}};
  const Vec2f uv[4] = {{0.125f, 0.25f}, {0.875f, 0.25f}, {0.875f, 0.75f}, {0.125f, 0.75f}};
  for (int i = 0; i < 4; ++i) {
    const int k = find_vertex(m, p[i]);
    ASSERT_GE(k, 0) << i;
    EXPECT_NEAR(m.uvs[k].x, uv[i].x, kTol) << i;
    EXPECT_NEAR(m.uvs[k].y, uv[i].y, kTol) << i;
  }
  ASSERT_EQ(m.textures.size(), 1u);
  expect_test_texture(m.textures[0]);
  EXPECT_EQ(m.tri_texture, (std::vector<int>{0, 0}));
}

TEST_F(MeshIoTest, ObjMtlDiffuseColor) {
  write_text("tri.mtl", "newmtl red\nKd 0.8 0.1 0.25\n");
  write_text("tri.obj", "mtllib tri.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl red\nf 1 2 3\n");
  const Mesh m = Mesh::load(file("tri.obj"));
  ASSERT_EQ(m.num_vertices(), 3);
  ASSERT_EQ(m.num_triangles(), 1);
  EXPECT_TRUE(m.uvs.empty());
  EXPECT_TRUE(m.textures.empty());
  EXPECT_EQ(m.tri_texture, std::vector<int>{-1});
  for (const Vec3f& c : m.colors) {
    EXPECT_NEAR(c.x, 0.8f, kTol);
    EXPECT_NEAR(c.y, 0.1f, kTol);
    EXPECT_NEAR(c.z, 0.25f, kTol);
  }
}

TEST_F(MeshIoTest, ObjWithoutMtlUsesDefaultColor) {
  write_text("tri.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
  MeshLoadOptions opt;
  opt.default_color = Eigen::Vector3f(0.9f, 0.4f, 0.05f);
  const Mesh m = Mesh::load(file("tri.obj"), opt);
  ASSERT_EQ(m.colors.size(), 3u);
  for (const Vec3f& c : m.colors) {
    EXPECT_NEAR(c.x, 0.9f, kTol);
    EXPECT_NEAR(c.y, 0.4f, kTol);
    EXPECT_NEAR(c.z, 0.05f, kTol);
  }
}

TEST_F(MeshIoTest, ObjMixedMaterialsShareOneTexture) {
  // Two textured materials on the same file (loaded once) and one colour-only material without UVs.
  write_image("tex.png", make_test_image());
  write_text("mix.mtl",
             "newmtl texA\nmap_Kd tex.png\nnewmtl texB\nKd 0.5 0.5 0.5\nmap_Kd ./tex.png\n"
             "newmtl green\nKd 0 1 0\n");
  write_text("mix.obj",
             "mtllib mix.mtl\n"
             "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 5 0 0\nv 6 0 0\nv 5 1 0\n"
             "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
             "usemtl texA\nf 1/1 2/2 3/3\nusemtl texB\nf 1/1 3/3 4/4\nusemtl green\nf 5 6 7\n");
  const Mesh m = Mesh::load(file("mix.obj"));
  ASSERT_EQ(m.num_triangles(), 3);
  ASSERT_EQ(m.textures.size(), 1u);
  expect_test_texture(m.textures[0]);
  ASSERT_EQ(m.uvs.size(), m.positions.size());  // any submesh with UVs -> UVs for all vertices
  int textured = 0, coloured = 0;
  for (int t = 0; t < m.num_triangles(); ++t) {
    const Vec3f& a = m.positions[m.triangles[3 * t]];
    if (a.x >= 4.f) {  // the green triangle
      EXPECT_EQ(m.tri_texture[t], -1);
      for (int k = 0; k < 3; ++k) {
        const int v = m.triangles[3 * t + k];
        EXPECT_NEAR(m.colors[v].x, 0.f, kTol);
        EXPECT_NEAR(m.colors[v].y, 1.f, kTol);
        EXPECT_NEAR(m.colors[v].z, 0.f, kTol);
        EXPECT_EQ(m.uvs[v].x, 0.f);
        EXPECT_EQ(m.uvs[v].y, 0.f);
      }
      ++coloured;
    } else {
      EXPECT_EQ(m.tri_texture[t], 0);
      ++textured;
    }
  }
  EXPECT_EQ(textured, 2);
  EXPECT_EQ(coloured, 1);
}

TEST_F(MeshIoTest, TextureSixteenBitAndGrey) {
  // 16-bit RGB PNG -> scaled by 1/65535; 8-bit grey PNG -> r = g = b.
  cv::Mat img16(1, 2, CV_16UC3);
  img16.at<cv::Vec<uint16_t, 3>>(0, 0) = cv::Vec<uint16_t, 3>(65535, 32768, 1000);  // BGR
  img16.at<cv::Vec<uint16_t, 3>>(0, 1) = cv::Vec<uint16_t, 3>(0, 65535, 16384);
  write_image("t16.png", img16);
  cv::Mat grey(1, 2, CV_8UC1);
  grey.at<uint8_t>(0, 0) = 51;
  grey.at<uint8_t>(0, 1) = 204;
  write_image("grey.png", grey);
  write_text("m.mtl", "newmtl a\nmap_Kd t16.png\nnewmtl b\nmap_Kd grey.png\n");
  write_text("m.obj",
             "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 3 0 0\nv 4 0 0\nv 3 1 0\nvt 0 0\nvt 1 0\nvt 0 1\n"
             "usemtl a\nf 1/1 2/2 3/3\nusemtl b\nf 4/1 5/2 6/3\n");
  const Mesh m = Mesh::load(file("m.obj"));
  ASSERT_EQ(m.textures.size(), 2u);
  const diffdope::Texture* t16 = nullptr;
  const diffdope::Texture* tg = nullptr;
  for (const auto& t : m.textures) (t.source.find("t16.png") != std::string::npos ? t16 : tg) = &t;
  ASSERT_NE(t16, nullptr);
  ASSERT_NE(tg, nullptr);
  ASSERT_EQ(t16->width, 2);
  ASSERT_EQ(t16->height, 1);
  EXPECT_NEAR(t16->rgb[0], 1000 / 65535.f, 1e-6);
  EXPECT_NEAR(t16->rgb[1], 32768 / 65535.f, 1e-6);
  EXPECT_NEAR(t16->rgb[2], 1.f, 1e-6);
  EXPECT_NEAR(t16->rgb[3], 16384 / 65535.f, 1e-6);
  EXPECT_NEAR(t16->rgb[4], 1.f, 1e-6);
  EXPECT_NEAR(t16->rgb[5], 0.f, 1e-6);
  ASSERT_EQ(tg->width, 2);
  ASSERT_EQ(tg->height, 1);
  for (int c = 0; c < 3; ++c) {
    EXPECT_NEAR(tg->rgb[c], 0.2f, 1e-6);
    EXPECT_NEAR(tg->rgb[3 + c], 0.8f, 1e-6);
  }
  // Each triangle points to its own material's texture.
  for (int t = 0; t < 2; ++t) {
    const bool left = m.positions[m.triangles[3 * t]].x < 2.f;
    ASSERT_GE(m.tri_texture[t], 0);
    EXPECT_EQ(&m.textures[m.tri_texture[t]], left ? t16 : tg);
  }
}

namespace {

// glTF triangle: positions (0,0,0) (1,0,0) (0,1,0), glTF UVs (0,0) (1,0) (0,1) (top-left origin), one node
// translated by (0,0,1). Returns the binary buffer and fills the JSON (buffer URI left to the caller).
std::vector<uint8_t> gltf_triangle(nlohmann::json* g) {
  std::vector<uint8_t> buf;
  const float pos[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
  const float uv[6] = {0, 0, 1, 0, 0, 1};
  for (float v : pos) append(&buf, v);
  for (float v : uv) append(&buf, v);
  for (uint16_t i : {0, 1, 2}) append(&buf, i);
  append(&buf, static_cast<uint16_t>(0));  // pad to 4 bytes
  using nlohmann::json;
  *g = json{{"asset", {{"version", "2.0"}}},
            {"scene", 0},
            {"scenes", json::array({{{"nodes", json::array({0})}}})},
            {"nodes", json::array({{{"mesh", 0}, {"translation", {0.0, 0.0, 1.0}}}})},
            {"meshes", json::array({{{"primitives", json::array({{{"attributes", {{"POSITION", 0}, {"TEXCOORD_0", 1}}},
                                                                  {"indices", 2},
                                                                  {"material", 0}}})}}})},
            {"bufferViews", json::array({{{"buffer", 0}, {"byteOffset", 0}, {"byteLength", 36}},
                                         {{"buffer", 0}, {"byteOffset", 36}, {"byteLength", 24}},
                                         {{"buffer", 0}, {"byteOffset", 60}, {"byteLength", 6}}})},
            {"accessors", json::array({{{"bufferView", 0},
                                        {"componentType", 5126},
                                        {"count", 3},
                                        {"type", "VEC3"},
                                        {"min", {0.0, 0.0, 0.0}},
                                        {"max", {1.0, 1.0, 0.0}}},
                                       {{"bufferView", 1}, {"componentType", 5126}, {"count", 3}, {"type", "VEC2"}},
                                       {{"bufferView", 2},
                                        {"componentType", 5123},
                                        {"count", 3},
                                        {"type", "SCALAR"}}})}};
  return buf;
}

void expect_gltf_triangle(const Mesh& m, float scale) {
  ASSERT_EQ(m.num_vertices(), 3);
  ASSERT_EQ(m.num_triangles(), 1);
  // Node translation flattened into the positions, then scaled.
  const Vec3f p[3] = {{0, 0, scale}, {scale, 0, scale}, {0, scale, scale}};
  // glTF uv (0,0) = top-left -> renderer convention (u right, v up): (0, 1).
  const Vec2f uv[3] = {{0, 1}, {1, 1}, {0, 0}};
  ASSERT_EQ(m.uvs.size(), 3u);
  for (int i = 0; i < 3; ++i) {
    const int k = find_vertex(m, p[i]);
    ASSERT_GE(k, 0) << i;
    EXPECT_NEAR(m.uvs[k].x, uv[i].x, kTol) << i;
    EXPECT_NEAR(m.uvs[k].y, uv[i].y, kTol) << i;
  }
}

}  // namespace

TEST_F(MeshIoTest, GltfEmbeddedBase64Texture) {
  nlohmann::json g;
  const std::vector<uint8_t> buf = gltf_triangle(&g);
  std::vector<uint8_t> png;
  ASSERT_TRUE(cv::imencode(".png", make_test_image(), png));
  g["buffers"] = nlohmann::json::array(
      {{{"byteLength", buf.size()}, {"uri", "data:application/octet-stream;base64," + base64(buf)}}});
  g["images"] = nlohmann::json::array({{{"uri", "data:image/png;base64," + base64(png)}}});
  g["textures"] = nlohmann::json::array({{{"source", 0}}});
  g["materials"] = nlohmann::json::array({{{"pbrMetallicRoughness", {{"baseColorTexture", {{"index", 0}}}}}}});
  write_text("tri.gltf", g.dump(2));

  MeshLoadOptions opt;
  opt.scale = 2.0;
  const Mesh m = Mesh::load(file("tri.gltf"), opt);
  expect_gltf_triangle(m, 2.f);
  ASSERT_EQ(m.textures.size(), 1u);
  expect_test_texture(m.textures[0]);
  EXPECT_EQ(m.tri_texture, std::vector<int>{0});
}

TEST_F(MeshIoTest, GlbBaseColorFactor) {
  nlohmann::json g;
  std::vector<uint8_t> bin = gltf_triangle(&g);
  g["buffers"] = nlohmann::json::array({{{"byteLength", bin.size()}}});
  g["materials"] =
      nlohmann::json::array({{{"pbrMetallicRoughness", {{"baseColorFactor", {0.5, 0.25, 1.0, 1.0}}}}}});
  std::string js = g.dump();
  while (js.size() % 4) js += ' ';
  while (bin.size() % 4) bin.push_back(0);
  std::vector<uint8_t> glb;
  append(&glb, static_cast<uint32_t>(0x46546C67));  // "glTF"
  append(&glb, static_cast<uint32_t>(2));
  append(&glb, static_cast<uint32_t>(12 + 8 + js.size() + 8 + bin.size()));
  append(&glb, static_cast<uint32_t>(js.size()));
  append(&glb, static_cast<uint32_t>(0x4E4F534A));  // JSON
  glb.insert(glb.end(), js.begin(), js.end());
  append(&glb, static_cast<uint32_t>(bin.size()));
  append(&glb, static_cast<uint32_t>(0x004E4942));  // BIN
  glb.insert(glb.end(), bin.begin(), bin.end());
  write_bytes("tri.glb", glb);

  const Mesh m = Mesh::load(file("tri.glb"));
  expect_gltf_triangle(m, 1.f);
  EXPECT_TRUE(m.textures.empty());
  EXPECT_EQ(m.tri_texture, std::vector<int>{-1});
  for (const Vec3f& c : m.colors) {
    EXPECT_NEAR(c.x, 0.5f, kTol);
    EXPECT_NEAR(c.y, 0.25f, kTol);
    EXPECT_NEAR(c.z, 1.f, kTol);
  }
}

TEST_F(MeshIoTest, ErrorMissingFile) {
  const std::string path = file("does_not_exist.ply");
  const std::string msg = load_error(path);
  EXPECT_NE(msg.find(path), std::string::npos) << msg;
  EXPECT_NE(msg.find("does not exist"), std::string::npos) << msg;
}

TEST_F(MeshIoTest, ErrorMissingPlyTexture) {
  write_text("box.ply",
             "ply\nformat ascii 1.0\ncomment TextureFile missing_texture_42.png\nelement vertex 3\n"
             "property float x\nproperty float y\nproperty float z\nproperty float texture_u\n"
             "property float texture_v\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
             "0 0 0 0 0\n1 0 0 1 0\n0 1 0 0 1\n3 0 1 2\n");
  const std::string msg = load_error(file("box.ply"));
  EXPECT_NE(msg.find("missing_texture_42.png"), std::string::npos) << msg;
  EXPECT_NE(msg.find(file("box.ply")), std::string::npos) << msg;
}

TEST_F(MeshIoTest, ErrorUnreadableTexture) {
  write_text("tex.png", "this is not a png");
  write_text("m.mtl", "newmtl a\nmap_Kd tex.png\n");
  write_text("m.obj", "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nusemtl a\nf 1/1 2/2 3/3\n");
  const std::string msg = load_error(file("m.obj"));
  EXPECT_NE(msg.find("tex.png"), std::string::npos) << msg;
  EXPECT_NE(msg.find(file("m.obj")), std::string::npos) << msg;
}

TEST_F(MeshIoTest, ErrorNoFaces) {
  write_text("points.ply",
             "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
             "end_header\n0 0 0\n1 0 0\n0 1 0\n");
  const std::string msg = load_error(file("points.ply"));
  EXPECT_NE(msg.find(file("points.ply")), std::string::npos) << msg;
  EXPECT_NE(msg.find("no triangles"), std::string::npos) << msg;
  // Same for an OBJ with only points.
  write_text("points.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\np 1 2 3\n");
  EXPECT_THROW(Mesh::load(file("points.obj")), std::runtime_error);
}

TEST_F(MeshIoTest, ErrorCorruptFile) {
  std::mt19937 rng(1234);
  std::vector<uint8_t> junk(4096);
  for (auto& b : junk) b = static_cast<uint8_t>(rng());
  write_bytes("junk.ply", junk);
  EXPECT_THROW(Mesh::load(file("junk.ply")), std::runtime_error);
  // A plausible header followed by truncated binary data.
  const std::string header =
      "ply\nformat binary_little_endian 1.0\nelement vertex 100000\nproperty float x\nproperty float y\n"
      "property float z\nelement face 50000\nproperty list uchar int vertex_indices\nend_header\n";
  std::vector<uint8_t> trunc(header.begin(), header.end());
  trunc.insert(trunc.end(), junk.begin(), junk.begin() + 100);
  write_bytes("trunc.ply", trunc);
  EXPECT_THROW(Mesh::load(file("trunc.ply")), std::runtime_error);
  // A header without end_header (assimp 5.2 spins on this one: it must be refused before assimp sees it).
  write_text("noend.ply", "ply\nformat ascii 1.0\nelement vertex 3\nthis is not a mesh\n");
  std::string msg = load_error(file("noend.ply"));
  EXPECT_NE(msg.find("end_header"), std::string::npos) << msg;
  // ASCII data shorter than the header declares.
  write_text("short.ply",
             "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
             "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n");
  msg = load_error(file("short.ply"));
  EXPECT_NE(msg.find("truncated"), std::string::npos) << msg;
  // Not a PLY at all despite the extension.
  write_text("text.ply", "hello\n");
  msg = load_error(file("text.ply"));
  EXPECT_NE(msg.find("not a PLY"), std::string::npos) << msg;
  // An empty file.
  write_bytes("empty.obj", {});
  EXPECT_THROW(Mesh::load(file("empty.obj")), std::runtime_error);
}

namespace {
/// A unit square of two triangles whose shared diagonal has its corners duplicated (a UV seam): the left
/// triangle maps into texture column 0, the right one into column `right_column` of a 2x1 texture whose
/// columns are `left` and `right` colours (sampled at texel centres, so bilinear filtering reads one texel).
Mesh seam_square(const diffdope::Vec3f& left, const diffdope::Vec3f& right, int right_column) {
  Mesh m;
  m.positions = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, {0, 0, 0}, {1, 1, 0}};
  // Vertices 4 and 5 duplicate 0 and 2 (the diagonal) for the right triangle 4-1-5; the left one is 0-2-3.
  const float u0 = 0.25f, u1 = right_column == 0 ? 0.25f : 0.75f;
  m.uvs = {{u0, 0.5f}, {u1, 0.5f}, {u0, 0.5f}, {u0, 0.5f}, {u1, 0.5f}, {u1, 0.5f}};
  m.triangles = {4, 1, 5, 0, 2, 3};
  m.colors.assign(m.positions.size(), {0.5f, 0.5f, 0.5f});
  m.tri_texture = {0, 0};
  diffdope::Texture t;
  t.width = 2, t.height = 1;
  t.rgb = {left.x, left.y, left.z, right.x, right.y, right.z};
  m.textures.push_back(t);
  m.finalize();
  return m;
}
bool any_seam(const Mesh& m) {
  for (unsigned char s : m.seams()) if (s) return true;
  return false;
}
}  // namespace

TEST(MeshSeams, AColourSeamIsWhereTheColourJumpsNotWhereOnlyTheUvsDo) {
  const diffdope::Vec3f red{0.8f, 0.1f, 0.1f}, blue{0.1f, 0.1f, 0.8f}, almost_red{0.82f, 0.1f, 0.1f};
  // The diagonal is shared (neighbours found across the duplicated corners) in every case.
  const Mesh jump = seam_square(red, blue, 1);
  ASSERT_EQ(jump.neighbors()[3 * 0 + 2], 1);
  EXPECT_TRUE(any_seam(jump));                           // other UVs, other colour: a crease between prints
  EXPECT_FALSE(any_seam(seam_square(red, red, 1)));       // other UVs, same colour: an atlas chart border
  EXPECT_FALSE(any_seam(seam_square(red, almost_red, 1)));  // within the tolerance (resampling differences)
  EXPECT_FALSE(any_seam(seam_square(red, blue, 0)));      // same UVs on both sides: no seam at all
  // Vertex colours: a jump is a seam, equal colours on duplicated corners are not.
  Mesh coloured = seam_square(red, red, 1);
  coloured.tri_texture = {-1, -1};
  coloured.textures.clear();
  coloured.uvs.clear();
  for (int i : {1, 4, 5}) coloured.colors[size_t(i)] = blue;
  coloured.finalize();
  EXPECT_TRUE(any_seam(coloured));
  for (auto& c : coloured.colors) c = red;
  coloured.finalize();
  EXPECT_FALSE(any_seam(coloured));
}
