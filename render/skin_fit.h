// Fitting a skin to a subject: moves a skin made for one body (the default mesh is MakeHuman's
// 1.675 m figure) so that its joints sit on the subject's skeleton (fusion/body/skeleton.h) in the
// reference pose, with its rigid groups moved as one (docs/render.md, "Fitted to the subject").
#pragma once

#include <array>

#include "board/board.h"
#include "fusion/body/skeleton.h"
#include "hal/core/error.h"
#include "render/skin.h"

namespace caphub::render {

// Where each segment's origin lies in the reference pose of a skeleton with these dimensions
// (skeleton world frame, metres): the offsets summed down the tree.
std::array<Vec3d, kSegmentCount> referenceOriginsM(const body::Dimensions& dims);

// Moves the skin's vertices so that its segment origins become `targetOriginsM`. Each segment s
// gets an affine map A_s(v) = T_s + M_s (v - O_s) (O_s its origin in the skin, T_s the target):
//   - a segment of a rigid group: M_s = g I, a uniform scale, so the group keeps its shape;
//   - any other segment: M_s maps the vectors from O_s to its children's origins onto the
//     target's (stretching the bone to the target length and direction), and scales what is
//     across the bones by g (girth);
// with g = targetHeightM / the skin's height. Each vertex moves by the blend of its segments'
// maps with its skin weights (normals by the blend's inverse transpose); jointOriginsM becomes
// the targets. Errors for a skin that does not validate or a height outside 0.5-2.5 m.
Result<Skin> fitSkin(const Skin& skin, const std::array<Vec3d, kSegmentCount>& targetOriginsM,
                     double targetHeightM);

// fitSkin onto the skeleton dimensionsFromSubject(subject) builds; its errors are passed on.
Result<Skin> fitSkinToSubject(const Skin& skin, const board::SubjectConfig& subject);

}  // namespace caphub::render
