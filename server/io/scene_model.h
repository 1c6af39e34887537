#pragma once
// The model of a scene file (kept apart from scene_file.h, which the fuzz build compiles
// without the simulation).
#include <memory>
#include <string>

#include "sim/scene.h"
#include "sim/two_body_model.h"

namespace hapco::io {

// The model of a scene read from `path`: a problem found while building it (the bodies overlap,
// a group holds no face, ...) is an InputError "PATH: what is wrong", like the file's own.
std::unique_ptr<sim::TwoBodyModel> MakeSceneModel(const sim::SceneSpec& scene, const std::string& path);

}  // namespace hapco::io
