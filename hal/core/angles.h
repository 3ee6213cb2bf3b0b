#pragma once

// Pi and the degree/radian factors: one definition for every area (no other includes, so the
// orientation filter's header can use them).

namespace caphub::hal {

inline constexpr double kPi = 3.14159265358979323846;
inline constexpr double kRadToDeg = 180.0 / kPi;
inline constexpr double kDegToRad = kPi / 180.0;

}  // namespace caphub::hal
