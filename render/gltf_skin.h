// User meshes: a skinned glTF 2.0 mesh (.gltf or .glb) turned into a caphub Skin, its joints
// mapped onto caphub's segments by name.
#pragma once

#include <filesystem>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "board/segment.h"
#include "hal/core/error.h"
#include "render/skin.h"

namespace caphub::render {

// glTF joint (node) name -> caphub segment; "#N" names node N (models with unnamed nodes). Joints
// not named follow their nearest named ancestor; a mesh none of whose joints is named is refused.
struct GltfJointMap {
    std::vector<std::pair<std::string, board::Segment>> joints;
};

// Parses "name = segment" lines ('#' comments, except "#N"), segment names as in board files.
// Errors read
// "<source>:<line>: <what was expected>".
Result<GltfJointMap> parseGltfJointMap(std::string_view text, std::string_view sourceName);

// Loads the first skinned mesh of the file. The mesh is taken in its rest pose (the nodes'
// own transforms), which becomes caphub's reference pose: model meshes in a T-pose facing +Z.
// Weights are renormalised to sum to 1 (some published models do not); beyond four influences
// the largest four are kept. Vertices are grouped with groupBySegment(skin, 0.97).
Result<Skin> loadGltfSkin(const std::filesystem::path& path, const GltfJointMap& map);

}  // namespace caphub::render
