// Sampling warps from the unit square and their densities. Every pdf name says
// its measure: *_pdf_w is per steradian, *_pdf_a per unit area. Formulas from
// Pharr, Jakob, Humphreys, "Physically Based Rendering" 4th ed. (PBR4),
// chapter A.5, and Shirley & Chiu 1997 for the concentric disk map.
#pragma once
#include "core/math.h"

namespace rm::warp {

// Concentric map of the square onto the unit disk (Shirley & Chiu 1997).
Vec2 square_to_uniform_disk_concentric(Vec2 u);
inline float square_to_uniform_disk_pdf_a() { return kInvPi; }

// Cosine-weighted hemisphere by Malley's method (PBR4 A.5.3): pdf = cos/pi.
Vec3 square_to_cosine_hemisphere(Vec2 u);
inline float square_to_cosine_hemisphere_pdf_w(const Vec3& w) { return w.z > 0 ? w.z * kInvPi : 0.f; }

Vec3 square_to_uniform_sphere(Vec2 u);
inline float square_to_uniform_sphere_pdf_w() { return kInv4Pi; }

Vec3 square_to_uniform_hemisphere(Vec2 u);
inline float square_to_uniform_hemisphere_pdf_w(const Vec3& w) { return w.z >= 0 ? kInv2Pi : 0.f; }

// Uniform directions within a cone of half-angle acos(cos_max) about +z.
Vec3 square_to_uniform_cone(Vec2 u, float cos_max);
inline float square_to_uniform_cone_pdf_w(const Vec3& w, float cos_max) {
    return w.z >= cos_max ? 1.f / (2.f * kPi * (1.f - cos_max)) : 0.f;
}

// Uniform barycentrics on a triangle (Heitz 2019, "A Low-Distortion Map
// Between Triangle and Square"): returns (b1, b2), b0 = 1 - b1 - b2.
Vec2 square_to_uniform_triangle(Vec2 u);

}  // namespace rm::warp
