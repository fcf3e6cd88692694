// RGB spectrum: linear sRGB/Rec.709 primaries, like Mitsuba 3's *_rgb variants.
#pragma once
#include "core/math.h"

namespace rm {

using Color = Vec3;  // component-wise algebra is shared with Vec3

inline float luminance(const Color& c) { return 0.212671f * c.x + 0.715160f * c.y + 0.072169f * c.z; }
inline bool is_black(const Color& c) { return c.x == 0.f && c.y == 0.f && c.z == 0.f; }
inline float average(const Color& c) { return (c.x + c.y + c.z) * (1.f / 3.f); }

}  // namespace rm
