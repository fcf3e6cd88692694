// Rays and interaction records shared by every estimator. The records carry
// a vertex kind and medium slots from the start, so participating media and
// subsurface vertices arrive later without changing their layout.
#pragma once
#include <cstdint>

#include "core/math.h"
#include "core/spectrum.h"

namespace rm {

struct MeshAttributes;  // scene/texture.h

// A surface point's texture coordinates (the Vec2 itself), and, on a mesh
// that carries attributes (Mitsuba's vertex_* and face_* PLY properties),
// the triangle, its barycentrics and the mesh's attributes, which
// mesh_attribute textures read. It travels wherever the uv does (hits,
// BsdfContext, position and emission samples), so a texture sees the same
// point whichever estimator asks; a plain Vec2 converts to it with no mesh.
struct SurfaceUv : Vec2 {
    int prim = -1;
    Vec2 bary;  // (b1, b2) of the triangle's corners 1 and 2
    const MeshAttributes* attributes = nullptr;
    SurfaceUv() = default;
    SurfaceUv(const Vec2& uv) : Vec2(uv) {}  // NOLINT: a plain uv converts implicitly
};

struct Ray {
    Vec3 o, d;
    float tmin = 0.f;
    float tmax = kInf;
};

enum class VertexKind : uint8_t { Surface, Medium, Subsurface, Emitter, Sensor };

struct Interaction {
    VertexKind kind = VertexKind::Surface;
    bool valid = false;
    float t = kInf;
    Vec3 p;    // position, world space
    Vec3 n;    // geometric normal, oriented as the shape declares (flip_normals applied)
    Frame sh;  // shading frame (z = shading normal, same side as n)
    SurfaceUv uv;
    // The surface's partial derivatives in its uv parametrisation (world
    // space, as Mitsuba 3's si.dp_du / si.dp_dv), filled only for shapes
    // whose BSDF asks for them (Shape::uv_frame: anisotropic BSDFs, normal
    // and bump maps); unset (stale) elsewhere.
    Vec3 dp_du, dp_dv;
    // The unperturbed shading normal in the local coordinates of sh: (0, 0, 1)
    // unless a normal or bump map replaced sh (Bsdf::perturb_frame); the
    // map's BSDF reads it through BsdfContext::n_base.
    Vec3 n_base{0.f, 0.f, 1.f};
    Vec3 wi;         // direction towards the previous vertex, world space
    int shape = -1;  // index in Scene::shapes
    int prim = -1;
    float eps = 0.f;  // ray-origin offset that clears this hit's floating-point error
    // Medium slots (filled by the medium-aware estimators; -1 = vacuum).
    int medium_inside = -1, medium_outside = -1;

    Vec3 to_local(const Vec3& w) const { return sh.to_local(w); }
    Vec3 to_world(const Vec3& w) const { return sh.to_world(w); }
    // A ray leaving the surface towards d, its origin pushed off the side d is on.
    Ray spawn(const Vec3& d) const {
        Ray r;
        r.o = p + n * (dot(d, n) >= 0.f ? eps : -eps);
        r.d = d;
        return r;
    }
};

}  // namespace rm
