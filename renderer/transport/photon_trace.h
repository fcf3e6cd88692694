// Photon tracing, the first pass of photon mapping (Jensen 2001, ch. 5):
// light paths leave the emitters with their flux, scatter by the adjoint
// BSDFs with Russian roulette, and leave a photon (position, incoming
// direction, power) at every vertex with a non-specular lobe. The light
// paths are those of light tracing and bdpt (subpath.h).
//
// Determinism: light path g draws on Sampler(mix64(seed + stream), g, pass)
// alone, and the photons of a pass are concatenated in path order, so the
// stored photons (and hence the maps and the image) do not depend on the
// thread count.
#pragma once
#include <atomic>
#include <cstdint>
#include <functional>
#include <vector>

#include "photon/photon_map.h"
#include "render/integrator.h"

namespace rm {

// Segments from the emitter to the photon's vertex, in Photon::flags.
constexpr int kPhotonDepthShift = 8;
inline int photon_depth(const Photon& p) { return int((p.flags >> kPhotonDepthShift) & 0xffu); }
// A volume photon's medium (index into Scene::media) in Photon::flags bits
// 16-31 as index + 1; 0 for a surface photon.
constexpr int kPhotonMediumShift = 16;
inline int photon_medium(const Photon& p) { return int(p.flags >> kPhotonMediumShift) - 1; }

struct PhotonTraceSpec {
    int max_depth = -1;          // light-path segments to the last stored photon; -1 = unbounded
    int rr_depth = 5;            // segments from which Russian roulette may stop the path
    bool caustic_only = false;   // keep only L S+ D photons; a path stops at its first non-specular vertex
    bool store_direct = true;    // keep photons at the first vertex (L D: direct light)
    bool indirect_only = false;  // keep only photons whose path had a non-specular vertex before
    uint64_t stream = 0;         // decorrelates the random streams of different maps
    // Scenes with media only (Scene::features.has_media): keep only volume
    // photons, at medium scattering events that follow at least one
    // scattering vertex (L X+ V: multiple scattering and volume caustics;
    // single scattering L V is computed by the camera pass's next event
    // estimation, as Jensen & Christensen 1998 compute it). Without it, a
    // photon tracer in a medium scene stores surface photons only.
    bool volume = false;
};

// Traces light path `path` of pass `pass` and appends its photons, their
// power not yet divided by the number of paths traced: the light subpath
// of ptracer and bdpt (subpath.h's light_subpath: the emitter pick, the
// emission sample, the adjoint walk with Russian roulette), its photons
// stored by a visitor on the walk's vertices (photon_trace.cpp). In a
// scene with media the walk takes free flights through them (mean free
// path 1 / sigma_t, scatter with probability sigma_s / sigma_t else
// absorb, the new direction drawn from the phase function), crosses
// index-matched boundaries without a vertex, and its power follows the
// hero-channel spectral MIS throughput of media_common.h; `depth` then
// counts scattering vertices (surface or medium, null boundaries
// excluded), as volpath's max_depth does.
void trace_photon_path(const Scene& scene, const PhotonTraceSpec& spec, uint64_t seed, uint64_t path, uint64_t pass,
                       std::vector<Photon>& out, ThreadStats& stats);

struct PhotonPass {
    std::vector<Photon> photons;  // power already divided by `paths`
    uint64_t paths = 0;           // light paths traced (the estimate's normaliser)
    uint64_t max_paths = 0;       // trace_photons_until: the most it would trace (the give-up bound)
    bool target_reached = true;
    bool cancelled = false;
    bool over_memory = false;  // trace_photon_paths: stopped at max_photons (the result is incomplete)
    double seconds = 0;
};

// The give-up bound of trace_photons_until: the paths it traces at most
// for `target` photons (photon_trace.cpp says why).
uint64_t photon_path_bound(uint64_t target);

// Traces light paths 0, 1, 2, ... until `target` photons are stored
// (Jensen's "photons in the map", Mitsuba's globalPhotons/causticPhotons);
// the paths after the one that stored the target-th photon are dropped, so
// the count of paths traced is a function of the seed. Gives up (the map
// keeps what was stored, target_reached false) after photon_path_bound(target)
// paths, or from 2^19 paths on once the storage rate is clearly too low to
// reach the target within that bound (photon_trace.cpp).
PhotonPass trace_photons_until(const Scene& scene, const PhotonTraceSpec& spec, uint64_t seed, uint64_t target,
                               int threads, const std::function<bool()>& poll, ThreadStats& stats);

// Traces exactly `paths` light paths of pass `pass` (SPPM's per-pass
// photons); stops with over_memory once more than `max_photons` are stored
// (the caller refuses the render: its photons outgrow the memory).
// `storage` (a previous pass's photon array, PhotonMap::release) is
// cleared and filled, so that its capacity serves again.
PhotonPass trace_photon_paths(const Scene& scene, const PhotonTraceSpec& spec, uint64_t seed, uint64_t pass,
                              uint64_t paths, int threads, const std::function<bool()>& poll, ThreadStats& stats,
                              uint64_t max_photons = UINT64_MAX, std::vector<Photon> storage = {});

}  // namespace rm
