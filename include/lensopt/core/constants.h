// Mathematical constants, one spelling each (use these, not M_PI or a literal).
#pragma once

namespace lensopt {

inline constexpr double kPi = 3.14159265358979323846;  // pi, to double precision
inline constexpr double kDegToRad = kPi / 180.0;       // radians per degree

}  // namespace lensopt
