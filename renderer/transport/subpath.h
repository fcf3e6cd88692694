// The subpath machinery shared by the light-tracing estimators (`ptracer`,
// `bdpt`, photon tracing; SmallVCM's shared vertex and walk of
// vertexcm.hxx, pbrt-v4's Vertex and RandomWalk in bdpt.cpp): one vertex
// record, one random walk for camera and light subpaths (adjoint BSDFs
// with the shading-normal correction in importance transport) whose
// vertices go to a visitor as they are made, the light subpath's start, the
// area densities of bidirectional MIS, the t = 1 connection to the sensor
// and the effect class of a strategy's vertex string.
#pragma once
#include <type_traits>
#include <vector>

#include "transport/common.h"
#include "transport/media_common.h"

namespace rm {

// Medium: a scattering event inside a participating medium (light
// subpaths, and bdpt's camera subpaths).
enum class VType : uint8_t { Camera, Light, Surface, Medium };

// One vertex of either subpath. pdf_fwd is the area density with which the
// vertex was sampled by its own subpath, pdf_rev the area density with which
// the other direction would sample it (Veach 1997, sec. 10.2.1: p_i^->, p_i^<-).
struct PathVertex {
    VType type = VType::Surface;
    Interaction it;   // p, n (zero for a delta-position light), wi towards the previous vertex
    Color beta{0.f};  // throughput of the subpath up to this vertex (Veach's alpha_i)
    float pdf_fwd = 0.f, pdf_rev = 0.f;
    bool delta = false;  // the walk sampled a delta lobe here
    bool infinite =
        false;  // a Light vertex at infinity (directional, environment): it.p is a far point along its direction
    const Bsdf* bsdf = nullptr;
    const Emitter* emitter = nullptr;      // the light of a Light vertex, or the area emitter a surface carries
    const PhaseFunction* phase = nullptr;  // a Medium vertex's phase function
    // Through media: pdf_fwd / pdf_rev above are the geometric densities
    // only (solid angle to area, no cosine at a medium vertex), without the
    // free-flight (sigma_t T) or transmittance (T) factors. Light tracing
    // never reads them; bdpt's MIS weights use them as they are, pbrt-v3's
    // choice (sec. 16.3.1, Vertex::Pdf and ConvertDensity): the weights of all
    // strategies of a path come from the same densities, so they still sum
    // to 1 and the estimator stays unbiased (Veach 1997, sec. 9.2.1);
    // bdpt.cpp's head comment says why little is lost.
    int medium = -1;        // the medium the vertex was reached through (a Medium vertex's own)
    bool enclosed = false;  // a Medium vertex behind a non-null boundary: B, not V (MediumTracker)
    bool connectible() const { return type != VType::Surface || bsdf->has_smooth(); }
    bool null_surface() const { return type == VType::Surface && bsdf->flags() == kNull; }
};

// Solid angle at `from` to area at `to` (Veach 1997, eq. 8.10): p_a = p_w |cos| / d^2;
// a vertex at infinity keeps the solid-angle density (pbrt-v4's ConvertDensity).
float to_area(float pdf_w, const Vec3& from, const PathVertex& to);
// Area density with which the emitter of vertex v (a Light vertex, or a
// surface carrying an area emitter) sends light to `next`; for emitters at
// infinity the planar density of the light ray's origin disk times
// |cos| at next (pbrt-v4's Vertex::PDFLight).
float emitter_pdf_to(const Scene& scene, const PathVertex& v, const PathVertex& next);
inline float remap0(float f) { return f != 0.f ? f : 1.f; }

// The camera's area density of sampling the first vertex v from the camera
// vertex z0: W(v) |cos| / (W H), W the importance of
// Sensor::sample_direction (bdpt.cpp explains why), for a pinhole; for an
// area sensor (irradiancemeter) the density of its ray directions at z0.
float camera_pdf_a(const Scene& scene, const PathVertex& z0, const PathVertex& v);
// Area density with which vertex v samples `next`, given it was reached
// from `prev` (pbrt-v4's Vertex::PDF).
float pdf_to(const Scene& scene, const PathVertex& v, const PathVertex* prev, const PathVertex& next);
// Area density with which light sampling picks v, a point on an area
// emitter, from `ref` (pbrt-v4's PdfLightOrigin); for a vertex at infinity
// the solid-angle density of its direction, summed over the emitters at
// infinity (pbrt-v4's InfiniteLightDensity).
float light_origin_pdf(const Scene& scene, const PathVertex& v, const PathVertex& ref);
// Where light selection from vertex v sees it from (common.h's LightContext).
LightContext vertex_light_context(const PathVertex& v);

// A point along `ray` beyond the scene's bounding sphere, where a vertex at
// infinity in the ray's direction is placed.
Vec3 far_point(const Scene& scene, const Ray& ray);

// A path's emitter vertex y0 is sampled by area when a light subpath starts
// (sample_emission) but by light sampling from its neighbour `adj` in next
// event estimation (s = 1), which for a sphere samples the cone it
// subtends: the two densities differ. Returns p_NEE(y0) / p_LE(y0), both
// per unit area with the emitter pick, for the MIS weights (for a delta
// position the ratio of the two selection probabilities; 1 for infinite
// emitters, whose two densities are the same, and where either is 0).
float nee_over_emission(const Scene& scene, const PathVertex& y0, const PathVertex& adj);

// The walk hands each new vertex (path.back()) to a visitor as soon as it
// is made, before the vertex's next direction is sampled (so its `delta`
// is not known yet; the vertices before it are complete): what an
// estimator does with the vertices of its walk as they come (photon
// storage into the maps, photon_trace.cpp; a light tracer's check that a
// requested class can still follow, ptracer.cpp). Returns false to end
// the walk at that vertex. A non-owning reference to the estimator's
// callable (a function_ref: one indirect call per vertex, no allocation or
// type-erased copy); it binds only to a named object, which must outlive it.
class VertexVisitor {
public:
    template <class F, class = std::enable_if_t<!std::is_same_v<std::remove_cv_t<F>, VertexVisitor>>>
    explicit VertexVisitor(F& f)
        : obj_(const_cast<void*>(static_cast<const void*>(&f))),
          call_([](void* o, const std::vector<PathVertex>& p) { return bool((*static_cast<F*>(o))(p)); }) {}
    bool operator()(const std::vector<PathVertex>& p) const { return call_(obj_, p); }

private:
    void* obj_;
    bool (*call_)(void*, const std::vector<PathVertex>&);
};

// Extends `path` (its start vertex, the camera or the light, already in it)
// from `ray` with throughput `beta`, up to max_vertices vertices in all.
// `media`: null for a walk that ignores media (scenes without media);
// else the walk starts in that medium state and samples free
// flights, medium vertices (VType::Medium) and phase-function directions,
// with the spectral MIS throughput of media_common.h, and crosses
// index-matched boundaries without making them vertices (they do not count
// towards max_vertices, as in volpath). Russian roulette from rr_depth
// scattering vertices on (common.h: Mitsuba's rule without media,
// volpath's through them). `densities`: whether the vertices get their
// pdf_fwd / pdf_rev (the MIS weights of bdpt and vertex merging read them;
// light tracing and photon mapping read none and save their cost, a tenth
// to a fifth of photon tracing's time); no random numbers depend on it.
void random_walk(const Scene& scene, Sampler& sampler, Ray ray, Color beta, TransportMode mode, int max_vertices,
                 int rr_depth, std::vector<PathVertex>& path, ThreadStats& stats, const VertexVisitor* visit = nullptr,
                 const MediumTracker* media = nullptr, bool densities = true);

// The light subpath y0 y1 .. of every light-tracing estimator (ptracer,
// bdpt, photon tracing): an emitter picked by the light sampler (as next event
// estimation), a ray of light leaving it (`es`), then the walk, each
// vertex (y0 included) handed to `visit`. Always draws the same random
// numbers for its start. Returns false (and leaves `light` empty) when the
// scene has no emitter or the sample failed. In a scene with media the
// walk goes through them (random_walk's `media`), starting in the
// emitter's medium (emitter_medium). `densities` as in random_walk.
bool light_subpath(const Scene& scene, Sampler& sampler, int max_vertices, int rr_depth, std::vector<PathVertex>& light,
                   EmissionSample& es, ThreadStats& stats, const VertexVisitor* visit = nullptr, bool densities = true);

// The sensor end of a connection from `ref`: Sensor::sample_direction, with
// a point drawn on an area sensor (random numbers only for those, so a
// camera's streams do not change).
ImportanceSample sensor_sample(const Scene& scene, const Vec3& ref, Sampler& sampler);

// The t = 1 strategy (light tracing): light vertex y connected to the
// sensor through its adjoint BSDF, or a medium vertex through its phase
// function. Returns y.beta f W Tr (zero when y is not connectible, faces
// away, or is occluded) and the sensor sample in `is`; Tr is the
// transmittance to where camera rays start (the near clip), through media
// and index-matched boundaries, in a scene with media (else 1).
Color connect_to_sensor(const Scene& scene, const PathVertex& y, ImportanceSample& is, ThreadStats& stats,
                        Sampler& sampler);
// The transmittance from `from` (a surface or medium point, in `medium`
// as Scene::transmittance takes it) to the camera along sensor sample `is`,
// ending where camera rays start; zero when occluded.
Color transmittance_to_sensor(const Scene& scene, const Interaction& from, int medium, const ImportanceSample& is,
                              ThreadStats& stats, Sampler& sampler);

// What a connection end v scatters towards wo, v.it.wi pointing back
// along its own subpath: at a medium vertex the phase function alone
// (the volume path measure has no cosine; pbrt-v3 sec. 16.3.1's
// Vertex::f), at a surface the BSDF times |cos|, adjoint with the
// shading-normal correction on the light subpath (common.h). Shared by
// bdpt's and vcm's connections.
Color scatter_value(const PathVertex& v, const Vec3& wo, TransportMode mode);

// The transmittance of a connection from z (a surface or medium vertex)
// to ds.p: without media visibility (1 or 0); with media
// Scene::transmittance, starting in the medium on the side of z the
// connection leaves to (a medium vertex's own), Beer-Lambert per segment
// or ratio tracking in grids (an unbiased estimate per channel, drawing
// from `sampler`), 0 at any surface that is not index-matched, as
// volpath's next event estimation.
Color connection_transmittance(const Scene& scene, const PathVertex& z, const DirectSample& ds, Sampler& sampler,
                               ThreadStats& stats);

// Next event estimation from camera vertex z (the s = 1 strategy of bdpt
// and vcm) with the random numbers given: an emitter picked from z, a
// point on it by light sampling. Returns z.beta f Tr Le / (p_w pick)
// (black when z cannot connect, the sample fails or is occluded) and the
// emitter vertex y0 with its area density (pdf_fwd) as the MIS weights
// read it.
Color connect_emitter_sample(const Scene& scene, const PathVertex& z, float u_pick, Vec2 u_l, float u_extra,
                             Sampler& sampler, ThreadStats& stats, PathVertex& y0);

// Effect class (DESIGN sec. 3) of strategy (s, t)'s vertex string
// E z1 .. z_{t-1} y_{s-1} .. y1 L: connection ends scatter through smooth
// lobes (D), walk vertices by the lobe they sampled; null boundaries are
// no vertices. For s = 0, z_{t-1} is the emitter.
int classify_strategy(const std::vector<PathVertex>& cam, const std::vector<PathVertex>& light, int s, int t);
// The same over arrays; light_end: light[s - 1] is a connection end (D);
// false for vertex merging, where the merge point is cam[t - 1] and
// light[s - 1] .. light[1] are walk vertices (filed by their lobes).
int classify_vertices(const PathVertex* cam, int t, const PathVertex* light, int s, bool light_end);
// A vertex's part in those classes in one byte (kClassSkip: a null
// boundary, none), so that an estimator classifying all O(n^2) strategies
// of one pair of subpaths reads two short byte arrays instead of O(n) full
// vertex records per strategy (bdpt on ajar_door spent 9 % of its
// instructions in classify_vertices: docs/performance.md).
enum ClassCode : uint8_t { kClassSkip, kClassSmooth, kClassDelta, kClassVolume, kClassSubsurface };
ClassCode class_code(const PathVertex& v);
// classify_vertices over the codes of the same vertices (the same result).
int classify_codes(const uint8_t* cam, int t, const uint8_t* light, int s, bool light_end);

}  // namespace rm
