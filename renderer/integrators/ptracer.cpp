// `ptracer`: light tracing (particle tracing). Light subpaths start on the
// emitters and every non-specular vertex is connected to the sensor (the
// t = 1 strategy of Veach 1997, sec. 10.2; pbrt-v4's LightPathIntegrator and
// Mitsuba 3's `ptracer` plugin). Emitters seen directly by the camera come
// from connecting the emission sample's own origin to the sensor (s = 1,
// t = 1), as Mitsuba's ptracer does. Parameters, as Mitsuba 3's `ptracer`:
//   max_depth      longest path in segments, sensor connection included;
//                  -1 = unbounded; 1 = only emitters seen directly; 2 = direct
//   rr_depth       light-path depth (segments) from which Russian roulette may stop it
//   hide_emitters  directly visible emitters appear black
//   (Mitsuba's samples_per_pass only shapes its GPU wavefronts: accepted, ignored)
// A render of `spp` traces spp * width * height light paths (as Mitsuba), and
// the driver (light_render.cpp) splats, filters and averages their splats.
//
// Limits, inherent to light tracing (Mitsuba's ptracer shares them): paths
// whose vertex next to the camera is specular (the `specular` effect class:
// mirrors and glass seen by the camera) are never produced; emitters with a
// delta position (point, spot) are invisible to the camera, as in `path`.
#include <stdexcept>

#include "integrators/common.h"

namespace rm {

namespace {



}  // namespace

class LightTracer final : public Integrator {
public:
    explicit LightTracer(const IntegratorDesc& d) : max_depth_(d.max_depth), rr_depth_(d.rr_depth), hide_(d.hide_emitters) {}

    bool is_light_tracer() const override { return true; }
    void sample(const Scene&, Sampler&, const Ray&, EffectRadiance&, ThreadStats&) const override {
        throw std::logic_error("integrator 'ptracer' traces light paths, not camera rays");
    }

    void check_scene(const Scene& scene) const override {
        const std::string& type = scene.sensor_desc.type;
        if (!scene.sensor->has_importance())
            throw std::invalid_argument("integrator 'ptracer': sensor '" + type +
                                        "' cannot be reached by light paths (light tracing connects to cameras with "
                                        "a film; a radiance or irradiance meter measures along a delta direction "
                                        "or over a shape's surface); use integrator 'path' or a perspective or "
                                        "orthographic camera");
        if (!hide_ && !scene.environment.empty() && type == "orthographic")
            throw std::invalid_argument("integrator 'ptracer': an orthographic camera sees an environment emitter "
                                        "along a single direction, which light paths reach with probability 0; set "
                                        "hide_emitters or use a perspective camera or integrator 'path'");
    }

    void trace_light_path(const Scene& scene, Sampler& sampler, int, std::vector<Splat>& out,
                          ThreadStats& stats) const override {
        const Sensor& sensor = *scene.sensor;
        size_t n = scene.emitters.size();
        // 1. Pick an emitter uniformly (as NEE does) and sample a ray of light leaving it.
        float u_pick = sampler.next_1d();
        Vec2 u_pos = sampler.next_2d();
        float u_extra = sampler.next_1d();
        Vec2 u_dir = sampler.next_2d();
        if (n == 0) return;
        ++stats.paths;
        const Emitter& e = *scene.emitters[std::min(size_t(u_pick * float(n)), n - 1)];
        float inv_pick = 1.f / emitter_pick_prob(scene);
        Vec3 center;
        float radius;
        scene.bounding_sphere(center, radius);
        EmissionSample es = e.sample_emission(u_pos, u_extra, u_dir, center, radius);
        if (!(es.pdf_a > 0.f) || !(es.pdf_w > 0.f)) return;

        // 2. The emitter seen directly: its sampled origin (or, at infinity,
        //    its sampled direction) connected to the sensor, s = 1, t = 1.
        if (!hide_ && mask[kEmission]) connect_emitter(scene, e, es, inv_pick, out, stats);

        // 3. Walk the light subpath L v1 v2 ...; `k` counts its vertices before
        //    the current one (null boundaries are no vertices of the class),
        //    `all_specular` says whether each of them scattered specularly.
        Color beta = es.weight * inv_pick;  // flux carried by the path
        Color thr(1.f);                     // its throughput since the emitter (Russian roulette)
        int k = 0;
        bool all_specular = true;
        Ray ray;
        ray.o = es.p + es.n * es.eps;
        ray.d = es.d;
        BsdfContext ctx{TransportMode::Importance};
        for (int depth = 1;; ++depth) {  // depth: segments from the emitter to `it`
            Interaction it;
            ++stats.rays;
            if (!scene.intersect(ray, it)) break;
            const Bsdf& bsdf = *scene.bsdfs[scene.shapes[it.shape]->bsdf];
            Vec3 wi = it.to_local(it.wi);

            // 4. Connect this vertex to the sensor (smooth lobes only); the
            //    whole path then has depth + 1 segments. Its class comes from
            //    the reversed vertex string E v_k+1 v_k .. v1 L (DESIGN sec. 3).
            if (bsdf.has_smooth() && (max_depth_ < 0 || depth + 1 <= max_depth_)) {
                int cls = k == 0 ? kDirect : (all_specular ? kCaustic : kIndirect);
                if (mask[cls]) {
                    ImportanceSample is = sensor.sample_direction(it.p);
                    if (is.valid) {
                        Color f = bsdf.eval(ctx, wi, it.to_local(is.d)) * shading_correction(it, it.wi, is.d);
                        if (!is_black(f)) {
                            DirectSample ds;
                            ds.p = is.p;
                            ds.d = is.d;
                            ds.dist = is.dist;
                            ++stats.shadow_rays;
                            if (scene.visible(it, ds)) out.push_back({is.film, cls, beta * thr * f * is.weight});
                        }
                    }
                }
            }

            // 5. Stop when the next vertex's connection would exceed max_depth,
            //    or when no requested class can follow.
            if (max_depth_ >= 0 && depth + 2 > max_depth_) break;
            if (!reachable(k, all_specular, bsdf.flags() == kNull)) break;

            // 6. Sample the adjoint BSDF for the next direction.
            BsdfSample bs = bsdf.sample(ctx, wi, sampler.next_1d(), sampler.next_2d());
            if (!(bs.pdf_w > 0.f) || is_black(bs.weight)) break;
            Vec3 wo = it.to_world(bs.wo);
            thr *= bs.weight * shading_correction(it, it.wi, wo);
            if (bsdf.flags() != kNull) {
                ++k;
                all_specular = all_specular && bs.is_delta;
            }
            ray = it.spawn(wo);

            // 7. Russian roulette on the throughput (Mitsuba: q = min(max(thr), 0.95)).
            float rr_u = sampler.next_1d();
            if (depth >= rr_depth_) {
                float q = std::min(max_component(thr), 0.95f);
                if (!(rr_u < q)) break;
                thr /= q;
            }
        }
    }

private:
    // Whether a class in `mask` can still come from a later vertex, given the
    // state after the current vertex scatters (a null vertex changes nothing).
    bool reachable(int k, bool all_specular, bool null_vertex) const {
        if (null_vertex) return k == 0 ? (mask[kDirect] || mask[kCaustic] || mask[kIndirect])
                                        : (mask[kIndirect] || (all_specular && mask[kCaustic]));
        return mask[kIndirect] || (all_specular && mask[kCaustic]);
    }

    void connect_emitter(const Scene& scene, const Emitter& e, const EmissionSample& es, float inv_pick,
                         std::vector<Splat>& out, ThreadStats& stats) const {
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
            if (!scene.occluded(r)) out.push_back({is.film, kEmission, le * (inv_pick * is.weight / es.pdf_w)});
            return;
        }
        // A delta position is never hit by a camera ray (Mitsuba's point and
        // spot eval() are 0, and `path` never sees them): nothing to connect.
        if (e.is_delta()) return;
        ImportanceSample is = sensor.sample_direction(es.p);
        if (!is.valid) return;
        Color le = e.emitted_towards(es, is.d);  // Le |cos| / pdf_a
        if (is_black(le)) return;
        Interaction from;
        from.p = es.p;
        from.n = es.n;
        from.eps = es.eps;
        DirectSample ds;
        ds.p = is.p;
        ds.d = is.d;
        ds.dist = is.dist;
        ++stats.shadow_rays;
        if (scene.visible(from, ds)) out.push_back({is.film, kEmission, le * (inv_pick * is.weight)});
    }

    int max_depth_, rr_depth_;
    bool hide_;
};

std::unique_ptr<Integrator> make_ptracer_integrator(const IntegratorDesc& d) { return std::make_unique<LightTracer>(d); }

}  // namespace rm
