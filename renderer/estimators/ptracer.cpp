// `ptracer`: light tracing (particle tracing). Light subpaths start on the
// emitters and every non-specular vertex is connected to the sensor (the
// t = 1 strategy of Veach 1997, sec. 10.2; pbrt-v4's LightPathIntegrator and
// Mitsuba 3's `ptracer` plugin). Emitters seen directly by the camera come
// from connecting the emission sample's own origin to the sensor (s = 1,
// t = 1), as Mitsuba's ptracer does. Parameters: the registration below
// (Mitsuba 3's `ptracer` plugin's, and strategy_images).
// A render of `spp` traces spp * width * height light paths (as Mitsuba), and
// the driver (light_render.cpp) splats, filters and averages their splats.
//
// Participating media (pbrt-v4's volumetric light paths, PBR4
// sec. 14.2, with the null-scattering formulation of Miller et al. 2019):
// a light subpath starts in its emitter's medium (media_common.h's
// emitter_medium), samples free flights there as volpath does (hero
// channel, spectral MIS: its throughput is f / mean_c p_c; delta tracking
// in grids, Novak et al. 2018), scatters by the phase function (a medium
// vertex counts towards max_depth like a surface vertex; index-matched
// boundaries do not), and tracks the medium across boundaries by Mitsuba 3's
// rule. Every medium vertex is joined to the sensor through its phase
// function; every connection (and the emitter seen directly) is weighted by
// the transmittance up to where camera rays start (the near clip), through
// media and null boundaries, ratio tracking in grids (Scene::transmittance).
// A camera inside a medium makes light tracing heavy-tailed: a medium
// vertex at distance r from a pinhole splats ~1 / r^2, so the second moment
// grows as 1 / near_clip.
//
// Limits, inherent to light tracing (Mitsuba's ptracer shares them): paths
// whose vertex next to the camera is specular (the `specular` effect class:
// mirrors and glass seen by the camera) are never produced; emitters with a
// delta position (point, spot) are invisible to the camera, as in `path`;
// a medium behind a smooth dielectric (a translucent object's inside) is
// seen through that delta boundary only, so only the light it sends onto
// other surfaces reaches the film.
#include <stdexcept>

#include <climits>

#include "render/registry.h"
#include "transport/subpath.h"

namespace rm {

namespace {

std::unique_ptr<Integrator> make_ptracer(ParamReader& p);

[[maybe_unused]] const bool kRegistered = register_estimator([] {
    EstimatorInfo e;
    e.name = "ptracer";
    e.doc =
        "light tracing: light subpaths connected to the sensor at every non-specular vertex (the t = 1 "
        "strategy, Veach 1997, sec. 10.2)";
    e.params = {
        max_depth_param().described("longest path in segments, sensor connection included (1: only emitters seen "
                                    "directly; 2: direct illumination)"),
        rr_depth_param().described("light-path depth (segments) from which Russian roulette may stop it"),
        hide_emitters_param(),
        ParamSpec::mitsuba_ignored("samples_per_pass", "Mitsuba's GPU wavefront size: changes nothing here"),
        strategy_images_param(),
    };
    e.caps.media = true;
    e.caps.driver = Driver::Light;
    e.caps.effects = effect_mask({kEmission, kDirect, kIndirect, kCaustic, kVolume, kSubsurface});  // no L..SE
    e.factory = make_ptracer;
    return e;
}());

}  // namespace

class LightTracer final : public Integrator {
public:
    explicit LightTracer(ParamReader& p)
        : max_depth_(p.get_int("max_depth")),
          rr_depth_(p.get_int("rr_depth")),
          hide_(p.get_bool("hide_emitters")),
          strategy_depth_(p.get_int("strategy_images")) {}
    int strategy_depth() const override { return strategy_depth_; }

    void sample(const Scene&, Sampler&, const Ray&, EffectRadiance&, ThreadStats&) const override {
        throw std::logic_error("integrator 'ptracer' traces light paths, not camera rays");
    }

    void check_scene(const Scene& scene) const override {
        const std::string& type = scene.sensor_desc.type;
        if (!scene.sensor->has_importance())
            throw std::invalid_argument("integrator 'ptracer': sensor '" + type +
                                        "' cannot be reached by light paths (a radiance meter measures at one "
                                        "point along one direction); use integrator 'path', or a camera or an "
                                        "irradiancemeter");
        if (!hide_ && !scene.environment.empty() && type == "orthographic")
            throw std::invalid_argument(
                "integrator 'ptracer': an orthographic camera sees an environment emitter "
                "along a single direction, which light paths reach with probability 0; set "
                "hide_emitters or use a perspective camera or integrator 'path'");
        // An irradiancemeter sees an environment emitter over its whole
        // hemisphere; light tracing would need its own strategy for that
        // (bdpt's s = 0 has it).
        if (!hide_ && !scene.environment.empty() && scene.sensor->area_sensor())
            throw std::invalid_argument(
                "integrator 'ptracer': the irradiancemeter sees an environment emitter "
                "directly, which light tracing does not connect; set hide_emitters or use "
                "integrator 'bdpt' or 'path'");
    }

    void trace_light_path(const Scene& scene, Sampler& sampler, int, std::vector<Splat>& out,
                          ThreadStats& stats) const override {
        // 1. The light subpath y0 y1 .. (subpath.h: an emitter picked
        //    by the light sampler, a ray of light leaving it, the adjoint random walk),
        //    stopped where no requested class can follow. Vertex y_i joined
        //    to the sensor makes a path of i + 1 segments: y0 .. y_{max_depth - 1}.
        std::vector<PathVertex>& light = tl_light();
        EmissionSample es;
        const int max_vertices = max_depth_ < 0 ? INT_MAX : max_depth_;
        auto reach = [this, &scene](const std::vector<PathVertex>& p) { return reachable(scene, p); };
        VertexVisitor visit(reach);
        if (!scene.emitters.empty()) ++stats.paths;
        if (!light_subpath(scene, sampler, max_vertices, rr_depth_, light, es, stats, &visit, false)) return;
        const float inv_pick = 1.f / start_pick_prob(scene, *light[0].emitter);

        // 2. The emitter seen directly: its sampled origin (or, at infinity,
        //    its sampled direction) connected to the sensor, s = 1, t = 1.
        if (!hide_ && mask[kEmission])
            connect_emitter(scene, *light[0].emitter, es, light[0].medium, inv_pick, out, stats, sampler);

        // 3. Every later vertex joined to the sensor (t = 1; smooth lobes
        //    only), filed under the class of E y_s .. y1 L (DESIGN sec. 3).
        static const std::vector<PathVertex> no_camera;
        for (int s = 2; s <= int(light.size()); ++s) {
            int cls = classify_strategy(no_camera, light, s, 1);
            if (!mask[cls]) continue;
            ImportanceSample is;
            Color L = connect_to_sensor(scene, light[s - 1], is, stats, sampler);
            if (is_black(L)) continue;
            Splat sp{is.film, cls, L};
            if (s <= strategy_depth_) sp.strategy = strategy_index(s, 1);
            out.push_back(sp);
        }
    }

private:
    // Whether a class in `mask` can still come from a vertex after the last
    // one of `p`, whichever lobe that vertex samples (a null vertex changes nothing).
    bool reachable(const Scene& scene, const std::vector<PathVertex>& p) const {
        if (scene.features.has_media) {
            // Through media a later vertex may be V or B (PathClass::can_reach).
            PathClass pc;
            for (size_t i = 1; i < p.size(); ++i)
                if (p[i].type == VType::Medium)
                    pc.push_medium(p[i].enclosed);
                else if (!p[i].null_surface())
                    pc.push(p[i].delta);
            return pc.volume || pc.subsurface ? pc.can_reach(mask, true)
                                              : mask[kVolume] || mask[kSubsurface] || reachable_surface(p);
        }
        return reachable_surface(p);
    }
    bool reachable_surface(const std::vector<PathVertex>& p) const {
        int k = 0;  // scattering vertices among y1 .. y_{n-2}
        bool all_specular = true;
        for (size_t i = 1; i + 1 < p.size(); ++i)
            if (!p[i].null_surface()) {
                ++k;
                all_specular = all_specular && p[i].delta;
            }
        bool null_last = p.size() > 1 && p.back().null_surface();
        if (p.size() == 1 || (null_last && k == 0)) return mask[kDirect] || mask[kCaustic] || mask[kIndirect];
        return mask[kIndirect] || (all_specular && mask[kCaustic]);
    }

    static std::vector<PathVertex>& tl_light() {
        thread_local std::vector<PathVertex> v;
        return v;
    }

    // `medium`: the medium the emission sample's ray leaves into (media only).
    void connect_emitter(const Scene& scene, const Emitter& e, const EmissionSample& es, int medium, float inv_pick,
                         std::vector<Splat>& out, ThreadStats& stats, Sampler& sampler) const {
        const Sensor& sensor = *scene.sensor;
        if (e.is_environment()) {
            // The camera looks along w = -d and sees L(w): weight L / pdf_w(w).
            Ray r;
            Vec3 w = -es.d;
            ImportanceSample is = sensor.eval_direction(w, &r);
            if (!is.valid) return;
            Color le = e.eval_environment(w);
            if (is_black(le)) return;
            ++stats.shadow_rays;
            if (!scene.features.has_media) {
                if (!scene.occluded(r)) out.push_back(emission_splat(is.film, le * (inv_pick * is.weight / es.pdf_w)));
                return;
            }
            // Through media: the camera ray's transmittance over its clip
            // range (volpath's camera ray escapes at the far clip),
            // starting in the sensor's medium.
            Interaction from;
            from.kind = VertexKind::Medium;
            from.p = r.o + r.d * r.tmin;
            DirectSample ds;
            ds.d = r.d;
            if (std::isfinite(r.tmax)) {
                ds.p = r.o + r.d * r.tmax;
                ds.dist = r.tmax - r.tmin;
            }
            Color tr = scene.transmittance(from, ds, scene.sensor_desc.medium, stats.rays, sampler);
            if (!is_black(tr)) out.push_back(emission_splat(is.film, tr * le * (inv_pick * is.weight / es.pdf_w)));
            return;
        }
        // A delta position is never hit by a camera ray (Mitsuba's point and
        // spot eval() are 0, and `path` never sees them): nothing to connect.
        if (e.is_delta()) return;
        ImportanceSample is = sensor_sample(scene, es.p, sampler);
        if (!is.valid) return;
        Color le = e.emitted_towards(es, is.d);  // Le |cos| / pdf_a
        if (is_black(le)) return;
        Interaction from;
        from.p = es.p;
        from.n = es.n;
        from.eps = es.eps;
        // Area lights emit on their normal's side only (one-sided, as
        // Mitsuba's), the side the emission ray left into: its medium.
        Color tr = transmittance_to_sensor(scene, from, medium, is, stats, sampler);
        if (!is_black(tr)) out.push_back(emission_splat(is.film, tr * le * (inv_pick * is.weight)));
    }

    // The emitter seen directly: strategy (1, 1).
    Splat emission_splat(Vec2 film, Color value) const {
        Splat sp{film, kEmission, value};
        if (strategy_depth_ >= 1) sp.strategy = strategy_index(1, 1);
        return sp;
    }

    int max_depth_, rr_depth_;
    bool hide_;
    int strategy_depth_;
};

namespace {

std::unique_ptr<Integrator> make_ptracer(ParamReader& p) { return std::make_unique<LightTracer>(p); }

}  // namespace

}  // namespace rm
