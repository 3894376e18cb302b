// The small files users hand over (cameras, poses, options, images): pipes are refused before they are opened,
// nesting and YAML alias expansion are bounded, image sizes are read from the header before decoding, images are
// read as stored (no EXIF rotation), float colour must be finite and in range.
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <csignal>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <functional>
#include <limits>
#include <string>
#include <vector>

#include "diffdope/image_file.hpp"
#include "diffdope/input_files.hpp"
#include "diffdope/input_limits.hpp"
#include "diffdope/object_config.hpp"
#include "diffdope/observation.hpp"
#include "diffdope/refiner.hpp"

using namespace diffdope;
namespace fs = std::filesystem;

namespace {

struct InputFiles : ::testing::Test {
  fs::path dir;
  void SetUp() override {
    dir = fs::temp_directory_path() / ("diffdope_input_files_" + std::to_string(::getpid()));
    fs::create_directories(dir);
    // A reader that opens a pipe blocks forever: the alarm turns that into a failed (killed) test.
    alarm(60);
  }
  void TearDown() override {
    alarm(0);
    fs::remove_all(dir);
  }
  std::string write(const std::string& name, const std::string& bytes) {
    const fs::path p = dir / name;
    std::ofstream(p, std::ios::binary) << bytes;
    return p.string();
  }
  std::string fifo(const std::string& name) {
    const fs::path p = dir / name;
    EXPECT_EQ(::mkfifo(p.c_str(), 0600), 0);
    return p.string();
  }
};

/// The message of what f throws ("" when it throws nothing).
template <class F>
std::string error_of(F&& f) {
  try {
    f();
  } catch (const std::exception& e) {
    return e.what();
  }
  return "";
}

/// {"a": {"a": ... 1 ...}} nested `depth` times.
std::string nested_json(int depth) {
  std::string s;
  for (int i = 0; i < depth; ++i) s += "{\"a\":";
  s += "1";
  s.append(size_t(depth), '}');
  return s;
}

/// A "billion laughs": ten levels, each a list of nine aliases of the one before (9^10 values), under `key`.
std::string laughs(const std::string& key) {
  std::string s = "l0: &l0 [x, x, x, x, x, x, x, x, x]\n";
  for (int i = 1; i < 10; ++i) {
    s += "l" + std::to_string(i) + ": &l" + std::to_string(i) + " [";
    for (int j = 0; j < 9; ++j) s += std::string(j ? ", " : "") + "*l" + std::to_string(i - 1);
    s += "]\n";
  }
  return s + key + ": *l9\n";
}

std::string png_header(uint32_t w, uint32_t h) {
  std::string s("\x89PNG\r\n\x1a\n\0\0\0\x0dIHDR", 16);
  for (uint32_t v : {w, h})
    for (int b = 3; b >= 0; --b) s += char((v >> (8 * b)) & 0xFF);
  return s + std::string("\x08\x02\0\0\0", 5) + std::string(64, '\0');
}

}  // namespace

TEST_F(InputFiles, PipesAreRefusedBeforeTheyAreOpened) {
  const std::string pipe = fifo("pipe");
  for (const auto& read : std::vector<std::function<void()>>{
           [&] { read_camera_file(pipe, 640, 480); }, [&] { read_pose_file(pipe); },
           [&] { read_text_file(pipe, "a URDF"); }, [&] { RefinerOptions::from_yaml_file(pipe); },
           [&] { read_image_file(pipe, cv::IMREAD_COLOR, "rgb", input_limits::kMaxImagePixels); }}) {
    const std::string e = error_of(read);
    EXPECT_NE(e.find("pipe (FIFO)"), std::string::npos) << e;
  }
  // A link to a pipe is a pipe (a shell's <(...) is /dev/fd/N, a link).
  fs::create_symlink(pipe, dir / "link.json");
  EXPECT_NE(error_of([&] { read_pose_file((dir / "link.json").string()); }).find("pipe"), std::string::npos);
  EXPECT_NE(error_of([&] { read_pose_file("/dev/null"); }).find("a device"), std::string::npos);
}

TEST_F(InputFiles, DeepJsonIsRefusedWhileParsing) {
  const std::string deep = write("deep.json", nested_json(100000));
  const std::string e = error_of([&] { read_pose_file(deep); });
  EXPECT_NE(e.find("nested deeper than 64"), std::string::npos) << e.substr(0, 200);
  EXPECT_LT(e.size(), 200u);
  // As deep as allowed is only "not a pose".
  const std::string ok = write("ok.json", nested_json(input_limits::kMaxNesting - 1));
  EXPECT_EQ(error_of([&] { read_pose_file(ok); }).find("nested"), std::string::npos);
  EXPECT_NE(error_of([&] { parse_json_checked(nested_json(1000), "x.json"); }).find("nested"), std::string::npos);
}

TEST_F(InputFiles, YamlAliasesCannotExpandWithoutBound) {
  const std::string camera = write("camera.yaml", laughs("fx"));
  EXPECT_NE(error_of([&] { read_camera_file(camera, 640, 480); }).find("expands to more than"), std::string::npos);
  const std::string options = write("options.yaml", laughs("iterations"));
  EXPECT_NE(error_of([&] { RefinerOptions::from_yaml_file(options); }).find("expands to more than"),
            std::string::npos);
  EXPECT_NE(error_of([&] { parse_objects_config(laughs("objects"), "objects.yaml", dir.string()); })
                .find("expands to more than"),
            std::string::npos);
  // Aliases used a few times are fine.
  EXPECT_EQ(RefinerOptions::from_yaml_string("iterations: &n 7\nbatch_size: *n\n", "s").batch_size, 7);
}

TEST_F(InputFiles, ImageSizesComeFromTheHeader) {
  long long w = 0, h = 0;
  ASSERT_TRUE(image_header_size(png_header(20000, 300), &w, &h));
  EXPECT_EQ(w, 20000);
  EXPECT_EQ(h, 300);
  // Encoded by OpenCV in every format the reader knows: the header's size is the image's.
  const cv::Mat img(37, 53, CV_8UC3, cv::Scalar(10, 20, 30));
  for (const char* ext : {".png", ".jpg", ".bmp", ".tif", ".ppm"}) {
    std::vector<uchar> buf;
    ASSERT_TRUE(cv::imencode(ext, img, buf)) << ext;
    w = h = 0;
    ASSERT_TRUE(image_header_size(std::string(buf.begin(), buf.end()), &w, &h)) << ext;
    EXPECT_EQ(w, 53) << ext;
    EXPECT_EQ(h, 37) << ext;
  }
  // A JPEG with a junk byte before its frame header: decoders skip it, so the check must too.
  std::vector<uchar> jpg;
  cv::imencode(".jpg", img, jpg);
  std::string junk(jpg.begin(), jpg.end());
  junk.insert(2, 1, '\x42');
  ASSERT_TRUE(image_header_size(junk, &w, &h));
  EXPECT_EQ(w, 53);
  EXPECT_FALSE(image_header_size("GIF89a........", &w, &h));
}

TEST_F(InputFiles, HugeImagesAreRefusedBeforeDecoding) {
  // 20000 x 20000 claimed by a file of a few bytes: refused from the header, nothing allocated.
  const std::string png = write("huge.png", png_header(20000, 20000));
  std::string e = error_of([&] { read_image_file(png, cv::IMREAD_COLOR, "rgb", input_limits::kMaxImagePixels); });
  EXPECT_NE(e.find("20000x20000"), std::string::npos) << e;
  // A format whose size cannot be read first is not decoded at all.
  const std::string gif = write("x.gif", "GIF89a\x10\x00\x10\x00");
  e = error_of([&] { read_image_file(gif, cv::IMREAD_COLOR, "rgb", input_limits::kMaxImagePixels); });
  EXPECT_NE(e.find("not PNG, JPEG, BMP, TIFF or PNM"), std::string::npos) << e;
  // A TIFF claiming 30000 x 30000 (little-endian, two LONG tags).
  std::string tif("II*\0\x08\0\0\0\x02\0", 10);
  const auto entry = [](uint16_t tag, uint32_t v) {
    std::string s(12, '\0');
    s[0] = char(tag & 0xFF), s[1] = char(tag >> 8), s[2] = 4, s[4] = 1;
    std::memcpy(&s[8], &v, 4);
    return s;
  };
  tif += entry(256, 30000) + entry(257, 30000) + std::string(4, '\0');
  const std::string tiff = write("huge.tif", tif);
  e = error_of([&] { read_image_file(tiff, cv::IMREAD_COLOR, "rgb", input_limits::kMaxImagePixels); });
  EXPECT_NE(e.find("30000x30000"), std::string::npos) << e;
}

TEST_F(InputFiles, ImagesAreReadAsStoredWithoutExifRotation) {
  // A 4 x 2 JPEG whose EXIF says "rotate 180 degrees" (orientation 3), left half black, right half white.
  cv::Mat img(16, 32, CV_8UC3, cv::Scalar(0, 0, 0));
  img(cv::Rect(16, 0, 16, 16)).setTo(cv::Scalar(255, 255, 255));
  std::vector<uchar> jpg;
  ASSERT_TRUE(cv::imencode(".jpg", img, jpg));
  const std::string tiff("II*\0\x08\0\0\0\x01\0\x12\x01\x03\0\x01\0\0\0\x03\0\0\0\0\0\0\0", 26);
  const std::string payload = std::string("Exif\0\0", 6) + tiff;
  std::string app1 = "\xFF\xE1";
  app1 += char((payload.size() + 2) >> 8), app1 += char((payload.size() + 2) & 0xFF);
  std::string bytes(jpg.begin(), jpg.end());
  bytes.insert(2, app1 + payload);
  const std::string path = write("exif.jpg", bytes);
  // (OpenCV's own default would turn it: the file does say 180 degrees.)
  const cv::Mat turned = cv::imread(path, cv::IMREAD_COLOR);
  ASSERT_EQ(turned.cols, 32);
  EXPECT_GT(turned.at<cv::Vec3b>(8, 2)[0], 215);
  const cv::Mat read = read_image_file(path, cv::IMREAD_COLOR, "rgb", input_limits::kMaxImagePixels);
  ASSERT_EQ(read.cols, 32);
  EXPECT_LT(read.at<cv::Vec3b>(8, 2)[0], 40);    // still dark on the left
  EXPECT_GT(read.at<cv::Vec3b>(8, 29)[0], 215);  // and light on the right
}

TEST_F(InputFiles, FloatColourMustBeFiniteAndInRange) {
  cv::Mat f(4, 4, CV_32FC3, cv::Scalar(0.5, 0.5, 0.5));
  EXPECT_NO_THROW(to_rgb_float(f, false));
  f.at<cv::Vec3f>(1, 1)[2] = 1e38f;
  EXPECT_NE(error_of([&] { to_rgb_float(f, false, "rgb.tif"); }).find("rgb.tif: a float colour image must lie in"),
            std::string::npos);
  f.at<cv::Vec3f>(1, 1)[2] = std::numeric_limits<float>::quiet_NaN();
  EXPECT_NE(error_of([&] { to_rgb_float(f, false); }).find("not finite"), std::string::npos);
  f.at<cv::Vec3f>(1, 1)[2] = 1.004f;  // rounding: clamped
  EXPECT_FLOAT_EQ(to_rgb_float(f, false).at<cv::Vec3f>(1, 1)[2], 1.0f);
}

TEST(CommandLineNumbers, ANumberInItsRange) {
  EXPECT_DOUBLE_EQ(parse_number_arg("--holes", "0.25", 0, 1), 0.25);
  EXPECT_DOUBLE_EQ(parse_number_arg("--holes", "1", 0, 1), 1.0);
  try {
    parse_number_arg("--holes", "2", 0, 1);
    ADD_FAILURE() << "2 accepted in [0, 1]";
  } catch (const std::invalid_argument& e) {
    EXPECT_EQ(std::string(e.what()), "--holes: 2 is outside [0, 1]");
  }
  EXPECT_THROW(parse_number_arg("--holes", "nan", 0, 1), std::invalid_argument);
  EXPECT_THROW(parse_number_arg("--holes", "0.5x", 0, 1), std::invalid_argument);
}
