#include "core/warp.h"

namespace rm::warp {

Vec2 square_to_uniform_disk_concentric(Vec2 u) {
    float x = 2.f * u.x - 1.f, y = 2.f * u.y - 1.f;
    if (x == 0.f && y == 0.f) return {0.f, 0.f};
    float r, phi;
    if (std::fabs(x) > std::fabs(y)) {
        r = x;
        phi = (kPi / 4.f) * (y / x);
    } else {
        r = y;
        phi = (kPi / 2.f) - (kPi / 4.f) * (x / y);
    }
    return {r * std::cos(phi), r * std::sin(phi)};
}

Vec3 square_to_cosine_hemisphere(Vec2 u) {
    Vec2 d = square_to_uniform_disk_concentric(u);
    float z = safe_sqrt(1.f - d.x * d.x - d.y * d.y);
    return {d.x, d.y, z};
}

Vec3 square_to_uniform_sphere(Vec2 u) {
    float z = 1.f - 2.f * u.x;
    float r = safe_sqrt(1.f - z * z);
    float phi = 2.f * kPi * u.y;
    return {r * std::cos(phi), r * std::sin(phi), z};
}

Vec3 square_to_uniform_hemisphere(Vec2 u) {
    float z = u.x;
    float r = safe_sqrt(1.f - z * z);
    float phi = 2.f * kPi * u.y;
    return {r * std::cos(phi), r * std::sin(phi), z};
}

Vec3 square_to_uniform_cone(Vec2 u, float cos_max) {
    float z = (1.f - u.x) + u.x * cos_max;
    float r = safe_sqrt(1.f - z * z);
    float phi = 2.f * kPi * u.y;
    return {r * std::cos(phi), r * std::sin(phi), z};
}

Vec2 square_to_uniform_triangle(Vec2 u) {
    // Heitz 2019, listing 1.
    float b0, b1;
    if (u.x < u.y) {
        b0 = u.x / 2.f;
        b1 = u.y - b0;
    } else {
        b1 = u.y / 2.f;
        b0 = u.x - b1;
    }
    return {b0, b1};
}

}  // namespace rm::warp
