// The float range of the text and double inputs (OBJ and PLY readers).
#pragma once

#include <cfloat>
#include <cmath>

namespace slim::detail {

// Whether the double d rounds to a finite float (round to nearest even): magnitudes below
// FLT_MAX plus half of its ulp (2^103) do, so "3.40282347e+38", FLT_MAX printed to 9 digits, is
// FLT_MAX. False for NaN and infinities.
inline bool rounds_to_finite_float(double d) { return std::fabs(d) < double(FLT_MAX) + 0x1p103; }

}  // namespace slim::detail
