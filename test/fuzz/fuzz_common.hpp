#pragma once
// What the libFuzzer harnesses share: inputs become files in a per-process folder (the parsers under test read
// files, as users hand them files), and an input may hold several files split at kSplit.
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

namespace fuzz {

inline const std::string& folder() {
  static const std::string dir = [] {
    const auto d = std::filesystem::temp_directory_path() / ("diffdope_fuzz_" + std::to_string(::getpid()));
    std::filesystem::create_directories(d);
    return d.string();
  }();
  return dir;
}

/// Writes `bytes` as `name` in the folder and returns its path.
inline std::string write(const std::string& name, const std::string& bytes) {
  const std::string path = folder() + "/" + name;
  std::ofstream(path, std::ios::binary | std::ios::trunc).write(bytes.data(), std::streamsize(bytes.size()));
  return path;
}

/// The input cut at every kSplit line into at most n parts (missing parts empty).
constexpr const char* kSplit = "\n----8<----\n";
inline std::vector<std::string> parts(const uint8_t* data, size_t size, size_t n) {
  const std::string s(reinterpret_cast<const char*>(data), size);
  std::vector<std::string> out;
  size_t at = 0;
  while (out.size() + 1 < n) {
    const size_t cut = s.find(kSplit, at);
    if (cut == std::string::npos) break;
    out.push_back(s.substr(at, cut - at));
    at = cut + std::char_traits<char>::length(kSplit);
  }
  out.push_back(s.substr(at));
  out.resize(n);
  return out;
}

}  // namespace fuzz
