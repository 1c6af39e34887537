#pragma once
// Scene files: protobuf text format (proto/scene.proto), versioned. Every problem in a file
// (syntax, a value out of range, a body that cannot be held) is reported as one
// hapco::InputError "FILE:LINE: field.path: what is wrong and what is allowed".
#include <string>

#include "sim/scene.h"

namespace hapco::io {

inline constexpr int kSceneFormatVersion = 1;

// Reads, checks and converts a text-format scene file. Throws InputError.
sim::SceneSpec LoadSceneFile(const std::string& path);

// Same, from text already in memory; `source_name` is used in messages.
sim::SceneSpec ParseSceneText(const std::string& text, const std::string& source_name);

}  // namespace hapco::io
