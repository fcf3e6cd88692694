// The vertex a BSDF-sampled ray leaves, kept until the ray finds what it
// hits, so that the MIS weight of an emitter reached that way is computed
// from the same two densities as the light sample's weight at that vertex.
//
// Next event estimation samples the emitter point y from the shading point
// x (estimate_direct) and weighs it with the light density of y seen from x
// and the BSDF density of the direction x -> y. The BSDF sample leaves an
// offset origin o (Interaction::spawn), so its direction and the density it
// was drawn with belong to the segment o -> y. Where the segment is short
// and grazing (|x - y| comparable to the offset) the two differ by tens of
// per cent, and the two strategies' weights for one path no longer sum to
// 1: in the closed furnace (where both densities are cos / pi from x, so
// every sample is exact) 1 sample in about 10^5 lost up to 5 % of its
// direct light, a bias of 5e-7 relative (docs/false_alarms.md). Recomputing
// the BSDF density of x -> y at the hit, and the light density from x,
// makes the weights a partition of unity for every path (Veach 1997, sec.
// 9.2.2), as bdpt's densities come from vertex positions (subpath_walk.h).
#pragma once
#include <cmath>

#include "scene/bsdf.h"
#include "scene/records.h"

namespace rm {

struct ScatterOrigin {
    Vec3 p;                      // the vertex itself, not the ray's offset origin
    Frame sh;                    // its shading frame
    Vec3 wi;                     // the direction towards its predecessor, in that frame
    SurfaceUv uv;                // its texture coordinates
    Vec3 n_base{0.f, 0.f, 1.f};  // Interaction::n_base (normal and bump maps)
    const Bsdf* bsdf = nullptr;  // null: a medium vertex (its ray leaves p itself) or the camera

    void set(const Interaction& it, const Vec3& wi_local, const Bsdf* b) {
        p = it.p;
        sh = it.sh;
        uv = it.uv;
        n_base = it.n_base;
        wi = wi_local;
        bsdf = b;
    }
    // The BSDF density (solid angle) of the direction to `y`; `sampled`
    // (the density the ray was drawn with) where there is no BSDF or y is x.
    float pdf_to(const Vec3& y, float sampled) const {
        if (!bsdf) return sampled;
        Vec3 v = y - p;
        float d2 = length_sq(v);
        if (!(d2 > 0.f)) return sampled;
        BsdfContext ctx;
        ctx.uv = uv;
        ctx.n_base = n_base;
        return bsdf->pdf_w(ctx, wi, sh.to_local(v / std::sqrt(d2)));
    }
};

}  // namespace rm
