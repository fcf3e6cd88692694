// Estimator interface and the per-path effect classification of DESIGN
// section 3 (Heckbert's path notation).
#pragma once
#include <array>
#include <cstdint>
#include <functional>
#include <initializer_list>
#include <memory>
#include <string>
#include <vector>

#include "core/rng.h"
#include "film/film.h"
#include "scene/desc.h"
#include "scene/scene.h"

namespace rm {

struct ThreadStats {
    uint64_t rays = 0, shadow_rays = 0, paths = 0, nan_samples = 0, inf_samples = 0;
    uint64_t photons = 0;  // photons stored (photon mapping estimators)
    // volpath's equiangular samples that reached a light point (volpath.cpp).
    uint64_t equiangular_samples = 0;
    // The truncation probe (path.cpp): the light that max_depth cuts off,
    // per camera sample (0 for the samples not probed), summed over samples
    // with its square per channel; probes: the samples continued. Sums of
    // doubles merged per thread: equal to rounding whatever the thread count.
    double truncated[3] = {0, 0, 0}, truncated_sq[3] = {0, 0, 0};
    uint64_t truncation_probes = 0;
    void add_truncated(const Color& c) {
        ++truncation_probes;
        for (int i = 0; i < 3; ++i) {
            truncated[i] += double(c[i]);
            truncated_sq[i] += double(c[i]) * double(c[i]);
        }
    }
    void merge(const ThreadStats& o) {
        rays += o.rays;
        shadow_rays += o.shadow_rays;
        paths += o.paths;
        nan_samples += o.nan_samples;
        inf_samples += o.inf_samples;
        photons += o.photons;
        equiangular_samples += o.equiangular_samples;
        truncation_probes += o.truncation_probes;
        for (int i = 0; i < 3; ++i) {
            truncated[i] += o.truncated[i];
            truncated_sq[i] += o.truncated_sq[i];
        }
    }
};

struct RenderOptions;
struct RenderOutput;

using EffectMask = std::array<bool, kNumEffects>;
inline EffectMask all_effects() {
    EffectMask m;
    m.fill(true);
    return m;
}

// Tracks a camera path's vertex string E v1 v2 ... to file each contribution
// under exactly one class: emission = LE, direct = LDE, caustic = LS+DE,
// specular = L(anything)SE, indirect = every other surface path; a path
// with a medium vertex V is volume, one with a subsurface vertex B (and no
// V) is subsurface (DESIGN section 3: volume, then subsurface, take
// precedence). B: a scattering event in a medium entered through a shape
// with a non-null BSDF (a dielectric) into its interior, i.e. inside a
// translucent object; V: any other medium scattering event (fog around the
// camera, media behind index-matched null boundaries).
struct PathClass {
    int scatter_vertices = 0;  // v1..vk so far
    bool first_specular = false;
    bool rest_specular = true;  // v2..vk all specular
    bool volume = false, subsurface = false;
    // Class of a contribution from an emitter reached right after the vertices
    // pushed so far (E v1 .. vk L). For next event estimation at v_{k+1},
    // classify a copy after push(false).
    int classify() const {
        if (volume) return kVolume;
        if (subsurface) return kSubsurface;
        if (scatter_vertices == 0) return kEmission;
        if (first_specular) return kSpecular;
        if (scatter_vertices == 1) return kDirect;
        return rest_specular ? kCaustic : kIndirect;
    }
    void push(bool is_delta) {
        ++scatter_vertices;
        if (scatter_vertices == 1)
            first_specular = is_delta;
        else
            rest_specular = rest_specular && is_delta;
    }
    // A medium vertex: V, or B when `enclosed` (see above).
    void push_medium(bool enclosed) {
        push(false);
        if (enclosed)
            subsurface = true;
        else
            volume = true;
    }
    // Can any class in `mask` still be produced once the current vertex
    // (the next one to be pushed) scatters or samples a light? `media`: the
    // scene has media, so a later vertex may still be V or B.
    bool can_reach(const EffectMask& m, bool media = false) const {
        if (volume) return m[kVolume];
        if (subsurface) return m[kSubsurface] || (media && m[kVolume]);
        if (media && (m[kVolume] || m[kSubsurface])) return true;
        if (scatter_vertices == 0) return m[kDirect] || m[kSpecular] || m[kCaustic] || m[kIndirect];
        if (first_specular) return m[kSpecular];
        if (scatter_vertices == 1) return m[kCaustic] || m[kIndirect];
        return m[kIndirect] || (rest_specular && m[kCaustic]);
    }
};

// One contribution of a light path to the film (light-tracing estimators):
// `value` at the continuous film position `film`, filed under `effect`. The
// driver spreads it over the pixels whose filter footprint covers `film`.
// A splat with pixel >= 0 is a camera sample of that pixel (bdpt's camera
// subpaths, drawn by filter importance sampling: camera_sample.h): it is
// added to that pixel alone, unfiltered, and its value is already scaled by
// W * H so that the driver's division by M = spp * W * H leaves the mean over
// the pixel's spp camera samples.
struct Splat {
    Vec2 film;
    int effect = 0;
    Color value{0.f};
    int pixel = -1;
    int strategy = -1;   // strategy_index(s, t) when per-strategy images are kept
    float weight = 1.f;  // the MIS weight already in `value` (value / weight: the unweighted strategy)
};

// Per-strategy images (Veach 1997, fig. 10.3 style; pbrt-v4's
// visualize_strategies): the strategies (s, t) of path depth d = s + t - 1
// are s = 0 .. d, numbered depth by depth, so depths 1 .. D hold
// D (D + 3) / 2 of them.
inline int strategy_index(int s, int t) {
    int d = s + t - 1;
    return (d - 1) * (d + 2) / 2 + s;
}
inline int num_strategies(int max_depth) { return max_depth * (max_depth + 3) / 2; }

// What an estimator renders and how the render driver runs it, declared with
// the estimator (render/registry.h).
enum class Driver {
    Camera,     // sample() per camera ray (render.cpp)
    Light,      // trace_light_path per light path (light_render.cpp)
    OwnPasses,  // drive(): passes of its own (photon mapping)
};
enum class Bias { Unbiased, Consistent, Biased };
// The mask of just the classes listed (kEmission, kDirect, ...).
inline EffectMask effect_mask(std::initializer_list<int> effects) {
    EffectMask m{};
    for (int e : effects) m[e] = true;
    return m;
}
struct Capabilities {
    // Transports light through participating media. The render driver
    // refuses a scene with media for one that does not (rather than render
    // it as if the media were vacuum).
    bool media = false;
    // Renders the dipole BSSRDF (scene/dipole.h); the render driver refuses
    // a dipole scene for any other, by name.
    bool dipole = false;
    Driver driver = Driver::Camera;
    // What the estimator's expectation is: the exact radiance of the classes
    // in `effects` at every sample count (unbiased); the exact radiance only
    // in the limit of many passes (consistent: progressive photon mapping's
    // shrinking radius, Hachisuka et al. 2008); or off by a bias that more
    // samples do not remove (biased: photon mapping's fixed photon count and
    // density-estimation radius, Jensen 2001, ch. 7). The estimator matrix
    // test (tests/test_estimator_matrix.py) holds each to what it declares.
    Bias bias = Bias::Unbiased;
    // Its pixels' estimates are correlated beyond a pixel filter's reach
    // (Metropolis chains linger over neighbouring pixels), so a block's
    // variance is not the sum of its pixels' (tests use a bound instead).
    bool correlated_pixels = false;
    // The effect classes it renders completely; the others it renders only
    // in part or not at all, by construction (whitted: no indirect light).
    EffectMask effects = all_effects();
};

class Integrator {
public:
    virtual ~Integrator() = default;
    // Light tracers (ptracer) trace light paths instead of camera rays: the
    // render driver sends them to render_light_paths (light_render.cpp),
    // which calls trace_light_path and never sample().
    bool is_light_tracer() const { return caps.driver == Driver::Light; }
    // Traces one light path and appends its splats to `out`. A pixel's
    // estimate is the filter-weighted sum of the splats of M light paths,
    // divided by M.
    // `pixel` is the pixel whose Sampler(seed, pixel, sample) drives the path
    // (bdpt also traces one camera path through that pixel).
    virtual void trace_light_path(const Scene&, Sampler&, int pixel, std::vector<Splat>& out, ThreadStats&) const {}
    // Estimators with passes of their own (photon mapping: photon passes
    // before or between camera passes) run the render themselves:
    // render() hands them the whole job (render.h's PollFn for `poll`),
    // which they run as a PassStep on a PassLoop (pass_loop.h).
    bool owns_driver() const { return caps.driver == Driver::OwnPasses; }
    virtual RenderOutput drive(const Scene& scene, const RenderOptions& opts,
                               const std::function<bool(uint64_t, uint64_t)>& poll) const;
    // Throws std::invalid_argument when this estimator cannot render `scene`.
    virtual void check_scene(const Scene&) const {}
    // Depth up to which the light-path driver keeps per-strategy images (0: none).
    virtual int strategy_depth() const { return 0; }
    bool supports_media() const { return caps.media; }
    bool supports_dipole() const { return caps.dipole; }
    // The estimator that renders `scene` (called once per render, before any
    // sample): `path` hands a scene with media to its media-aware loop
    // (volpath.cpp), so that its own surface loop has no media code at all.
    virtual const Integrator& for_scene(const Scene&) const { return *this; }
    std::string type;   // the estimator's name, for messages (set by make_integrator)
    Capabilities caps;  // the estimator's declared capabilities (set by make_integrator)
    // Radiance along one camera ray, split by effect class, into `out`.
    virtual void sample(const Scene& scene, Sampler& sampler, const Ray& ray, EffectRadiance& out,
                        ThreadStats& stats) const = 0;
    // An estimator whose camera sample starts with the camera ray's closest
    // hit may take that hit from the camera driver, which traces the rays
    // of neighbouring pixels as one Embree packet (Scene::intersect_packet):
    // sample_from_hit then gets it (nullptr: the ray escaped) instead of
    // tracing the ray itself, with the same result bytes.
    virtual bool takes_camera_hits() const { return false; }
    virtual void sample_from_hit(const Scene& scene, Sampler& sampler, const Ray& ray, const Interaction* hit,
                                 EffectRadiance& out, ThreadStats& stats) const {
        sample(scene, sampler, ray, out, stats);
    }
    EffectMask mask = all_effects();
    // The emitter selection of its renders (the `light_sampler` parameter;
    // render() makes it the scene's for the render's duration).
    LightSamplerKind light_sampler = LightSamplerKind::Uniform;
};

// The estimator `desc` names, its parameters checked against its declaration
// (render/registry.h); throws ParamError (a std::invalid_argument) for an
// unknown estimator or a bad parameter.
std::unique_ptr<Integrator> make_integrator(const IntegratorDesc& desc, const EffectMask& mask);

// Test hook of bdpt (estimators/bdpt_mis_check.cpp): for the strategies (s, t) of n random sample
// pairs, the MIS weight as bdpt computes it and as a brute-force product of
// every strategy's path density gives it, and the sum of bdpt's weights
// over every strategy of the same path (`sums`); strategy = 1000 s + t,
// plus 1000000 when the path has a medium vertex.
void bdpt_mis_check(const Scene& scene, const Integrator& bdpt, uint64_t seed, int n, std::vector<float>& fast,
                    std::vector<float>& brute, std::vector<float>& sums, std::vector<int>& strategy);

// Test hook of vcm and bpm (estimators/vcm_mis_check.cpp): for the full
// paths of n random sample pairs, every technique's weight as the renderer
// computes it (fast) and from full-path densities (brute), its code
// (connection: 1000 s + t; merge at x_i: 500000 + 1000 i + t), each path's
// sum of fast weights, and the renderer's weight of the pair's own
// connection on its walked subpaths beside the brute one; `mutation` > 0
// breaks one quantity (the test's power check).
void vcm_mis_check(const Scene& scene, const Integrator& vcm, uint64_t seed, int n, int iteration, int mutation,
                   std::vector<float>& fast, std::vector<float>& brute, std::vector<int>& technique,
                   std::vector<float>& sums, std::vector<float>& own_fast, std::vector<float>& own_brute);

// Power heuristic with beta = 2 (Veach 1997, eq. 9.13), for one sample per strategy.
inline float mis_power(float pdf_a, float pdf_b) {
    float a = pdf_a * pdf_a, b = pdf_b * pdf_b;
    if (!(a > 0.f)) return 0.f;
    if (std::isinf(a)) return 1.f;
    return a / (a + b);
}

}  // namespace rm
