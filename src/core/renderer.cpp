// Renderer's default multi-object evaluation: one evaluate() per object.
#include "diffdope/renderer.hpp"

#include <stdexcept>

#include "diffdope/observation.hpp"

namespace diffdope {

void Renderer::evaluate_objects(const Camera& camera, const Observation& frame, const std::vector<ObjectBatch>& objects,
                                bool with_gradient, std::vector<std::vector<LossValue>>& out) {
  out.resize(objects.size());
  for (size_t k = 0; k < objects.size(); ++k) {
    const ObjectBatch& b = objects[k];
    if (!b.mesh) throw std::invalid_argument("evaluate_objects: object " + std::to_string(k) + " has no mesh");
    Observation o;
    o.rgb = frame.rgb;
    o.depth = frame.depth;
    o.edges = frame.edges;
    o.mask = b.mask;
    evaluate(camera, *b.mesh, o, b.poses, b.loss, with_gradient, out[k]);
  }
}

}  // namespace diffdope
