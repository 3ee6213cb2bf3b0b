// A skin: the mesh that covers caphub's skeleton, split into polygon groups (paper section 2.2),
// and the project's compact .mesh file format that ships the default skin (docs/render.md).
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "board/segment.h"
#include "hal/core/error.h"

namespace caphub::render {

inline constexpr int kSegmentCount = board::kSegmentCount;
inline constexpr int kMaxInfluences = 4;

// How a polygon group follows the skeleton.
enum class GroupMethod : std::uint8_t {
    Rigid,  // every vertex moves with one segment, no blending (head, hands, feet, toes)
    Lbs,    // linear blend skinning, paper eqs. 14-16
    Dqs,    // dual-quaternion skinning: no collapse under twist
};
std::string_view toString(GroupMethod m);

// A contiguous range of vertices that is skinned one way. Vertices are stored group by group so
// that each group's loop runs over a plain range.
struct PolygonGroup {
    std::string name;
    GroupMethod method = GroupMethod::Lbs;
    int segment = 0;  // the segment of a rigid group; the dominant segment otherwise
    std::uint32_t firstVertex = 0;
    std::uint32_t vertexCount = 0;
};

// Vertex data in the reference pose (the T-pose of docs/frames.md), metres, skeleton world frame.
// Per vertex up to four (segment, weight) influences; unused ones have weight 0. Weights sum to 1.
struct Skin {
    std::vector<std::array<float, 3>> positions;
    std::vector<std::array<float, 3>> normals;
    std::vector<std::array<std::uint8_t, kMaxInfluences>> joints;
    std::vector<std::array<float, kMaxInfluences>> weights;
    std::vector<std::array<std::uint32_t, 3>> triangles;
    std::vector<PolygonGroup> groups;
    // Each segment's origin (its proximal joint centre) in the reference pose: the skin is driven
    // by joint rotations about these points (docs/render.md, "Driving the skin").
    std::array<std::array<float, 3>, kSegmentCount> jointOriginsM{};
    std::string provenance;  // where the mesh came from, one line

    std::size_t vertexCount() const { return positions.size(); }
    int findGroup(std::string_view name) const;  // -1 when absent
};

// Checks the invariants every consumer relies on: array sizes agree, triangle indices in range,
// joints < 21, weights finite, >= 0 and summing to 1 (1e-3), groups covering the vertices in
// order without gaps, a rigid group's vertices weighted fully to its segment. The message names
// the first offending element.
Result<void> validate(const Skin& skin);

// Divides each vertex's weights by their sum (some published models do not sum to 1); a vertex
// whose weights are all zero is given weight 1 on `fallbackSegment`.
void renormaliseWeights(Skin& skin, int fallbackSegment);

// The .mesh format: "CAPHUBSK", format version, then a zlib-compressed little-endian payload
// (docs/render.md, "Mesh format"). Normals and weights are quantised (int16, uint8).
std::vector<std::uint8_t> encodeSkin(const Skin& skin);
Result<Skin> decodeSkin(std::span<const std::uint8_t> bytes, std::string_view sourceName);
Result<void> saveSkin(const Skin& skin, const std::filesystem::path& path);
Result<Skin> loadSkin(const std::filesystem::path& path);

// The default skin shipped with caphub: render/data/caphub-default.mesh in the source tree or
// share/caphub/mesh/caphub-default.mesh when installed.
std::filesystem::path defaultSkinPath();
Result<Skin> loadDefaultSkin();

// Splits a skin into caphub's polygon groups and orders its vertices group by group (triangles
// renumbered): a vertex weighted at least `rigidWeight` to the head, a hand, a foot or the toes
// joins that segment's rigid group (weight snapped to 1); the others go to the deformable group
// of their dominant segment's limb: "torso", "l_upperarm", "r_upperarm" (LBS), "l_forearm",
// "r_forearm" with the wrists (dual quaternions: pronation twists up to 90 degrees), "l_leg",
// "r_leg" (LBS). Groups left empty are kept, with no vertices.
Skin groupBySegment(const Skin& skin, float rigidWeight);

// Per segment, the triangles whose first vertex is influenced most by it: what the skeleton's
// Bone::meshElements holds.
std::array<std::vector<int>, kSegmentCount> trianglesBySegment(const Skin& skin);

}  // namespace caphub::render
