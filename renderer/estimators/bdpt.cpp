// `bdpt`: bidirectional path tracing (Veach 1997, ch. 10; Lafortune and
// Willems 1993). Each sample traces a camera subpath z0 z1 .. and a light
// subpath y0 y1 .. with one vertex record and one random walk (pbrt-v4's
// Vertex and RandomWalk, bdpt.cpp; SmallVCM's shared subpath of
// vertexcm.hxx), and combines every strategy (s, t) of s light and t camera
// vertices:
//   s = 0   the camera subpath reaches an emitter by itself
//   t = 1   a light vertex connected to the camera: a splat (as `ptracer`)
//   s = 1   next event estimation: a fresh emitter sample for z_{t-1}
//   s, t >= 2  a deterministic connection of y_{s-1} and z_{t-1}
// weighted by multiple importance sampling over all strategies that could
// have produced the same path (Veach 1997, sec. 10.2 and eq. 9.13).
// Parameters: the registration below (Mitsuba 3's (0.6's) `bdpt`'s, and
// mis, beta, strategy_images).
//
// Driver: bdpt splats (t = 1), so it runs through the light-path driver
// (light_render.cpp): light path g = s W H + j also traces one camera path
// through pixel j, its film position drawn by filter importance sampling
// (camera_sample.h, as every camera path), and its (t >= 2) contributions go to pixel j alone
// (Splat::pixel), scaled by W H so that the driver's division by spp W H
// leaves the mean over the pixel's spp camera samples.
//
// Densities of the MIS weights, per sample (one camera and one light path):
// the camera's density of z1 per unit area is W(z1) |cos z1| / (W H), W the
// importance of sample_direction (per unit film area in pixels), because
// camera paths cover the film uniformly with W H of them per spp; that is
// pbrt-v4's PerspectiveCamera::PDF_We (1 / (A cos^3) per steradian over the
// whole film) converted to area, and for the orthographic camera the uniform
// density over the film plane, projected. Exact for the box filter; for
// other filters any consistent choice keeps the weights a partition of
// unity, hence the estimator unbiased (Veach 1997, sec. 9.2.1).
//
// Emitters at infinity (constant, directional) as pbrt-v4's BDPT: a camera
// path that leaves the scene ends on a Light vertex at infinity (s = 0);
// light subpaths start on the disk outside the scene, y1 with the disk's
// planar density times |cos|, y0 with its direction's light-sampling
// density (subpath.cpp). An irradiancemeter's camera vertex is a point of
// its shape (sensor.cpp). A sensor without importance (the radiance meter:
// a delta position and a delta direction) can be reached by no light
// subpath, so t = 1 cannot make any path there: z0 is marked a delta
// vertex, which leaves t = 1 out of every weight's denominator (Veach 1997,
// sec. 10.2.1: a strategy whose connection touches a delta vertex has
// density 0), and the other strategies, z1 found by the meter's ray, are
// weighted among themselves.
//
// Participating media (Veach 1997 ch. 10 over the volume path
// measure of Pauly et al. 2000; pbrt-v3 sec. 16.3): both subpaths walk
// through media with subpath.cpp's random_walk, the camera subpath from the
// near clip in the sensor's medium (as volpath's camera rays), the light
// subpath from its emitter's medium (as ptracer's). Medium vertices are
// connectible like diffuse surface vertices: a connection evaluates the
// phase function there (no cosine: the volume measure has none) and is
// weighted by the transmittance of the connecting segment through media and
// index-matched boundaries (Scene::transmittance: Beer-Lambert, ratio
// tracking in grids, as volpath's next event estimation), any other surface
// blocking it; s = 0 (the camera walk reaching an emitter) carries the
// transmittance in the walk's throughput, t = 1 is connect_to_sensor.
//
// Spectral MIS in connections: each subpath draws its own hero channel, and
// its beta is f / mean_c p_c of its prefix, an unbiased estimate of the
// prefix's contribution under the one-sample balance heuristic over the
// three channels (media_common.h's SpectralThroughput; Miller et al. 2019,
// sec. 5.2). The two subpaths are independent, so the product
// beta_z * c * beta_y (c the connection's f_z Tr f_y / d^2, Tr per channel
// and not sampled, as in volpath's next event estimation) is an unbiased
// estimate of the whole path's contribution: the connection samples nothing
// and so needs no spectral weight of its own.
//
// MIS densities with medium vertices: pbrt-v3's choice (sec. 16.3.1, its
// Vertex::Pdf and ConvertDensity leave out transmittance and the free-flight
// densities): the per-vertex densities of the weights are the geometric
// ones only (solid angle to area, without a cosine at a medium vertex:
// subpath.cpp's to_area), with no sigma_t T or T factor and no hero
// channel. The weights stay a partition of unity over the strategies that
// can make a path, since all strategies' weights of that path are computed
// from the same densities (Veach 1997, sec. 9.2.1 and eq. 10.9), so the
// estimator stays unbiased. What is left out is smaller than it looks: an
// inner medium vertex x_i is sampled in every strategy exactly once, from
// one side or the other, and both sides' true densities carry the same
// sigma_t(x_i) (and scattering probability), which cancel in the ratios of
// eq. 10.9; only the transmittances of the segment the vertex was reached
// along differ (T(x_{i-1}, x_i) from the camera side, T(x_i, x_{i+1}) from
// the light's), so the weights are less than optimal only where those
// differ strongly (thick, chromatic or strongly varying media).
#include <algorithm>
#include <climits>
#include <cmath>
#include <stdexcept>

#include "estimators/bdpt_internal.h"
#include "film/film.h"
#include "render/registry.h"
#include "transport/camera_sample.h"
#include "transport/subpath.h"

namespace rm {

namespace {

enum class Mis { Power, Balance, Uniform };

std::unique_ptr<Integrator> make_bdpt(ParamReader& p);

[[maybe_unused]] const bool kRegistered = register_estimator([] {
    EstimatorInfo e;
    e.name = "bdpt";
    e.doc =
        "bidirectional path tracing: every strategy (s, t) combined by multiple importance sampling "
        "(Veach 1997, ch. 10)";
    e.params = {
        max_depth_param().described("longest path in segments (s + t - 1)"),
        rr_depth_param().described("subpath depth (segments) from which Russian roulette may stop a subpath"),
        hide_emitters_param(),
        mis_param(),
        mis_beta_param(),
        strategy_images_param(),
    };
    e.caps.media = true;
    e.caps.driver = Driver::Light;
    e.factory = make_bdpt;
    return e;
}());

Mis mis_from_name(const std::string& name) {
    if (name == "balance") return Mis::Balance;
    if (name == "uniform") return Mis::Uniform;
    return Mis::Power;  // the declaration admits no other name
}

}  // namespace

class BdptIntegrator final : public Integrator {
    friend class BdptMisProbeImpl;  // the test hook's access (bdpt_internal.h)

public:
    explicit BdptIntegrator(ParamReader& p)
        : max_depth_(p.get_int("max_depth")),
          rr_depth_(p.get_int("rr_depth")),
          hide_(p.get_bool("hide_emitters")),
          beta_(p.get_float("beta")),
          strategy_depth_(p.get_int("strategy_images")),
          mis_(mis_from_name(p.get_string("mis"))) {}

    int strategy_depth() const override { return strategy_depth_; }
    void sample(const Scene&, Sampler&, const Ray&, EffectRadiance&, ThreadStats&) const override {
        throw std::logic_error("integrator 'bdpt' runs through the light-path driver, not camera rays");
    }

    void check_scene(const Scene& scene) const override {
        const SensorDesc& sd = scene.sensor_desc;
        filter_ = std::make_unique<FilterSampler>(sd.rfilter, sd.filter_radius, sd.filter_stddev);
    }

    // Steps 1 and 2 of trace_light_path: the two subpaths, into cam_ref()
    // and light_ref(); `es` keeps the emission sample. `cam_limit`,
    // `light_limit` (>= 0): at most that many vertices (mmlt's one strategy).
    void generate_subpaths(const Scene& scene, Sampler& sampler, int pixel, EmissionSample& es, ThreadStats& stats,
                           int cam_limit = -1, int light_limit = -1) const {
        const Sensor& sensor = *scene.sensor;
        std::vector<PathVertex>& cam = cam_ref();
        std::vector<PathVertex>& light = light_ref();
        cam.clear();
        light.clear();
        ++stats.paths;

        // 1. The camera subpath through `pixel`, its film position drawn by
        //    filter importance sampling (camera_sample.h).
        SensorRay sr = sample_camera_ray(sensor, *filter_, pixel, sampler);
        PathVertex z0;
        z0.type = VType::Camera;
        z0.it.p = sr.ray.o;
        z0.it.n = sr.n;
        z0.beta = sr.weight;
        z0.pdf_fwd = 1.f;
        z0.delta = !sensor.has_importance();                      // a radiance meter: no t = 1 (the file's head)
        int max_cam = max_depth_ < 0 ? INT_MAX : max_depth_ + 1;  // z0 .. z_max_depth
        if (cam_limit >= 0) max_cam = std::min(max_cam, cam_limit);
        if (!scene.features.has_media) {
            cam.push_back(z0);
            random_walk(scene, sampler, sr.ray, sr.weight, TransportMode::Radiance, max_cam, rr_depth_, cam, stats);
        } else {
            // Through media the walk starts at the near clip in the
            // sensor's medium (volpath's camera rays; connect_to_sensor's
            // transmittance also ends there); z0 stays at the pinhole, where
            // the densities of the weights are measured from.
            Ray ray = sr.ray;
            ray.o = ray.o + ray.d * ray.tmin;
            ray.tmax = std::isinf(ray.tmax) ? kInf : ray.tmax - ray.tmin;
            ray.tmin = 0.f;
            MediumTracker mt{scene.sensor_desc.medium, false};
            z0.medium = mt.medium;
            cam.push_back(z0);
            random_walk(scene, sampler, ray, sr.weight, TransportMode::Radiance, max_cam, rr_depth_, cam, stats,
                        nullptr, &mt);
        }

        // 2. The light subpath: an emitter picked uniformly (as NEE), a ray of light leaving it.
        int max_light = max_depth_ < 0 ? INT_MAX : max_depth_;  // y0 .. y_{max_depth - 1}
        if (light_limit >= 0) max_light = std::min(max_light, light_limit);
        if (max_light > 0) light_subpath(scene, sampler, max_light, rr_depth_, light, es, stats);

        // 3. Each vertex's effect-class code, for classify().
        std::vector<uint8_t>& cc = tl_codes().first;
        std::vector<uint8_t>& lc = tl_codes().second;
        cc.resize(cam.size());
        lc.resize(light.size());
        for (size_t i = 0; i < cam.size(); ++i) cc[i] = class_code(cam[i]);
        for (size_t i = 0; i < light.size(); ++i) lc[i] = class_code(light[i]);
    }

    // Multiplexed MLT's sample (Hachisuka, Kaplanyan and Dachsbacher 2014,
    // sec. 4): strategy (s, t) alone, on subpaths of just s and t
    // vertices, its MIS-weighted contribution times `n_strategies` (the
    // strategies of its depth it was chosen among uniformly); the splat
    // conventions of trace_light_path. Nothing when (s, t) cannot be made.
    void trace_strategy(const Scene& scene, Sampler& sampler, int pixel, int s, int t, float n_strategies,
                        std::vector<Splat>& out, ThreadStats& stats) const {
        const float film_scale = float(scene.sensor->width) * float(scene.sensor->height);
        EmissionSample es;
        generate_subpaths(scene, sampler, pixel, es, stats, t, s == 1 ? 0 : s);
        std::vector<PathVertex>& cam = cam_ref();
        std::vector<PathVertex>& light = light_ref();
        const int depth = s + t - 1;
        if (int(cam.size()) < t || (s != 1 && int(light.size()) < s)) return;
        if (s == 1 && scene.emitters.empty()) return;
        if (t == 1 && cam[0].delta) return;
        if (s > 0 && cam[t - 1].type == VType::Light) return;
        if (depth < 1 || (s == 1 && t == 1)) return;
        if (max_depth_ >= 0 && depth > max_depth_) return;
        Splat sp;
        float w = 0.f;
        Color L = connect(scene, sampler, es, s, t, sp.film, sp.effect, w, hide_ && depth == 1, stats);
        if (is_black(L) || !(w > 0.f)) return;
        sp.value = L * (w * n_strategies);
        sp.weight = w;
        if (t > 1) {
            sp.pixel = pixel;
            sp.value *= film_scale;
        }
        out.push_back(sp);
    }

    void trace_light_path(const Scene& scene, Sampler& sampler, int pixel, std::vector<Splat>& out,
                          ThreadStats& stats) const override {
        const float film_scale = float(scene.sensor->width) * float(scene.sensor->height);
        EmissionSample es;
        generate_subpaths(scene, sampler, pixel, es, stats);
        std::vector<PathVertex>& cam = cam_ref();
        std::vector<PathVertex>& light = light_ref();
        size_t n_em = scene.emitters.size();

        // 3. Every strategy (s, t) with s + t - 1 segments, 1 <= s + t - 1 <= max_depth.
        //    (1, 1), the emitter's origin seen by the camera, is left to (0, 2),
        //    as in pbrt-v4 (its weight is then 1).
        // s = 1 draws its own emitter sample, so it exists even without a light subpath.
        const int nc = int(cam.size()), nl = std::max(int(light.size()), n_em > 0 ? 1 : 0);
        for (int t = cam[0].delta ? 2 : 1; t <= nc; ++t)
            for (int s = 0; s <= nl; ++s) {
                if (s > int(light.size()) && s != 1) continue;
                if (s > 0 && cam[t - 1].type == VType::Light) continue;  // an escaped camera path: s = 0 only
                int depth = s + t - 1;
                if (depth < 1 || (s == 1 && t == 1)) continue;
                if (max_depth_ >= 0 && depth > max_depth_) continue;
                bool hidden = hide_ && depth == 1;
                Splat sp;
                float w = 0.f;
                Color L = connect(scene, sampler, es, s, t, sp.film, sp.effect, w, hidden, stats);
                if (is_black(L) || !(w > 0.f)) continue;
                sp.value = L * w;
                sp.weight = w;
                if (depth <= strategy_depth_) sp.strategy = strategy_index(s, t);
                if (t > 1) {
                    sp.pixel = pixel;
                    sp.value *= film_scale;
                }
                out.push_back(sp);
            }
    }

private:
    float heuristic(float r) const {
        switch (mis_) {
            case Mis::Balance:
                return r;
            case Mis::Uniform:
                return 1.f;
            default:
                return beta_ == 2.f ? r * r : std::pow(r, beta_);
        }
    }

    // MIS weight of strategy (s, t) in time linear in s + t: with r_i the
    // ratio of the density of the strategy that would connect at vertex i to
    // the density of (s, t), w = 1 / (1 + sum_i h(r_i)) (Veach 1997, eq. 10.9
    // and sec. 10.2.1, where p_{i+1} / p_i = p^<-_i / p^->_i: each ratio is the
    // previous one times one vertex's reverse over forward density; pbrt-v4
    // BDPT MISWeight). h(r) = r^beta is the power heuristic (eq. 9.13), r the
    // balance heuristic, 1 the uniform weights. A strategy exists only if
    // both vertices it connects are non-delta (and, for s' = 0, the light is
    // not a delta position). The densities at the connection are set here
    // for the duration of the call.
    float mis_weight(const Scene& scene, int s, int t) const {
        if (s + t == 2) return 1.f;
        std::vector<PathVertex>& cam = cam_ref();
        std::vector<PathVertex>& light = light_ref();
        PathVertex* qs = s > 0 ? &light[s - 1] : nullptr;
        PathVertex* pt = &cam[t - 1];
        PathVertex* qs_m = s > 1 ? &light[s - 2] : nullptr;
        PathVertex* pt_m = t > 1 ? &cam[t - 2] : nullptr;
        struct Saved {
            float pt_rev = 0, ptm_rev = 0, qs_rev = 0, qsm_rev = 0;
            bool pt_delta = false, qs_delta = false;
        } sv;
        sv.pt_rev = pt->pdf_rev;
        sv.pt_delta = pt->delta;
        if (pt_m) sv.ptm_rev = pt_m->pdf_rev;
        if (qs) {
            sv.qs_rev = qs->pdf_rev;
            sv.qs_delta = qs->delta;
        }
        if (qs_m) sv.qsm_rev = qs_m->pdf_rev;

        pt->pdf_rev = s > 0 ? pdf_to(scene, *qs, qs_m, *pt) : light_origin_pdf(scene, *pt, *pt_m);
        if (pt_m) pt_m->pdf_rev = s > 0 ? pdf_to(scene, *pt, qs, *pt_m) : emitter_pdf_to(scene, *pt, *pt_m);
        if (qs) qs->pdf_rev = pdf_to(scene, *pt, pt_m, *qs);
        if (qs_m) qs_m->pdf_rev = pdf_to(scene, *qs, pt, *qs_m);
        pt->delta = false;  // the ends of a connection (or the emitter an s = 0 path ends on)
        if (qs) qs->delta = false;

        // The emitter vertex's density differs between strategy s' = 1 (next
        // event estimation: p_NEE) and s' >= 2 (light subpath: p_LE); the
        // ratio chain carries the one stored for the current strategy, so
        // each alternative's ratio is corrected by m(s') (nee_over_emission,
        // c = p_NEE / p_LE; 1 for emitters whose two densities agree).
        float c = s >= 2   ? nee_over_emission(scene, light[0], light[1])
                  : s == 1 ? nee_over_emission(scene, light[0], *pt)
                           : nee_over_emission(scene, *pt, *pt_m);
        auto m = [&](int s_alt) {
            if (s_alt == 0 || c == 1.f) return 1.f;
            if (s_alt == 1) return s >= 2 ? c : 1.f;
            return s >= 2 ? 1.f : 1.f / c;
        };
        float sum = 0.f, ri = 1.f;
        for (int i = t - 1; i > 0; --i) {  // strategies with fewer camera vertices
            ri *= remap0(cam[i].pdf_rev) / remap0(cam[i].pdf_fwd);
            if (!cam[i].delta && !cam[i - 1].delta) sum += heuristic(ri * m(s + t - i));
        }
        ri = 1.f;
        for (int i = s - 1; i >= 0; --i) {  // strategies with fewer light vertices
            ri *= remap0(light[i].pdf_rev) / remap0(light[i].pdf_fwd);
            bool delta_before = i > 0 ? light[i - 1].delta : light[0].emitter->is_delta();
            if (!light[i].delta && !delta_before) sum += heuristic(ri * m(i));
        }

        pt->pdf_rev = sv.pt_rev;
        pt->delta = sv.pt_delta;
        if (pt_m) pt_m->pdf_rev = sv.ptm_rev;
        if (qs) {
            qs->pdf_rev = sv.qs_rev;
            qs->delta = sv.qs_delta;
        }
        if (qs_m) qs_m->pdf_rev = sv.qsm_rev;
        return 1.f / (1.f + sum);
    }

    // The contribution of strategy (s, t) before its MIS weight `w`, its
    // effect class and, for t = 1, its film position. Veach 1997, eq. 10.8:
    // C = alpha^L_s c_{s,t} alpha^E_t.
    Color connect(const Scene& scene, Sampler& sampler, const EmissionSample& es, int s, int t, Vec2& film, int& effect,
                  float& w, bool hidden, ThreadStats& stats) const {
        Color L(0.f);
        w = 0.f;
        // Random numbers for s = 1 are drawn whatever happens, so that with a
        // pinhole camera and no grid media the stream of the later
        // strategies does not depend on the mask. (Ratio tracking in grid
        // media and an irradiancemeter's point are drawn only for the
        // strategies that are evaluated: an `effects` subset then changes
        // the bytes of the classes it keeps, not their expectation.)
        float u_pick = 0.f, u_extra = 0.f;
        Vec2 u_l;
        if (s == 1) {
            u_pick = sampler.next_1d();
            u_l = sampler.next_2d();
            u_extra = sampler.next_1d();
        }
        // The class decides whether the strategy is evaluated only under an
        // `effects` subset; with every class requested it is needed only for
        // a contribution, so it is found last (most connections are black).
        const bool every = std::all_of(mask.begin(), mask.end(), [](bool m) { return m; });
        if (!every) {
            effect = classify(s, t);
            if (!mask[effect]) return L;
        }
        if (hidden) return L;
        L = evaluate(scene, sampler, es, s, t, u_pick, u_l, u_extra, film, w, stats);
        if (every && !is_black(L)) effect = classify(s, t);
        return L;
    }

    // connect's strategy (s, t) itself: its contribution before the MIS
    // weight `w`, with s = 1's emitter sample drawn by connect.
    Color evaluate(const Scene& scene, Sampler& sampler, const EmissionSample& es, int s, int t, float u_pick, Vec2 u_l,
                   float u_extra, Vec2& film, float& w, ThreadStats& stats) const {
        std::vector<PathVertex>& cam = cam_ref();
        std::vector<PathVertex>& light = light_ref();
        Color L(0.f);
        if (s == 0) {
            // The camera subpath found an emitter.
            const PathVertex& z = cam[t - 1];
            if (z.infinite) {  // it left the scene: every environment emitter's radiance
                for (const Emitter* env : scene.environment) L += env->eval_environment(-z.it.wi);
                L = z.beta * L;
            } else {
                if (z.type != VType::Surface || !z.emitter) return L;
                L = z.beta * z.emitter->eval(z.it, z.it.wi);
            }
            if (is_black(L)) return L;
        } else if (t == 1) {
            // A light vertex connected to the camera (light tracing's splat).
            PathVertex& y = light[s - 1];
            ImportanceSample is;
            L = connect_to_sensor(scene, y, is, stats, sampler);
            if (is_black(L)) return L;
            film = is.film;
            PathVertex z0;
            z0.type = VType::Camera;
            z0.it.p = is.p;
            // An area sensor's point has a normal (its ray directions'
            // density about it enters the weights); a pinhole's has none.
            z0.it.n = is.n;
            z0.pdf_fwd = 1.f;
            PathVertex saved = cam[0];
            cam[0] = z0;
            w = mis_weight(scene, s, t);
            cam[0] = saved;
            return L;
        } else if (s == 1) {
            // Next event estimation with a fresh emitter sample.
            PathVertex y0;
            L = connect_emitter_sample(scene, cam[t - 1], u_pick, u_l, u_extra, sampler, stats, y0);
            if (is_black(L)) return L;
            bool had = !light.empty();
            PathVertex saved;
            if (had)
                saved = light[0];
            else
                light.push_back(y0);
            light[0] = y0;
            w = mis_weight(scene, s, t);
            if (had)
                light[0] = saved;
            else
                light.pop_back();
            return L;
        } else {
            // Connect y_{s-1} and z_{t-1}: f_L Tr f_E / d^2 (Veach 1997,
            // eq. 10.8), the cosines inside the BSDF evals, none at a medium
            // vertex; Tr the segment's transmittance (1 or 0 without media).
            PathVertex& y = light[s - 1];
            PathVertex& z = cam[t - 1];
            auto scatters = [](const PathVertex& v) { return v.type == VType::Surface || v.type == VType::Medium; };
            if (!scatters(y) || !scatters(z) || !y.connectible() || !z.connectible()) return L;
            Vec3 d = y.it.p - z.it.p;
            float d2 = length_sq(d);
            if (!(d2 > 0.f)) return L;
            float dist = std::sqrt(d2);
            d = d / dist;
            Color fz = scatter_value(z, d, TransportMode::Radiance);
            if (is_black(fz)) return L;
            Color fy = scatter_value(y, -d, TransportMode::Importance);
            if (is_black(fy)) return L;
            DirectSample ds;
            ds.p = y.it.p;
            ds.n = y.it.n;  // zero at a medium vertex: the shadow ray ends at the point itself
            ds.eps = y.it.eps;
            ds.d = d;
            ds.dist = dist;
            Color tr = connection_transmittance(scene, z, ds, sampler, stats);
            if (is_black(tr)) return L;
            L = z.beta * fz * tr * fy * y.beta / d2;
        }
        w = mis_weight(scene, s, t);
        return L;
    }

    // Strategy (s, t)'s effect class from the codes generate_subpaths left
    // (classify_strategy's result; connect swaps only z0 and y0, which no
    // class reads).
    int classify(int s, int t) const {
        return classify_codes(tl_codes().first.data(), t, tl_codes().second.data(), s, true);
    }
    static std::pair<std::vector<uint8_t>, std::vector<uint8_t>>& tl_codes() {
        thread_local std::pair<std::vector<uint8_t>, std::vector<uint8_t>> c;
        return c;
    }

    static std::vector<PathVertex>& cam_ref() { return tl_paths().first; }
    static std::vector<PathVertex>& light_ref() { return tl_paths().second; }
    static std::pair<std::vector<PathVertex>, std::vector<PathVertex>>& tl_paths() {
        thread_local std::pair<std::vector<PathVertex>, std::vector<PathVertex>> p;
        return p;
    }

    int max_depth_, rr_depth_;
    bool hide_;
    float beta_;
    int strategy_depth_;
    Mis mis_ = Mis::Power;
    // Built by check_scene, before any path: safe because make_integrator
    // builds a fresh integrator for every render (never shared by two).
    mutable std::unique_ptr<FilterSampler> filter_;
};

namespace {

std::unique_ptr<Integrator> make_bdpt(ParamReader& p) { return std::make_unique<BdptIntegrator>(p); }

}  // namespace

// The test hook's view of bdpt (bdpt_internal.h): the production code, forwarded.
class BdptMisProbeImpl final : public BdptMisProbe {
public:
    BdptMisProbeImpl(const Scene& scene, const BdptIntegrator& b) : b_(b) { b_.check_scene(scene); }
    void generate_subpaths(const Scene& scene, Sampler& sampler, int pixel) const override {
        EmissionSample es;
        ThreadStats stats;
        b_.generate_subpaths(scene, sampler, pixel, es, stats);
    }
    std::vector<PathVertex>& cam() const override { return BdptIntegrator::cam_ref(); }
    std::vector<PathVertex>& light() const override { return BdptIntegrator::light_ref(); }
    float mis_weight(const Scene& scene, int s, int t) const override { return b_.mis_weight(scene, s, t); }
    double heuristic_exponent() const override {
        return b_.mis_ == Mis::Uniform ? 0.0 : b_.mis_ == Mis::Balance ? 1.0 : double(b_.beta_);
    }
    int max_depth() const override { return b_.max_depth_; }

private:
    const BdptIntegrator& b_;
};

void bdpt_trace_strategy(const Integrator& bdpt, const Scene& scene, Sampler& sampler, int pixel, int s, int t,
                         float n_strategies, std::vector<Splat>& out, ThreadStats& stats) {
    static_cast<const BdptIntegrator&>(bdpt).trace_strategy(scene, sampler, pixel, s, t, n_strategies, out, stats);
}

std::unique_ptr<BdptMisProbe> make_bdpt_mis_probe(const Scene& scene, const Integrator& bdpt) {
    const auto* b = dynamic_cast<const BdptIntegrator*>(&bdpt);
    if (!b) throw std::invalid_argument("bdpt_mis_check: integrator '" + bdpt.type + "' is not bdpt");
    return std::make_unique<BdptMisProbeImpl>(scene, *b);
}

}  // namespace rm
