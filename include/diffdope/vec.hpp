#pragma once
// Tiny POD vector types usable on host and device (Eigen stays on the host side of the API).
#include <cmath>

#include "diffdope/host_device.hpp"

namespace diffdope {

struct Vec2f {
  float x, y;
};
struct Vec3f {
  float x, y, z;
};

DD_HOST_DEVICE Vec2f operator+(Vec2f a, Vec2f b) { return {a.x + b.x, a.y + b.y}; }
DD_HOST_DEVICE Vec2f operator-(Vec2f a, Vec2f b) { return {a.x - b.x, a.y - b.y}; }
DD_HOST_DEVICE Vec2f operator*(float s, Vec2f a) { return {s * a.x, s * a.y}; }

DD_HOST_DEVICE Vec3f operator+(Vec3f a, Vec3f b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
DD_HOST_DEVICE Vec3f operator-(Vec3f a, Vec3f b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
DD_HOST_DEVICE Vec3f operator*(float s, Vec3f a) { return {s * a.x, s * a.y, s * a.z}; }
DD_HOST_DEVICE Vec3f& operator+=(Vec3f& a, Vec3f b) {
  a.x += b.x;
  a.y += b.y;
  a.z += b.z;
  return a;
}

DD_HOST_DEVICE float dot(Vec3f a, Vec3f b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
DD_HOST_DEVICE Vec3f cross(Vec3f a, Vec3f b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
/// 2-D cross product (z of the 3-D one): positive when b is counter-clockwise of a in a y-up frame.
DD_HOST_DEVICE float cross2(Vec2f a, Vec2f b) { return a.x * b.y - a.y * b.x; }

DD_HOST_DEVICE float clampf(float v, float lo, float hi) { return v < lo ? lo : (v > hi ? hi : v); }
DD_HOST_DEVICE float signf(float v) { return v > 0.f ? 1.f : (v < 0.f ? -1.f : 0.f); }

}  // namespace diffdope
