// vision_msgs/Detection3DArray from its ROS 1 serialization (detection3d_array.hpp).
#include "diffdope_ros/detection3d_array.hpp"

#include <cmath>
#include <cstring>
#include <stdexcept>

namespace diffdope_ros {
namespace {

/// Little-endian reads (ROS 1 serialization) that never pass the end of the buffer.
class Reader {
 public:
  Reader(const uint8_t* data, size_t size) : data_(data), size_(size) {}
  size_t offset() const { return at_; }
  size_t left() const { return size_ - at_; }

  void need(size_t n, const char* what) const {
    if (n > left())
      throw std::invalid_argument(std::string("Detection3DArray: truncated in ") + what + " at byte " +
                                  std::to_string(at_) + " (" + std::to_string(n) + " bytes needed, " +
                                  std::to_string(left()) + " left)");
  }
  template <class T>
  T read(const char* what) {
    need(sizeof(T), what);
    T v;
    std::memcpy(&v, data_ + at_, sizeof(T));  // x86-64 and aarch64 are little-endian, as the wire
    at_ += sizeof(T);
    return v;
  }
  /// A count of elements of at least `min_element_bytes` each: refused when they cannot all be there.
  uint32_t count(size_t min_element_bytes, const char* what) {
    const uint32_t n = read<uint32_t>(what);
    if (min_element_bytes > 0 && n > left() / min_element_bytes)
      throw std::invalid_argument(std::string("Detection3DArray: ") + what + " says " + std::to_string(n) +
                                  " elements at byte " + std::to_string(at_ - 4) + ", more than the " +
                                  std::to_string(left()) + " bytes left can hold");
    return n;
  }
  std::string string(const char* what) {
    const uint32_t n = count(1, what);
    std::string s(reinterpret_cast<const char*>(data_ + at_), n);
    at_ += n;
    return s;
  }
  void skip(size_t n, const char* what) {
    need(n, what);
    at_ += n;
  }

 private:
  const uint8_t* data_;
  size_t size_, at_ = 0;
};

void header(Reader& r, std::string* frame, uint32_t* sec, uint32_t* nsec) {
  r.read<uint32_t>("header.seq");
  *sec = r.read<uint32_t>("header.stamp");
  *nsec = r.read<uint32_t>("header.stamp");
  *frame = r.string("header.frame_id");
}

/// The pose, or (`problem` set) identity when its values cannot be one.
diffdope::Pose pose(Reader& r, const char* what, std::string* problem) {
  double v[7];
  for (double& x : v) x = r.read<double>(what);
  for (double x : v)
    if (!std::isfinite(x)) {
      *problem = std::string(what) + " is not finite";
      return diffdope::Pose();
    }
  if (std::sqrt(v[3] * v[3] + v[4] * v[4] + v[5] * v[5] + v[6] * v[6]) < 1e-6) {
    *problem = std::string(what) + " has a zero quaternion";
    return diffdope::Pose();
  }
  return diffdope::Pose::from_quaternion(v[3], v[4], v[5], v[6], Eigen::Vector3d(v[0], v[1], v[2]));
}

/// sensor_msgs/PointCloud2 source_cloud: read past it (DOPE leaves it empty; its contents are not used).
void skip_point_cloud(Reader& r) {
  std::string frame;
  uint32_t sec, nsec;
  header(r, &frame, &sec, &nsec);
  r.skip(8, "source_cloud.height/width");
  const uint32_t fields = r.count(4 + 4 + 1 + 4, "source_cloud.fields");
  for (uint32_t i = 0; i < fields; ++i) {
    r.string("source_cloud.fields.name");
    r.skip(4 + 1 + 4, "source_cloud.fields");
  }
  r.skip(1 + 4 + 4, "source_cloud.is_bigendian/point_step/row_step");
  r.skip(r.count(1, "source_cloud.data"), "source_cloud.data");
  r.skip(1, "source_cloud.is_dense");
}

}  // namespace

DecodedDetectionArray decode_detection3d_array(const uint8_t* data, size_t size) {
  Reader r(data, size);
  DecodedDetectionArray out;
  header(r, &out.frame_id, &out.stamp_sec, &out.stamp_nsec);
  // A detection is at least a header (16), a results count (4), a box (80) and an empty cloud (~45 bytes).
  const uint32_t n = r.count(16 + 4 + 80, "detections");
  out.detections.resize(n);
  for (DecodedDetection& d : out.detections) {
    header(r, &d.frame_id, &d.stamp_sec, &d.stamp_nsec);
    const uint32_t m = r.count(8 + 8 + 56 + 288, "results");  // id, score, pose, covariance
    d.results.resize(m);
    for (DecodedHypothesis& h : d.results) {
      h.class_id = r.read<int64_t>("results.id");
      h.score = r.read<double>("results.score");
      h.pose = pose(r, "results.pose", &h.problem);
      if (h.problem.empty() && !std::isfinite(h.score)) h.problem = "results.score is not finite";
      for (double& c : h.covariance) c = r.read<double>("results.pose.covariance");
    }
    r.skip(56 + 24, "bbox");  // center pose and size: not used
    skip_point_cloud(r);
  }
  if (r.left() != 0)
    throw std::invalid_argument("Detection3DArray: " + std::to_string(r.left()) + " bytes after the message (" +
                                std::to_string(size) + " in all): not this message's layout");
  return out;
}

namespace {

/// Little-endian writes, field by field as the .msg files define them.
struct Writer {
  std::vector<uint8_t> bytes;
  template <class T>
  void put(T v) {
    const size_t at = bytes.size();
    bytes.resize(at + sizeof(T));
    std::memcpy(bytes.data() + at, &v, sizeof(T));
  }
  void string(const std::string& s) {
    put<uint32_t>(uint32_t(s.size()));
    bytes.insert(bytes.end(), s.begin(), s.end());
  }
  void header(const std::string& frame, uint32_t sec, uint32_t nsec) {
    put<uint32_t>(0), put<uint32_t>(sec), put<uint32_t>(nsec), string(frame);
  }
  void pose(const diffdope::Pose& p) {
    const auto q = p.quaternion_xyzw();
    for (double v : {p.t.x(), p.t.y(), p.t.z(), q[0], q[1], q[2], q[3]}) put<double>(v);
  }
};

}  // namespace

std::vector<uint8_t> encode_detection3d_array(const DecodedDetectionArray& array, double box_size) {
  Writer w;
  w.header(array.frame_id, array.stamp_sec, array.stamp_nsec);
  w.put<uint32_t>(uint32_t(array.detections.size()));
  for (const DecodedDetection& d : array.detections) {
    w.header(d.frame_id, d.stamp_sec, d.stamp_nsec);
    w.put<uint32_t>(uint32_t(d.results.size()));
    for (const DecodedHypothesis& h : d.results) {
      w.put<int64_t>(h.class_id);
      w.put<double>(h.score);
      w.pose(h.pose);
      for (double c : h.covariance) w.put<double>(c);
    }
    w.pose(d.results.empty() ? diffdope::Pose() : d.results.front().pose);  // bbox.center
    for (int k = 0; k < 3; ++k) w.put<double>(box_size);                    // bbox.size
    w.header(d.frame_id, d.stamp_sec, d.stamp_nsec);                         // source_cloud: empty
    w.put<uint32_t>(0), w.put<uint32_t>(0);                                  // height, width
    w.put<uint32_t>(0);                                                      // fields
    w.put<uint8_t>(0), w.put<uint32_t>(0), w.put<uint32_t>(0);               // is_bigendian, point_step, row_step
    w.put<uint32_t>(0);                                                      // data
    w.put<uint8_t>(1);                                                       // is_dense
  }
  return w.bytes;
}

}  // namespace diffdope_ros
