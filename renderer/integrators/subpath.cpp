// The subpath machinery of subpath.h, shared by ptracer.cpp and bdpt.cpp.
#include "integrators/subpath.h"

#include <algorithm>
#include <stdexcept>
#include <string>

namespace rm {

float to_area(float pdf_w, const Vec3& from, const PathVertex& to) {
    if (to.infinite) return pdf_w;
    Vec3 v = to.it.p - from;
    float d2 = length_sq(v);
    if (!(d2 > 0.f)) return 0.f;
    float c = length_sq(to.it.n) > 0.f ? absdot(to.it.n, v) / std::sqrt(d2) : 1.f;
    return pdf_w * c / d2;
}

float emitter_pdf_to(const Scene& scene, const PathVertex& v, const PathVertex& next) {
    Vec3 d = next.it.p - v.it.p;
    float len = length(d);
    if (!(len > 0.f)) return 0.f;
    d = d / len;
    if (v.infinite) {
        Vec3 c;
        float r;
        scene.bounding_sphere(c, r);
        float rd = infinite_disk_radius(r);
        float pdf = 1.f / (kPi * rd * rd);
        return length_sq(next.it.n) > 0.f ? pdf * absdot(next.it.n, d) : pdf;
    }
    return to_area(v.emitter->pdf_emission_w(v.it.n, d), v.it.p, next);
}

float camera_pdf_a(const Scene& scene, const PathVertex& v) {
    if (v.infinite) {  // per steradian: the camera's directional importance over the film
        ImportanceSample is = scene.sensor->eval_direction(normalize(-v.it.wi), nullptr);
        if (!is.valid) return 0.f;
        return is.weight / (float(scene.sensor->width) * float(scene.sensor->height));
    }
    ImportanceSample is = scene.sensor->sample_direction(v.it.p);
    if (!is.valid) return 0.f;
    float c = length_sq(v.it.n) > 0.f ? absdot(v.it.n, is.d) : 1.f;
    return is.weight * c / (float(scene.sensor->width) * float(scene.sensor->height));
}

float pdf_to(const Scene& scene, const PathVertex& v, const PathVertex* prev, const PathVertex& next) {
    if (v.type == VType::Camera) return camera_pdf_a(scene, next);
    Vec3 d = next.it.p - v.it.p;
    float len = length(d);
    if (!(len > 0.f)) return 0.f;
    d = d / len;
    if (v.type == VType::Light) return emitter_pdf_to(scene, v, next);
    if (!prev) return 0.f;
    BsdfContext ctx;
    Vec3 wi = normalize(prev->it.p - v.it.p);
    return to_area(v.bsdf->pdf_w(ctx, v.it.to_local(wi), v.it.to_local(d)), v.it.p, next);
}

float light_origin_pdf(const Scene& scene, const PathVertex& v, const PathVertex& ref) {
    if (v.infinite) {
        float sum = 0.f;
        for (const auto& e : scene.emitters)
            if (e->is_infinite()) sum += e->pdf_direct(ref.it.p, v.it.p, Vec3(0.f));
        return emitter_pick_prob(scene) * sum;
    }
    float pd = v.emitter->pdf_direct(ref.it.p, v.it.p, v.it.n);
    Vec3 d = v.it.p - ref.it.p;
    float d2 = length_sq(d);
    if (!(pd > 0.f) || !(d2 > 0.f)) return 0.f;
    float cos_l = absdot(v.it.n, d) / std::sqrt(d2);
    return emitter_pick_prob(scene) * pd * cos_l / d2;
}

float nee_over_emission(const Scene& scene, const PathVertex& y0, const PathVertex& adj) {
    if (y0.infinite || !y0.emitter || y0.emitter->is_delta()) return 1.f;
    float le = emitter_pick_prob(scene) * y0.emitter->pdf_emission_a(y0.it.p);
    float nee = light_origin_pdf(scene, y0, adj);
    if (!(le > 0.f) || !(nee > 0.f) || !std::isfinite(nee / le)) return 1.f;
    return nee / le;
}

// A point along `ray` beyond the scene's bounding sphere: where a vertex at
// infinity sits, so that directions computed from the scene towards it are
// the ray's direction.
Vec3 far_point(const Scene& scene, const Ray& ray) {
    Vec3 c;
    float r;
    scene.bounding_sphere(c, r);
    return ray.o + ray.d * (2.f * (r + length(ray.o - c)) + 1.f);
}

// Each new vertex gets pdf_fwd and its predecessor's predecessor pdf_rev
// (Veach 1997, sec. 10.2.1), both through pdf_to from the vertex positions,
// exactly as the connections compute them: the weights are a partition of
// unity only if every strategy sees the same numbers (the sampled direction
// leaves an offset origin, and for vertices 1e-2 apart in a corner that
// moved densities by 1 %, measured by bdpt_mis_check).
void random_walk(const Scene& scene, Sampler& sampler, Ray ray, Color beta, TransportMode mode, int max_vertices,
                 int rr_depth, std::vector<PathVertex>& path, ThreadStats& stats, const WalkStop* stop) {
    BsdfContext ctx{mode};
    Color thr(1.f);         // throughput since the start (Russian roulette)
    float eta_scale = 1.f;  // undoes radiance scaling by eta^2 (Russian roulette)
    for (int depth = 1;; ++depth) {  // depth: segments from the start to the new vertex
        if (int(path.size()) >= max_vertices) break;
        Interaction it;
        ++stats.rays;
        if (!scene.intersect(ray, it)) {
            // A camera path leaving the scene ends on the environment: a
            // Light vertex at infinity, for the s = 0 strategy (pbrt-v4).
            if (mode == TransportMode::Radiance && !scene.environment.empty()) {
                PathVertex v;
                v.type = VType::Light;
                v.infinite = true;
                v.emitter = scene.environment[0];
                v.it.p = far_point(scene, ray);
                v.it.wi = -ray.d;
                v.beta = beta;
                const size_t n = path.size();
                const PathVertex& prev = path[n - 1];
                if (n == 1) {
                    v.pdf_fwd = camera_pdf_a(scene, v);
                } else if (prev.delta) {
                    v.pdf_fwd = 0.f;
                    path[n - 2].pdf_rev = 0.f;
                } else {
                    v.pdf_fwd = pdf_to(scene, prev, &path[n - 2], v);
                    path[n - 2].pdf_rev = pdf_to(scene, prev, &v, path[n - 2]);
                }
                path.push_back(v);
            }
            break;
        }
        const Shape& shape = *scene.shapes[it.shape];
        PathVertex v;
        v.it = it;
        v.beta = beta;
        v.bsdf = scene.bsdfs[shape.bsdf].get();
        v.emitter = shape.emitter >= 0 ? scene.emitters[shape.emitter].get() : nullptr;
        const size_t n = path.size();  // index of v
        const PathVertex& prev = path[n - 1];
        if (n == 1) {
            v.pdf_fwd = prev.type == VType::Camera ? camera_pdf_a(scene, v) : pdf_to(scene, prev, nullptr, v);
        } else if (prev.delta) {
            v.pdf_fwd = 0.f;  // a delta: remap0 in the weights (pbrt-v4)
            path[n - 2].pdf_rev = 0.f;
        } else {
            v.pdf_fwd = pdf_to(scene, prev, &path[n - 2], v);
            path[n - 2].pdf_rev = pdf_to(scene, prev, &v, path[n - 2]);
        }
        path.push_back(v);
        if (int(path.size()) >= max_vertices) break;
        if (stop && (*stop)(path)) break;

        // Sample the next direction (adjoint BSDF with the shading-normal
        // correction in importance transport, common.h).
        PathVertex& cur = path.back();
        Vec3 wi = it.to_local(it.wi);
        BsdfSample bs = cur.bsdf->sample(ctx, wi, sampler.next_1d(), sampler.next_2d());
        if (!(bs.pdf_w > 0.f) || is_black(bs.weight)) break;
        Vec3 wo = it.to_world(bs.wo);
        Color f = bs.weight;
        if (mode == TransportMode::Importance) f *= shading_correction(it, it.wi, wo);
        else eta_scale *= sqr(bs.eta);
        beta *= f;
        thr *= f;
        cur.delta = bs.is_delta;
        ray = it.spawn(wo);

        // Russian roulette (Mitsuba: q = min(max(throughput) eta^2, 0.95)).
        float rr_u = sampler.next_1d();
        if (depth >= rr_depth) {
            float q = std::min(max_component(thr) * eta_scale, 0.95f);
            if (!(rr_u < q)) break;
            beta /= q;
            thr /= q;
        }
    }
}

bool light_subpath(const Scene& scene, Sampler& sampler, int max_vertices, int rr_depth,
                   std::vector<PathVertex>& light, EmissionSample& es, ThreadStats& stats, const WalkStop* stop) {
    light.clear();
    size_t n_em = scene.emitters.size();
    float u_pick = sampler.next_1d();
    Vec2 u_pos = sampler.next_2d();
    float u_extra = sampler.next_1d();
    Vec2 u_dir = sampler.next_2d();
    if (n_em == 0) return false;
    const Emitter& e = *scene.emitters[std::min(size_t(u_pick * float(n_em)), n_em - 1)];
    Vec3 center;
    float radius;
    scene.bounding_sphere(center, radius);
    es = e.sample_emission(u_pos, u_extra, u_dir, center, radius);
    if (!(es.pdf_a > 0.f) || !(es.pdf_w > 0.f)) return false;
    float pick = emitter_pick_prob(scene);
    PathVertex y0;
    y0.type = VType::Light;
    y0.emitter = &e;
    y0.it.p = es.p;
    y0.it.n = es.n;
    y0.it.eps = es.eps;
    y0.pdf_fwd = pick * es.pdf_a;
    y0.infinite = e.is_infinite();
    // At infinity y0's own density is that of its direction under light
    // sampling (pbrt-v4's GenerateLightSubpath); y1's comes from the origin
    // disk through emitter_pdf_to.
    if (y0.infinite) y0.pdf_fwd = light_origin_pdf(scene, y0, y0);
    light.push_back(y0);
    if (stop && (*stop)(light)) return true;
    Ray ray;
    ray.o = es.p + es.n * es.eps;
    ray.d = es.d;
    random_walk(scene, sampler, ray, es.weight / pick, TransportMode::Importance, max_vertices, rr_depth, light, stats,
                stop);
    return true;
}

Color connect_to_sensor(const Scene& scene, const PathVertex& y, ImportanceSample& is, ThreadStats& stats) {
    if (y.type != VType::Surface || !y.connectible()) return Color(0.f);
    is = scene.sensor->sample_direction(y.it.p);
    if (!is.valid) return Color(0.f);
    BsdfContext ctx{TransportMode::Importance};
    Color f = y.bsdf->eval(ctx, y.it.to_local(y.it.wi), y.it.to_local(is.d)) * shading_correction(y.it, y.it.wi, is.d);
    if (is_black(f)) return Color(0.f);
    DirectSample ds;
    ds.p = is.p;
    ds.d = is.d;
    ds.dist = is.dist;
    ++stats.shadow_rays;
    if (!scene.visible(y.it, ds)) return Color(0.f);
    return y.beta * f * is.weight;
}

int classify_strategy(const std::vector<PathVertex>& cam, const std::vector<PathVertex>& light, int s, int t) {
    PathClass pc;
    int last_cam = s == 0 ? t - 2 : t - 1;
    for (int i = 1; i <= last_cam; ++i)
        if (!cam[i].null_surface()) pc.push(i == t - 1 ? false : cam[i].delta);
    for (int i = s - 1; i >= 1; --i)
        if (!light[i].null_surface()) pc.push(i == s - 1 ? false : light[i].delta);
    return pc.classify();
}

void check_strategy_images(const char* integrator, int strategy_images) {
    if (strategy_images < 0 || strategy_images > 16)
        throw std::invalid_argument(std::string("integrator '") + integrator +
                                    "': strategy_images must be a path depth in 0..16 (0: none), not " +
                                    std::to_string(strategy_images));
}

}  // namespace rm
