#ifndef FIELDSPACE_CORE_OPERATORS_COMPLEX_POWER_H_
#define FIELDSPACE_CORE_OPERATORS_COMPLEX_POWER_H_

#include <cmath>
#include <cstdint>

#include "Eigen/Core"

namespace fieldspace {

// z^n for a unit complex number z = (z[0], z[1]) and n >= 0, by repeated squaring (exact
// rotation arithmetic, no trigonometry), renormalized to unit length against rounding drift.
// The n-field representation (r e^{i phi} -> r e^{i n phi}) and the n-field transport
// (e^{i delta} -> e^{i n delta}) both use it.
inline Eigen::Vector2d UnitComplexPower(const Eigen::Vector2d& z, int32_t n) {
  double zr = z[0], zi = z[1], pr = 1.0, pi = 0.0;
  for (int32_t m = n; m > 0; m >>= 1) {
    if (m & 1) {
      const double t = pr * zr - pi * zi;
      pi = pr * zi + pi * zr;
      pr = t;
    }
    const double t = zr * zr - zi * zi;
    zi = 2.0 * zr * zi;
    zr = t;
  }
  const double inv = 1.0 / std::sqrt(pr * pr + pi * pi);
  return {pr * inv, pi * inv};
}

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_OPERATORS_COMPLEX_POWER_H_
