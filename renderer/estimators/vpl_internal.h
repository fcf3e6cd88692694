// What `vpl` (instant radiosity, vpl.cpp) and `rowcolumn` (matrix
// row-column sampling, rowcolumn.cpp) share: one pass's set of virtual
// point lights, the camera sample that ends at gather points and one
// VPL's (clamped) contribution to a gather point (the per-pixel sums over
// passes: PassSums, render/pass_loop.h). docs/vpl.md has the whole story.
//
// A pass (one spp of the pass loop):
//   1. vpl_count light paths on subpath.h's light walk; each vertex y_i,
//      i >= 1, on a surface with a smooth lobe becomes a VPL (Keller 1997,
//      "Instant Radiosity"): the vertex itself, its throughput (flux) over
//      vpl_count, and the clamping distance below. The emitter vertices
//      y_0 are not VPLs: direct light comes from next event estimation.
//   2. each pixel's camera sample follows delta lobes (walk_specular_chain)
//      and at every vertex with a smooth lobe takes direct light by one
//      light sample and becomes a gather point (at most kMaxGather per
//      sample; the chain goes on through a delta lobe that the BSDF's own
//      lobe selection picks, as whitted.cpp's).
//   3. each gather point x sums the contributions of the VPLs y (the
//      bidirectional connection of Veach 1997, eq. 10.8):
//        beta_x f_x(x -> y) f_y(y -> x) beta_y V(x, y) / max(d^2, d_min(y)^2),
//      `clamping` as Mitsuba 0.6's vpl (src/libhw/vpl.cpp, setVPL): the
//      distance is clamped from below at d_min = near + clamping (far -
//      near), near and far the closest and farthest hits of kClampRays
//      rays cast from y over the hemisphere on x's side (a fixed Hammersley
//      set, cosine-distributed in the frame of y's geometric normal, so
//      that d_min is a function of the point alone: the compensation of
//      vpl.cpp evaluates the same function at its gather hits).
// Effect classes: emission along the chain and the direct light at x as
// in `path` (direct, or specular behind a delta vertex); every VPL
// contribution (and vpl's compensation) is a path E S* x y ... L with two
// non-delta vertices: indirect, or specular behind a delta vertex. Paths
// that reach the light from x through a delta vertex (L .. S+ x E: caustics,
// and L .. D S+ D E) are no VPL connection: missing by construction.
#pragma once
#include <string>
#include <vector>

#include "render/pass_loop.h"
#include "render/registry.h"
#include "transport/subpath.h"

namespace rm {

// One virtual point light.
struct Vpl {
    PathVertex v;                 // the light vertex; v.beta is its flux over vpl_count
    float dmin2[2] = {0.f, 0.f};  // squared clamping distance towards the side of v.it.n (0) and the other (1)
    int depth = 0;                // i: segments from the emitter
};

// A camera sample's vertex that gathers from the VPLs.
struct GatherPoint {
    PathVertex v;   // Surface vertex: it, bsdf; beta with the camera sample's weight
    int depth = 0;  // segments from the camera
    int cls = 0;    // the class of what it gathers (indirect, or specular behind a delta vertex)
};
constexpr int kMaxGather = 4;
constexpr int kClampRays = 32;

struct VplConfig {
    int vpl_count = 32, max_depth = -1, rr_depth = 5;
    float clamping = 0.1f;
    bool hide = false;
};

// The parameters both estimators declare, and their reading.
std::vector<ParamSpec> vpl_shared_params();
VplConfig read_vpl_config(ParamReader& p);

class VplEngine {
public:
    VplEngine(const Scene& scene, const VplConfig& cfg, const EffectMask& mask, const std::string& name);

    // Whether any VPL can contribute (a class they file under is asked for,
    // paths of 3 segments are allowed, the scene has emitters).
    bool needs_vpls() const { return needs_; }
    // Step 1 of pass `pass`: the VPLs in light-path order; false when cancelled.
    bool trace(PassLoop& loop, int pass, std::vector<Vpl>& out);
    // Step 2: pixel `pixel`'s camera sample on `sampler`: emission and direct
    // light into `er`, its gather points into gp; returns their count.
    int camera_sample(Sampler& sampler, int pixel, EffectRadiance& er, GatherPoint* gp, ThreadStats& stats) const;
    // VPL y's contribution to gather point vertex x at `depth` segments from
    // the camera, before x's beta, its shadow ray included (black when the
    // path would exceed max_depth, faces away or is occluded).
    Color contribution(const PathVertex& x, int depth, const Vpl& y, ThreadStats& stats) const;
    // Sum of every VPL's contribution to x, in VPL order.
    Color gather(const PathVertex& x, int depth, const std::vector<Vpl>& vpls, ThreadStats& stats) const;
    // Squared clamping distance at surface point `it`, on the side of its
    // geometric normal (back = false) or the other (0: no clamping).
    float clamp_distance2(const Interaction& it, bool back, ThreadStats& stats) const;

    const Scene& scene() const { return scene_; }
    const VplConfig& config() const { return cfg_; }
    const EffectMask& mask() const { return mask_; }
    PhotonMapStats stats_out;  // the VPL sets: count, light paths, time (res.stats["photon_maps"]["vpl"])

private:
    const Scene& scene_;
    VplConfig cfg_;
    EffectMask mask_;
    FilterSampler filter_;
    bool needs_ = false;
};

// The light paths' stream of pass `pass` (one per path g).
inline Sampler vpl_light_sampler(uint64_t seed, uint64_t g, int pass) {
    return Sampler(mix64(seed + 0x76706c6c69676874ULL), g, uint64_t(pass));
}

}  // namespace rm
