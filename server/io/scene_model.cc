#include "io/scene_model.h"

#include "common/error.h"

namespace hapco::io {

std::unique_ptr<sim::TwoBodyModel> MakeSceneModel(const sim::SceneSpec& scene, const std::string& path) {
  try {
    return std::make_unique<sim::TwoBodyModel>(scene);
  } catch (const InputError& error) {
    throw InputError(path + ": " + error.what());
  }
}

}  // namespace hapco::io
