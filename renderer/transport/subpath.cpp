// The subpath machinery of subpath.h: the light walk of ptracer.cpp, bdpt.cpp
// and photon_trace.cpp, and bdpt's camera walk.
#include "transport/subpath.h"

#include "transport/subpath_walk.h"

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

float camera_pdf_a(const Scene& scene, const PathVertex& z0, const PathVertex& v) {
    if (scene.sensor->area_sensor()) {  // directions drawn at z0 itself (sample_ray), about its normal
        Vec3 d = v.it.p - z0.it.p;
        float len = length(d);
        if (!(len > 0.f)) return 0.f;
        return to_area(scene.sensor->pdf_ray_direction(z0.it.n, d / len), z0.it.p, v);
    }
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
    if (v.type == VType::Camera) return camera_pdf_a(scene, v, next);
    Vec3 d = next.it.p - v.it.p;
    float len = length(d);
    if (!(len > 0.f)) return 0.f;
    d = d / len;
    if (v.type == VType::Light) return emitter_pdf_to(scene, v, next);
    if (!prev) return 0.f;
    BsdfContext ctx;
    ctx.set(v.it);
    Vec3 wi = normalize(prev->it.p - v.it.p);
    if (v.type == VType::Medium) return to_area(v.phase->pdf_w(wi, d), v.it.p, next);
    return to_area(v.bsdf->pdf_w(ctx, v.it.to_local(wi), v.it.to_local(d)), v.it.p, next);
}

LightContext vertex_light_context(const PathVertex& v) {
    return {v.it.p, v.type == VType::Medium ? Vec3(0.f) : v.it.n};
}

float light_origin_pdf(const Scene& scene, const PathVertex& v, const PathVertex& ref) {
    const LightContext ctx = vertex_light_context(ref);
    if (v.infinite) {
        // Whichever emitter at infinity was picked: the sum over them.
        float sum = 0.f;
        if (scene.lights().kind() == LightSamplerKind::Uniform) {  // one probability for all
            for (const auto& e : scene.emitters)
                if (e->is_infinite()) sum += e->pdf_direct(ref.it.p, v.it.p, Vec3(0.f));
            return (scene.emitters.empty() ? 0.f : 1.f / float(scene.emitters.size())) * sum;
        }
        for (const auto& e : scene.emitters)
            if (e->is_infinite()) sum += emitter_pick_prob(scene, ctx, *e) * e->pdf_direct(ref.it.p, v.it.p, Vec3(0.f));
        return sum;
    }
    float pd = v.emitter->pdf_direct(ref.it.p, v.it.p, v.it.n);
    Vec3 d = v.it.p - ref.it.p;
    float d2 = length_sq(d);
    if (!(pd > 0.f) || !(d2 > 0.f)) return 0.f;
    float cos_l = absdot(v.it.n, d) / std::sqrt(d2);
    return emitter_pick_prob(scene, ctx, *v.emitter) * pd * cos_l / d2;
}

float nee_over_emission(const Scene& scene, const PathVertex& y0, const PathVertex& adj) {
    if (y0.infinite || !y0.emitter) return 1.f;
    if (y0.emitter->is_delta()) {
        // A delta position: the two densities differ only by the selection.
        float le = start_pick_prob(scene, *y0.emitter);
        float nee = emitter_pick_prob(scene, vertex_light_context(adj), *y0.emitter);
        if (!(le > 0.f) || !(nee > 0.f) || nee == le || !std::isfinite(nee / le)) return 1.f;
        return nee / le;
    }
    float le = emission_origin_pdf(scene, *y0.emitter, y0.it.p);
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

// A vertex with every field at its default (subpath_walk.h).
const PathVertex kFreshVertex{};

void random_walk(const Scene& scene, Sampler& sampler, Ray ray, Color beta, TransportMode mode, int max_vertices,
                 int rr_depth, std::vector<PathVertex>& path, ThreadStats& stats, const VertexVisitor* visit,
                 const MediumTracker* media, bool densities) {
    auto v = [visit](const std::vector<PathVertex>& p) { return !visit || (*visit)(p); };
    random_walk_with(scene, sampler, ray, beta, mode, max_vertices, rr_depth, path, stats, v, media, densities);
}

int emitter_shape(const Scene& scene, const Emitter& e) {
    for (size_t i = 0; i < scene.shapes.size(); ++i) {
        int k = scene.shapes[i]->emitter;
        if (k >= 0 && scene.emitters[k].get() == &e) return int(i);
    }
    return -1;
}

bool light_subpath(const Scene& scene, Sampler& sampler, int max_vertices, int rr_depth, std::vector<PathVertex>& light,
                   EmissionSample& es, ThreadStats& stats, const VertexVisitor* visit, bool densities) {
    auto v = [visit](const std::vector<PathVertex>& p) { return !visit || (*visit)(p); };
    return light_subpath_with(scene, sampler, max_vertices, rr_depth, light, es, stats, v, densities);
}

Color transmittance_to_sensor(const Scene& scene, const Interaction& from, int medium, const ImportanceSample& is,
                              ThreadStats& stats, Sampler& sampler) {
    DirectSample ds;
    ds.p = is.p;
    ds.d = is.d;
    ds.dist = is.dist;
    ++stats.shadow_rays;
    if (!scene.features.has_media) return scene.visible(from, ds) ? Color(1.f) : Color(0.f);
    // Camera rays start at the near clip (as Mitsuba's): the medium is
    // crossed up to there, as volpath's camera rays cross it from there.
    ds.p = is.p - is.d * is.clip;
    ds.dist = is.dist - is.clip;
    return scene.transmittance(from, ds, medium, stats.rays, sampler);
}

ImportanceSample sensor_sample(const Scene& scene, const Vec3& ref, Sampler& sampler) {
    if (!scene.sensor->area_sensor()) return scene.sensor->sample_direction(ref);  // no random numbers
    Vec2 u = sampler.next_2d();
    return scene.sensor->sample_direction(ref, u, sampler.next_1d());
}

Color connect_to_sensor(const Scene& scene, const PathVertex& y, ImportanceSample& is, ThreadStats& stats,
                        Sampler& sampler) {
    if ((y.type != VType::Surface && y.type != VType::Medium) || !y.connectible()) return Color(0.f);
    is = sensor_sample(scene, y.it.p, sampler);
    if (!is.valid) return Color(0.f);
    Color f;
    int medium = y.medium;
    if (y.type == VType::Medium) {
        // The phase function in place of the BSDF and cosine (Veach 1997
        // sec. 10.2 with the volume path measure; pbrt-v4's
        // LightPathIntegrator connects medium vertices through p).
        f = Color(y.phase->eval(y.it.wi, is.d));
    } else {
        BsdfContext ctx = BsdfContext::at(y.it, TransportMode::Importance);
        f = y.bsdf->eval(ctx, y.it.to_local(y.it.wi), y.it.to_local(is.d)) * shading_correction(y.it, y.it.wi, is.d);
        medium = Scene::medium_after(y.it, is.d, y.medium);
    }
    if (is_black(f)) return Color(0.f);
    Color tr = transmittance_to_sensor(scene, y.it, medium, is, stats, sampler);
    if (is_black(tr)) return Color(0.f);
    return y.beta * f * tr * is.weight;
}

int classify_strategy(const std::vector<PathVertex>& cam, const std::vector<PathVertex>& light, int s, int t) {
    return classify_vertices(cam.data(), t, light.data(), s, true);
}

ClassCode class_code(const PathVertex& v) {
    if (v.type == VType::Medium) return v.enclosed ? kClassSubsurface : kClassVolume;
    if (v.null_surface()) return kClassSkip;
    return v.delta ? kClassDelta : kClassSmooth;
}

namespace {
// The one classification, over any vertex-code accessor: E z1 .. z_{t-1}
// then y_{s-1} .. y1 pushed into a PathClass (a connection end as D).
template <class CamCode, class LightCode>
int classify_with(CamCode cam, int t, LightCode light, int s, bool light_end) {
    PathClass pc;
    int last_cam = s == 0 ? t - 2 : t - 1;
    auto push = [&pc](ClassCode c, bool end) {
        switch (c) {
            case kClassVolume:
                pc.push_medium(false);
                break;
            case kClassSubsurface:
                pc.push_medium(true);
                break;
            case kClassSmooth:
                pc.push(false);
                break;
            case kClassDelta:
                pc.push(!end);
                break;
            case kClassSkip:
                break;
        }
    };
    for (int i = 1; i <= last_cam; ++i) push(cam(i), i == t - 1);
    for (int i = s - 1; i >= 1; --i) push(light(i), light_end && i == s - 1);
    return pc.classify();
}
}  // namespace

int classify_vertices(const PathVertex* cam, int t, const PathVertex* light, int s, bool light_end) {
    return classify_with([cam](int i) { return class_code(cam[i]); }, t,
                         [light](int i) { return class_code(light[i]); }, s, light_end);
}

int classify_codes(const uint8_t* cam, int t, const uint8_t* light, int s, bool light_end) {
    return classify_with([cam](int i) { return ClassCode(cam[i]); }, t, [light](int i) { return ClassCode(light[i]); },
                         s, light_end);
}

Color scatter_value(const PathVertex& v, const Vec3& wo, TransportMode mode) {
    if (v.type == VType::Medium) return Color(v.phase->eval(v.it.wi, wo));
    BsdfContext ctx = BsdfContext::at(v.it, mode);
    Color f = v.bsdf->eval(ctx, v.it.to_local(v.it.wi), v.it.to_local(wo));
    if (mode == TransportMode::Importance) f *= shading_correction(v.it, v.it.wi, wo);
    return f;
}

Color connection_transmittance(const Scene& scene, const PathVertex& z, const DirectSample& ds, Sampler& sampler,
                               ThreadStats& stats) {
    ++stats.shadow_rays;
    if (!scene.features.has_media) return scene.visible(z.it, ds) ? Color(1.f) : Color(0.f);
    int m = z.type == VType::Medium ? z.medium : Scene::medium_after(z.it, ds.d, z.medium);
    return scene.transmittance(z.it, ds, m, stats.rays, sampler);
}

Color connect_emitter_sample(const Scene& scene, const PathVertex& z, float u_pick, Vec2 u_l, float u_extra,
                             Sampler& sampler, ThreadStats& stats, PathVertex& y0) {
    Color L(0.f);
    if (!z.connectible() || (z.type != VType::Surface && z.type != VType::Medium)) return L;
    float pick = 0.f;
    const Emitter* picked = pick_emitter(scene, vertex_light_context(z), u_pick, pick);
    if (!picked) return L;
    const Emitter& e = *picked;
    DirectSample ds = e.sample_direct(z.it.p, u_l, u_extra);
    if (!(ds.pdf_w > 0.f) || is_black(ds.radiance)) return L;
    Color f = scatter_value(z, ds.d, TransportMode::Radiance);
    if (is_black(f)) return L;
    Color tr = connection_transmittance(scene, z, ds, sampler, stats);
    if (is_black(tr)) return L;
    L = z.beta * f * tr * ds.radiance / (ds.pdf_w * pick);
    y0 = PathVertex();
    y0.type = VType::Light;
    y0.emitter = &e;
    if (e.is_infinite()) {
        y0.infinite = true;
        Ray toward;
        toward.o = z.it.p;
        toward.d = ds.d;
        y0.it.p = far_point(scene, toward);
        y0.pdf_fwd = light_origin_pdf(scene, y0, z);
    } else {
        y0.it.p = ds.p;
        y0.it.n = e.is_delta() ? Vec3(0.f) : ds.n;
        float pdf_a = 1.f;
        if (!e.is_delta()) pdf_a = ds.pdf_w * std::fabs(dot(ds.n, ds.d)) / (ds.dist * ds.dist);
        y0.pdf_fwd = pick * pdf_a;
    }
    return L;
}

}  // namespace rm
