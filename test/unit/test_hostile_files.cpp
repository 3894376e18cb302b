// Hostile mesh and texture files: a corpus the test writes itself of files that crashed assimp,
// made it read out of bounds or allocate gigabytes. Each must end in a clear error, with bounded memory, and the
// test process (a node, in real life) keeps running. Also the child-process isolation itself: a crash, a
// runaway allocation or a hang inside the import costs only an error.
#include <gtest/gtest.h>

#include <assimp/Importer.hpp>
#include <assimp/postprocess.h>
#include <assimp/scene.h>

#include <signal.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <opencv2/imgcodecs.hpp>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "diffdope/mesh.hpp"
#include "base/thread_pool.hpp"
#include "mesh/isolated_call.hpp"

namespace fs = std::filesystem;
using namespace diffdope;

namespace {

class HostileFiles : public ::testing::Test {
 protected:
  void SetUp() override {
    std::random_device rd;
    dir_ = fs::temp_directory_path() /
           ("diffdope_hostile_" + std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()) +
            "_" + std::to_string(rd()));
    fs::create_directories(dir_);
  }
  void TearDown() override {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }
  std::string write(const std::string& name, const std::string& bytes) const {
    std::ofstream out(dir_ / name, std::ios::binary);
    out.write(bytes.data(), std::streamsize(bytes.size()));
    return (dir_ / name).string();
  }
  fs::path dir_;
};

/// The message Mesh::load gives, "" when it loads.
std::string load_error(const std::string& path, const MeshLoadOptions& o = {}) {
  try {
    Mesh::load(path, o);
  } catch (const std::runtime_error& e) {
    return e.what();
  }
  return "";
}

template <typename T>
void put(std::string& s, T v) {
  s.append(reinterpret_cast<const char*>(&v), sizeof v);
}

/// A binary little-endian PLY: `vertices` float xyz vertices, then faces given as (count, indices...) with a
/// uchar count and int indices, then `tail` bytes as they are.
std::string binary_ply(int vertices, const std::vector<std::vector<int>>& faces, int declared_faces = -1) {
  std::string s = "ply\nformat binary_little_endian 1.0\nelement vertex " + std::to_string(vertices) +
                  "\nproperty float x\nproperty float y\nproperty float z\nelement face " +
                  std::to_string(declared_faces < 0 ? int(faces.size()) : declared_faces) +
                  "\nproperty list uchar int vertex_indices\nend_header\n";
  for (int v = 0; v < vertices; ++v) put(s, float(v % 2)), put(s, float(v / 2 % 2)), put(s, float(v / 4));
  for (const auto& f : faces) {
    put(s, uint8_t(f.size()));
    for (int i : f) put(s, int32_t(i));
  }
  return s;
}

const char* kAsciiHeader =
    "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
    "element face 2\nproperty list uchar int vertex_indices\nend_header\n";

}  // namespace

TEST_F(HostileFiles, ABinaryPlyWithAFaceIndexOutOfRangeIsRefused) {
  EXPECT_EQ(load_error(write("ok.ply", binary_ply(8, {{0, 1, 2}, {1, 3, 2}}))), "");
  const std::string m = load_error(write("bad.ply", binary_ply(8, {{0, 1, 2}, {1, 99999, 2}})));
  EXPECT_NE(m.find("face 1 refers to vertex 99999; the file has 8 vertices"), std::string::npos) << m;
  const std::string neg = load_error(write("neg.ply", binary_ply(8, {{0, -5, 2}})));
  EXPECT_NE(neg.find("refers to vertex -5"), std::string::npos) << neg;
}

/// The corpus of binary PLYs that crash assimp (Debian 12's 5.2) in its own process.
std::vector<std::string> assimp_crashers(const std::function<std::string(const std::string&, const std::string&)>& write) {
  std::string trunc = binary_ply(8, {{0, 1, 2}, {1, 3, 2}});
  trunc.resize(trunc.size() - 6);
  std::string list255 = binary_ply(8, {{0, 1, 2}}, 2);
  list255.push_back(char(255));
  for (int i = 0; i < 40; ++i) put(list255, int32_t(i % 8));
  return {write("index.ply", binary_ply(8, {{0, 1, 2}, {1, 99999, 2}})), write("trunc.ply", trunc),
          write("list255.ply", list255)};
}

TEST_F(HostileFiles, FilesThatCrashAssimpItselfAreOnlyAnErrorForMeshLoad) {
  const auto files = assimp_crashers([&](const std::string& n, const std::string& b) { return write(n, b); });
  int crashed = 0;
  for (const std::string& f : files) {
    // assimp alone, in a child: these files crash it (which is what a node would have died of).
    try {
      run_isolated([&] {
        Assimp::Importer importer;
        const aiScene* scene = importer.ReadFile(f, aiProcess_Triangulate | aiProcess_JoinIdenticalVertices);
        return std::string(scene ? "loaded" : "error");
      }, {}, "assimp");
    } catch (const std::runtime_error& e) {
      crashed += std::string(e.what()).find("crashed") != std::string::npos;
    }
    for (bool isolate : {true, false}) {  // our checks refuse them before assimp, isolated or not
      MeshLoadOptions o;
      o.isolate_import = isolate;
      const std::string m = load_error(f, o);
      EXPECT_NE(m, "") << f;
      EXPECT_EQ(m.find("crashed"), std::string::npos) << m;
    }
  }
  EXPECT_GE(crashed, 1) << "none of the corpus crashes this assimp any more: the corpus needs new crashers";
}

TEST_F(HostileFiles, ATruncatedBinaryBodyOrAHugeListCountIsRefused) {
  std::string s = binary_ply(8, {{0, 1, 2}, {1, 3, 2}});
  s.resize(s.size() - 6);
  EXPECT_NE(load_error(write("trunc.ply", s)).find("truncated PLY"), std::string::npos);
  // A face list count of 255 whose indices are the rest of the file (and beyond).
  std::string big = binary_ply(8, {{0, 1, 2}});
  big.push_back(char(255));
  for (int i = 0; i < 40; ++i) put(big, int32_t(i % 8));
  const std::string header_fix = "element face 2";
  big.replace(big.find("element face 1"), header_fix.size(), header_fix);
  EXPECT_NE(load_error(write("list255.ply", big)).find("truncated PLY"), std::string::npos);
}

// fuzz_mesh_ply's find: a corrupt property line left an element of 2e18 records with nothing to read, which the
// body check walked for ever.
TEST_F(HostileFiles, AHeaderWithUnknownLinesOrEmptyHugeElementsEndsAtOnce) {
  std::string s = binary_ply(8, {{0, 1, 2}});
  s.replace(s.find("property list"), 8, "propert ");
  EXPECT_NE(load_error(write("bad_line.ply", s)).find("corrupt PLY header: unknown line 'propert"), std::string::npos);
  std::string empty = binary_ply(8, {{0, 1, 2}});
  empty.insert(empty.find("end_header"), "element junk 2222222222222222221\n");
  // Counts no file could hold (their sum overflowed a 64-bit integer).
  std::string huge = binary_ply(8, {{0, 1, 2}});
  huge.insert(huge.find("end_header"), "element face 9223372036854775807\nproperty uchar a\n");
  huge.insert(huge.find("end_header"), "element face 9223372036854775807\nproperty uchar b\n");
  EXPECT_NE(load_error(write("huge.ply", huge)).find("corrupt PLY header: 'element face 9223372036854775807"),
            std::string::npos);
  const auto t0 = std::chrono::steady_clock::now();
  load_error(write("empty.ply", empty));
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 10.0);
}

TEST_F(HostileFiles, AsciiPlyGarbageAndBadIndicesAreRefused) {
  const std::string good = std::string(kAsciiHeader) + "0 0 0\n1 0 0\n0 1 0\n1 1 0\n3 0 1 2\n3 1 3 2\n";
  EXPECT_EQ(load_error(write("good.ply", good)), "");
  const std::string garbage =
      std::string(kAsciiHeader) + "0 0 0\n1 0 0 xx yy zz\n0 1 0\n1 1 0\n3 0 1 2\n3 1 3 2\n";
  std::string m = load_error(write("garbage.ply", garbage));
  EXPECT_NE(m.find("PLY body line 2 (vertex 1): more values than the header declares"), std::string::npos) << m;
  const std::string words = std::string(kAsciiHeader) + "0 0 0\n1 0 0\nnot a number\n1 1 0\n3 0 1 2\n3 1 3 2\n";
  m = load_error(write("words.ply", words));
  EXPECT_NE(m.find("expected a number for 'x'"), std::string::npos) << m;
  const std::string index = std::string(kAsciiHeader) + "0 0 0\n1 0 0\n0 1 0\n1 1 0\n3 0 1 2\n3 1 99999 2\n";
  m = load_error(write("index.ply", index));
  EXPECT_NE(m.find("refers to vertex 99999; the file has 4 vertices"), std::string::npos) << m;
  // fuzz_mesh_ply's find: an index too large for an integer (its message cast it: undefined behaviour).
  const std::string huge = std::string(kAsciiHeader) + "0 0 0\n1 0 0\n0 1 0\n1 1 0\n3 0 1 2\n3 1 1e19 2\n";
  m = load_error(write("huge.ply", huge));
  EXPECT_NE(m.find("refers to vertex 10000000000000000000"), std::string::npos) << m;
  const std::string two = std::string(kAsciiHeader) + "0 0 0\n1 0 0\n0 1 0\n1 1 0\n2 0 1\n3 1 3 2\n";
  m = load_error(write("two.ply", two));
  EXPECT_NE(m.find("a face of 2 vertices"), std::string::npos) << m;
}

TEST_F(HostileFiles, AGlbWhoseChunkLengthIsHugeIsRefusedBeforeAnyAllocation) {
  // 872 bytes like the file: a valid header, then a JSON chunk that claims ~4 GB.
  std::string glb = "glTF";
  put(glb, uint32_t(2)), put(glb, uint32_t(872));
  put(glb, uint32_t(0xF0000000u)), glb += "JSON";
  glb += std::string(872 - glb.size(), ' ');
  std::string m = load_error(write("huge.glb", glb));
  EXPECT_NE(m.find("corrupt GLB: a chunk of"), std::string::npos) << m;
  std::string bad_total = glb;
  const uint32_t total = 1u << 31;
  std::memcpy(&bad_total[8], &total, 4);
  m = load_error(write("total.glb", bad_total));
  EXPECT_NE(m.find("the header declares"), std::string::npos) << m;
  m = load_error(write("short.glb", "glTF"));
  EXPECT_NE(m.find("truncated GLB"), std::string::npos) << m;
}

TEST_F(HostileFiles, AnObjWhoseMaterialLibraryIsMissingIsAnError) {
  const std::string obj = "mtllib gone.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl a\nf 1 2 3\n";
  const std::string m = load_error(write("m.obj", obj));
  EXPECT_NE(m.find("material library 'gone.mtl' not found"), std::string::npos) << m;
  write("gone.mtl", "newmtl a\nKd 0.2 0.4 0.6\n");
  EXPECT_EQ(load_error((dir_ / "m.obj").string()), "");
}

TEST_F(HostileFiles, AHugeTextureIsRefusedFromItsHeaderAndABigOneIsDownsampled) {
  const std::string ply_head =
      "ply\nformat ascii 1.0\ncomment TextureFile tex.png\nelement vertex 3\nproperty float x\nproperty float y\n"
      "property float z\nproperty float texture_u\nproperty float texture_v\nelement face 1\n"
      "property list uchar int vertex_indices\nend_header\n0 0 0 0 0\n1 0 0 1 0\n0 1 0 0 1\n3 0 1 2\n";
  write("m.ply", ply_head);
  // A PNG whose header says 16384 x 16384: refused before a byte is decoded (7 GB otherwise).
  std::string png = "\x89PNG\r\n\x1a\n";
  png += std::string("\0\0\0\x0dIHDR", 8);
  png += std::string("\0\0\x40\0\0\0\x40\0\x08\x02\0\0\0", 13);
  png += std::string(4, '\0');  // (CRC: never read)
  write("tex.png", png);
  std::string m = load_error((dir_ / "m.ply").string());
  EXPECT_NE(m.find("16384 x 16384 pixels: more than the limit"), std::string::npos) << m;
  // A real 300 x 200 texture with a 64-pixel cap: kept at 64 x 43.
  cv::Mat img(200, 300, CV_8UC3, cv::Scalar(10, 200, 30));
  ASSERT_TRUE(cv::imwrite((dir_ / "tex.png").string(), img));
  MeshLoadOptions o;
  o.max_texture_size = 64;
  const Mesh mesh = Mesh::load((dir_ / "m.ply").string(), o);
  ASSERT_EQ(mesh.textures.size(), 1u);
  EXPECT_EQ(mesh.textures[0].width, 64);
  EXPECT_EQ(mesh.textures[0].height, 43);
  EXPECT_NEAR(mesh.textures[0].rgb[1], 200 / 255.f, 1e-3);  // (RGB order: green)
}

// A model reads its textures, material libraries and buffers from its folder (or MeshLoadOptions::resource_dirs)
// only: a file that names ../../secret.png or /etc/passwd is refused, not opened.
TEST_F(HostileFiles, AModelReadsOnlyFromItsOwnFolder) {
  fs::create_directories(dir_ / "model");
  fs::create_directories(dir_ / "elsewhere");
  cv::Mat img(8, 8, CV_8UC3, cv::Scalar(10, 200, 30));
  ASSERT_TRUE(cv::imwrite((dir_ / "elsewhere/secret.png").string(), img));
  ASSERT_TRUE(cv::imwrite((dir_ / "model/tex.png").string(), img));
  const std::string ply_body =
      "element vertex 3\nproperty float x\nproperty float y\nproperty float z\nproperty float texture_u\n"
      "property float texture_v\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
      "0 0 0 0 0\n1 0 0 1 0\n0 1 0 0 1\n3 0 1 2\n";
  const auto ply = [&](const std::string& texture) {
    return "ply\nformat ascii 1.0\ncomment TextureFile " + texture + "\n" + ply_body;
  };
  std::string m = load_error(write("model/up.ply", ply("../elsewhere/secret.png")));
  EXPECT_NE(m.find("outside the model's folder"), std::string::npos) << m;
  m = load_error(write("model/abs.ply", ply((dir_ / "elsewhere/secret.png").string())));
  EXPECT_NE(m.find("outside the model's folder"), std::string::npos) << m;
  // A link inside the folder that points out is outside too.
  fs::create_symlink(dir_ / "elsewhere/secret.png", dir_ / "model/link.png");
  m = load_error(write("model/link.ply", ply("link.png")));
  EXPECT_NE(m.find("outside the model's folder"), std::string::npos) << m;
  // A folder the caller allows, and the model's own texture, load.
  MeshLoadOptions allowed;
  allowed.resource_dirs = {(dir_ / "elsewhere").string()};
  EXPECT_EQ(load_error((dir_ / "model/up.ply").string(), allowed), "");
  EXPECT_EQ(load_error(write("model/own.ply", ply("tex.png"))), "");
  // OBJ material libraries: outside, absolute, or not a file.
  const std::string tri = "v 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl a\nf 1 2 3\n";
  write("elsewhere/m.mtl", "newmtl a\nKd 0.2 0.4 0.6\n");
  m = load_error(write("model/up.obj", "mtllib ../elsewhere/m.mtl\n" + tri));
  EXPECT_NE(m.find("outside the model's folder"), std::string::npos) << m;
  m = load_error(write("model/abs.obj", "mtllib /etc/passwd\n" + tri));
  EXPECT_NE(m.find("absolute path"), std::string::npos) << m;
  ASSERT_EQ(::mkfifo((dir_ / "model/pipe.mtl").c_str(), 0600), 0);
  m = load_error(write("model/pipe.obj", "mtllib pipe.mtl\n" + tri));
  EXPECT_NE(m.find("not a regular file"), std::string::npos) << m;
  // glTF buffers: a pipe would hang the importer; outside the folder is refused.
  ASSERT_EQ(::mkfifo((dir_ / "model/pipe.bin").c_str(), 0600), 0);
  const auto gltf = [](const std::string& uri) {
    return "{\"asset\": {\"version\": \"2.0\"}, \"buffers\": [{\"uri\": \"" + uri + "\", \"byteLength\": 36}]}";
  };
  m = load_error(write("model/pipe.gltf", gltf("pipe.bin")));
  EXPECT_NE(m.find("buffer 'pipe.bin' is not a regular file"), std::string::npos) << m;
  write("elsewhere/b.bin", std::string(36, '\0'));
  m = load_error(write("model/up.gltf", gltf("../elsewhere/b.bin")));
  EXPECT_NE(m.find("outside the model's folder"), std::string::npos) << m;
}

// An n-gon costs assimp's triangulation n^2 (a 5 MB file of 32k-gons ran the import child's full minute), and
// assimp allocates for every face of an OBJ before anything checks the count.
TEST_F(HostileFiles, HugePolygonsAndTooManyObjFacesAreRefusedBeforeImport) {
  std::string ply = "ply\nformat ascii 1.0\nelement vertex 2000\nproperty float x\nproperty float y\n"
                    "property float z\nelement face 1\nproperty list ushort int vertex_indices\nend_header\n";
  for (int v = 0; v < 2000; ++v) ply += std::to_string(std::cos(v * 0.00314)) + " " + std::to_string(std::sin(v * 0.00314)) + " 0\n";
  ply += "2000";
  for (int v = 0; v < 2000; ++v) ply += " " + std::to_string(v);
  std::string m = load_error(write("gon.ply", ply + "\n"));
  EXPECT_NE(m.find("polygon of 2000 vertices: at most 1024"), std::string::npos) << m;
  std::string obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\n";
  for (int f = 0; f < 50; ++f) obj += "f 1 2 3\nf 2 4 3\n";
  MeshLoadOptions few;
  few.max_triangles = 99;
  m = load_error(write("many.obj", obj), few);
  EXPECT_NE(m.find("100 triangles: more than the limit"), std::string::npos) << m;
  few.max_triangles = 100;
  EXPECT_EQ(load_error((dir_ / "many.obj").string(), few), "");
}

TEST_F(HostileFiles, ManyTexturesTogetherHaveABudget) {
  // Two materials, each with its own 64 x 64 texture: 8192 pixels together.
  cv::Mat img(64, 64, CV_8UC3, cv::Scalar(10, 200, 30));
  ASSERT_TRUE(cv::imwrite((dir_ / "a.png").string(), img));
  ASSERT_TRUE(cv::imwrite((dir_ / "b.png").string(), img));
  write("m.mtl", "newmtl a\nmap_Kd a.png\nnewmtl b\nmap_Kd b.png\n");
  const std::string obj = write("m.obj", "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nvt 0 0\nvt 1 0\nvt 0 1\n"
                                          "vt 1 1\nusemtl a\nf 1/1 2/2 3/3\nusemtl b\nf 2/2 4/4 3/3\n");
  MeshLoadOptions small;
  small.max_total_texture_pixels = 6000;
  const std::string m = load_error(obj, small);
  EXPECT_NE(m.find("textures hold more than 6000 pixels together"), std::string::npos) << m;
  small.max_total_texture_pixels = 8192;
  EXPECT_EQ(load_error(obj, small), "");
}

TEST_F(HostileFiles, AFileIsReadOnlyAsTheFormatItsExtensionNames) {
  // A valid PLY named .gltf: assimp alone would sniff it and read it as PLY (and garbage as anything, 3DS
  // included, which the fuzzer found allocating terabytes).
  const std::string ply = std::string(kAsciiHeader) + "0 0 0\n1 0 0\n0 1 0\n1 1 0\n3 0 1 2\n3 1 3 2\n";
  EXPECT_EQ(load_error(write("ok.ply", ply)), "");
  EXPECT_NE(load_error(write("not.gltf", ply)), "");
  EXPECT_NE(load_error(write("not.stl", "glTF")), "");
  // fuzz_mesh_gltf's find (40 bytes another reader took for its own format, then asked for 4.6 TB).
  const unsigned char found[40] = {0x71, 0x75, 0x69, 0x63, 0x6b, 0x33, 0x64, 0x73, 0x30, 0xff, 0xff, 0xff, 0xff, 0xff,
                                   0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff,
                                   0xff, 0xff, 0xff, 0xff, 0xff, 0x20, 0x30, 0x2e, 0x77, 0x20, 0x5d, 0x61};
  MeshLoadOptions in_process;
  in_process.isolate_import = false;
  EXPECT_NE(load_error(write("found.gltf", std::string(reinterpret_cast<const char*>(found), 40)), in_process), "");
  const std::string m = load_error(write("x.unknownformat", ply));
  EXPECT_NE(m.find("no reader for '.unknownformat' files"), std::string::npos) << m;
}

TEST_F(HostileFiles, TooManyVerticesAreRefusedFromTheHeader) {
  MeshLoadOptions o;
  o.max_vertices = 4;
  const std::string m = load_error(write("big.ply", binary_ply(8, {{0, 1, 2}})), o);
  EXPECT_NE(m.find("more than the limit"), std::string::npos) << m;
}

TEST_F(HostileFiles, RandomBytesUnderEveryExtensionEndInAnError) {
  std::mt19937 rng(7);
  for (const char* ext : {".ply", ".obj", ".glb", ".gltf", ".stl", ".dae", ".off"}) {
    for (int k = 0; k < 4; ++k) {
      std::string junk(256 + 512 * k, '\0');
      for (char& c : junk) c = char(rng());
      if (k == 1 && std::string(ext) == ".ply") junk.replace(0, 4, "ply\n");
      if (k == 1 && std::string(ext) == ".glb") junk.replace(0, 4, "glTF");
      const std::string path = write(std::string("junk") + std::to_string(k) + ext, junk);
      EXPECT_NE(load_error(path), "") << path << " loaded";
    }
  }
}

// ---- the isolation itself ----

TEST(IsolatedCall, ReturnsTheChildsAnswerOrItsError) {
  EXPECT_EQ(run_isolated([] { return std::string("abc\0def", 7); }, {}, "test"), std::string("abc\0def", 7));
  try {
    run_isolated([]() -> std::string { throw std::runtime_error("no such thing"); }, {}, "test");
    FAIL();
  } catch (const std::runtime_error& e) {
    EXPECT_STREQ(e.what(), "no such thing");
  }
  // A big answer (more than a pipe holds) arrives whole.
  const std::string big = run_isolated([] { return std::string(5 << 20, 'x'); }, {}, "test");
  EXPECT_EQ(big.size(), size_t(5 << 20));
}

TEST(IsolatedCall, ACrashInTheChildIsAnErrorHere) {
  try {
    run_isolated([]() -> std::string {
      ::raise(SIGSEGV);
      return "";
    }, {}, "importing");
    FAIL();
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("importing: crashed (signal 11"), std::string::npos) << e.what();
  }
  try {
    run_isolated([]() -> std::string { std::abort(); }, {}, "importing");
    FAIL();
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("signal 6"), std::string::npos) << e.what();
  }
}

TEST(IsolatedCall, AHangingChildIsStoppedAtTheTimeLimit) {
  IsolationLimits l;
  l.timeout_s = 0.5;
  const auto t0 = std::chrono::steady_clock::now();
  try {
    run_isolated([]() -> std::string {
      for (;;) std::this_thread::sleep_for(std::chrono::seconds(1));
    }, l, "importing");
    FAIL();
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("took longer than"), std::string::npos) << e.what();
  }
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 10.0);
}

#if !defined(__SANITIZE_ADDRESS__)
TEST(IsolatedCall, ARunawayAllocationInTheChildHitsItsMemoryLimit) {
  IsolationLimits l;
  l.address_space_bytes = size_t(1) << 30;
  try {
    run_isolated([]() -> std::string {
      std::vector<std::string> hog;
      for (;;) hog.emplace_back(size_t(64) << 20, 'x');  // 64 MB at a time, touched
    }, l, "importing");
    FAIL();
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("ran out of memory"), std::string::npos) << e.what();
  }
}

/// This process's address space in bytes (VmSize).
size_t address_space_in_use() {
  std::ifstream status("/proc/self/status");
  for (std::string line; std::getline(status, line);)
    if (line.rfind("VmSize:", 0) == 0) return size_t(std::stoull(line.substr(7))) * 1024;
  return 0;
}

TEST(ThreadPool, MoreThreadsThanTheSystemGivesIsAnErrorNotAHang) {
  // `render.threads: 100000` used to hang for ever: the pool's constructor threw while its started workers
  // waited. In a child whose address space leaves room for a few thread stacks only (the thread limit itself
  // cannot be reached as root), asking for 256 threads must fail with a message, and quickly.
  const size_t in_use = address_space_in_use();
  ASSERT_GT(in_use, 0u);
  IsolationLimits l;
  l.address_space_bytes = in_use + (size_t(256) << 20);  // ~256 MB more: a few 8 MB stacks and malloc arenas
  l.timeout_s = 30;  // a hang is reported as "took longer than"
  const std::string answer = run_isolated([]() -> std::string {
    try {
      ThreadPool pool(256);
      return "started " + std::to_string(pool.size()) + " threads";
    } catch (const std::runtime_error& e) {
      return e.what();
    }
  }, l, "starting threads");
  EXPECT_NE(answer.find("thread pool: could not start 256 threads"), std::string::npos) << answer;
  // The pool still works at a size the system allows.
  ThreadPool pool(4);
  std::atomic<int> sum{0};
  pool.parallel_for(100, [&](int i, int) { sum += i; });
  EXPECT_EQ(sum.load(), 4950);
}
#endif
