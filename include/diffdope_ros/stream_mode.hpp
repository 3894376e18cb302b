#pragma once
// When the refiner nodelet refines frames (~mode). Plain C++: the node's settings and the reconfigure values
// both hold it.
#include <string>

namespace diffdope_ros {

enum class StreamMode { kContinuous, kTracking, kOnRequest };
const char* to_string(StreamMode mode);
/// Throws std::invalid_argument for anything but "continuous", "tracking", "on_request".
StreamMode parse_stream_mode(const std::string& name);

}  // namespace diffdope_ros
