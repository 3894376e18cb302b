// The backend-independent part of Renderer: evaluate() as one object of evaluate_objects(), and the input checks
// every backend's evaluate_objects() starts from.
#include "diffdope/renderer.hpp"

#include <stdexcept>
#include <string>

#include "diffdope/observation.hpp"

namespace diffdope {

void Renderer::evaluate(const Camera& camera, const Mesh& mesh, const Observation& observed,
                        const std::vector<Pose>& poses, const LossOptions& loss, bool with_gradient,
                        std::vector<LossValue>& out) {
  one_object_.resize(1);
  ObjectBatch& b = one_object_[0];
  b.mesh = &mesh;
  b.mask = observed.mask;
  b.loss = loss;
  b.poses = poses;
  evaluate_objects(camera, observed, one_object_, with_gradient, one_result_);
  out = one_result_[0];
}

std::vector<Observation> Renderer::object_observations(const Camera& camera, const Observation& frame,
                                                       const std::vector<ObjectBatch>& objects) {
  std::vector<Observation> obs(objects.size());
  for (size_t k = 0; k < objects.size(); ++k) {
    const ObjectBatch& b = objects[k];
    if (!b.mesh) throw std::invalid_argument("evaluate_objects: object " + std::to_string(k) + " has no mesh");
    if (!(b.loss.depth_truncation > 0)) throw std::invalid_argument("loss: depth_truncation must be > 0");
    obs[k] = frame.with_mask(b.mask);
    obs[k].validate(camera);
  }
  return obs;
}

}  // namespace diffdope
