// Emitters: area (on any shape), point, spot, directional, constant, envmap. Names and
// parameter meanings follow Mitsuba 3's plugins of the same names.
#pragma once
#include <algorithm>
#include <memory>

#include "core/math.h"
#include "core/spectrum.h"
#include "scene/desc.h"
#include "scene/light_sampler.h"
#include "scene/records.h"

namespace rm {

class Shape;

// A point on (or direction to) an emitter, sampled from a reference point.
struct DirectSample {
    Vec3 p, n;          // position on the emitter and its normal (unused for delta/infinite)
    Vec3 d;             // unit direction from the reference point towards the emitter
    float dist = kInf;  // distance to p; infinite for directional and constant
    float pdf_w = 0.f;  // solid-angle density at the reference point; 1 for delta emitters
    bool is_delta = false;
    Color radiance{0.f};  // radiance arriving along -d (for point/spot: intensity / dist^2)
    float eps = 0.f;      // offset that clears p's floating-point error (area emitters)
    float pick = 0.f;     // the probability that the emitter was selected (set by sample_light)
};

// A ray of light leaving an emitter, for light-path estimators (ptracer, later
// bdpt and photon mapping). Veach 1997, sec. 8.1.2 / pbrt-v4's Light::SampleLe:
// the origin is sampled with density pdf_a (per unit area; on the disk that
// bounds the scene for directional and environment emitters), the direction
// with pdf_w (per steradian; 1 for a delta direction), and `weight` is the
// flux the ray carries, Le |cos| / (pdf_a pdf_w) (intensity / pdf_w for point
// and spot lights, whose position is a delta).
struct EmissionSample {
    Vec3 p;             // origin of the ray
    Vec3 n;             // surface normal at p (area emitters; zero otherwise)
    SurfaceUv uv;       // texture coordinates at p (area emitters)
    Vec3 d;             // unit direction the light travels
    Color weight{0.f};  // Le |cos| / (pdf_a pdf_w); black = failed sample
    float pdf_a = 0.f;  // origin density (1 for a delta position)
    float pdf_w = 0.f;  // direction density (1 for a delta direction)
    float eps = 0.f;    // ray-origin offset that clears p's floating-point error
};

class Emitter {
public:
    // Environment emitters: the solid-angle density with which sample_direct
    // picks the unit direction d (towards the emitter). For them pdf_direct's
    // p is a point along that direction from ref.
    virtual float pdf_environment(const Vec3& d) const { return 0.f; }
    virtual ~Emitter() = default;
    std::string id;
    // u: 2D sample on the emitter, u_extra: picks a triangle on meshes.
    virtual DirectSample sample_direct(const Vec3& ref, Vec2 u, float u_extra) const = 0;
    // Solid-angle density that sample_direct from `ref` produces the point p
    // (normal n) with; 0 for delta emitters.
    virtual float pdf_direct(const Vec3& ref, const Vec3& p, const Vec3& n) const { return 0.f; }
    // Radiance leaving a surface point of an area emitter towards w (world).
    virtual Color eval(const Interaction& it, const Vec3& w) const { return Color(0.f); }
    // Radiance arriving from direction -d for rays that leave the scene (constant).
    virtual Color eval_environment(const Vec3& d) const { return Color(0.f); }
    // Samples a ray of light leaving the emitter (see EmissionSample): u_pos and
    // u_extra pick the origin, u_dir the direction. scene_center/scene_radius
    // bound the scene (directional and constant emitters start their rays on
    // a disk of that radius outside it, as pbrt-v4 does).
    virtual EmissionSample sample_emission(Vec2 u_pos, float u_extra, Vec2 u_dir, const Vec3& scene_center,
                                           float scene_radius) const = 0;
    // The s = 1 connection of light tracing (Veach 1997, sec. 10.2): what
    // leaves es's origin towards the unit direction w, per unit of origin
    // density: Le(p, w) |cos| / pdf_a for area lights, I(w) for point and
    // spot lights; zero for directional and environment emitters, which a
    // point cannot connect to (the environment is seen along directions:
    // eval_environment).
    virtual Color emitted_towards(const EmissionSample& es, const Vec3& w) const { return Color(0.f); }
    // Solid-angle density with which sample_emission picks the direction w
    // leaving a point of normal n (area lights; n unused otherwise): the
    // reverse densities of bidirectional MIS (Veach 1997, sec. 10.2).
    // 0 for directional and environment emitters.
    virtual float pdf_emission_w(const Vec3& n, const Vec3& w) const { return 0.f; }
    // Area density of sample_emission's origin at p (area emitters; 0 otherwise).
    virtual float pdf_emission_a(const Vec3& p) const { return 0.f; }
    // Light selection (scene/light_sampler.h): the luminance of the flux it
    // emits (emitters at infinity: through the disk of scene_radius, as
    // pbrt-v4's Light::Phi), and for a finite emitter the bounds of its
    // light with phi = 0 (the sampler sets it); false at infinity.
    virtual float power(float scene_radius) const = 0;
    virtual bool light_bounds(LightBounds& b) const { return false; }
    int index = -1;  // in Scene::emitters
    bool is_delta() const { return delta_; }
    bool is_environment() const { return environment_; }
    // At infinity: directional and environment emitters (their light rays
    // start on the disk of infinite_disk_radius around the scene).
    bool is_infinite() const { return infinite_; }
    // Its emission is a texture (area radiance, spot texture, projector
    // irradiance): it varies over the surface or the image.
    bool textured() const { return textured_; }

protected:
    bool delta_ = false, environment_ = false, infinite_ = false, textured_ = false;
};

// Radius of the disk outside the scene's bounding sphere (of radius r) on
// which emitters at infinity start their light rays (pbrt-v4's SampleLe):
// r plus a margin of 0.1 % and 1e-6 r, the latter at most 1e-6 (the margin
// must shrink with the scene: an absolute 1e-6 made a scene of size 1e-8
// start its light paths on a disk 35 times its width, so only 1 path in
// 1200 reached it), never under 1e-18 (pi r^2 stays a normal float).
inline float infinite_disk_radius(float scene_radius) {
    return std::max(scene_radius * 1.001f + 1e-6f * std::min(scene_radius, 1.f), 1e-18f);
}

// Area light on `shape`, radiance on the side its normal points to (one-sided, like Mitsuba).
std::unique_ptr<Emitter> make_area_emitter(const EmitterDesc& desc, const Shape* shape);
// point, spot, directional, constant, envmap.
std::unique_ptr<Emitter> make_emitter(const EmitterDesc& desc);

}  // namespace rm
