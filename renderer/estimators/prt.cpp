// `prt`: precomputed radiance transfer (Sloan, Kautz and Snyder 2002,
// "Precomputed Radiance Transfer for Real-Time Rendering in Dynamic,
// Low-Frequency Lighting Environments"). The distant lighting is projected
// onto real spherical harmonics of `bands` bands (core/sh.h), L_i; each
// pixel keeps a transfer vector T_i per colour channel and effect class,
// and its radiance is the dot product sum_i T_i L_i (Sloan et al., eq. 3
// for the diffuse case), so new lighting needs a new projection and a dot
// product per pixel, not a new render (radiometer.prt.Transfer).
//
// Where the transfer lives: per pixel (the shading points the pixel's
// camera rays reach, averaged over its filter footprint), not per mesh
// vertex as in Sloan et al.: the canonical scenes have analytic shapes
// without vertices, and a per-pixel transfer has no interpolation error,
// so what separates this image from `path`'s is the band limit alone (plus
// noise). The price: the camera is fixed; relighting, not a new view.
//
// The transfer of pixel p and channel c, estimated by Monte Carlo with
// Embree visibility, one camera path per sample (Sloan et al., sec. 5):
//   unshadowed      T_i = E[ f cos / pdf  y_i(w) ]         at the first hit, no ray cast
//   shadowed        the same, counted only when the ray from the hit escapes
//   interreflected  the shadowed term plus the paths of 1 .. `bounces` more
//                   diffuse bounces that then escape (Sloan et al., sec. 5's
//                   interreflected transfer, gathered along paths)
// BSDF samples carry f cos / pdf = the albedo for a diffuse surface (the
// cosine sampling of scene/bsdf.cpp), so the weights are exact. A camera
// ray that escapes files y_i(w) under `emission` (hide_emitters: nothing).
// Only diffuse surfaces: with a glossy or specular BSDF the transfer would
// depend on the view direction, which Sloan et al.'s diffuse transfer
// drops; such a scene is refused by name, as are lights not at infinity.
//
// The error: the dot product is int T(w) L_n(w) dw with L_n the lighting's
// projection on the first n bands, so |prt - exact| <= ||T|| ||L - L_n||
// (Cauchy-Schwarz); docs/prt.md has the bound and the measured error per
// band count. L_n can be negative (ringing); each effect image is clamped
// at 0 and the clamped values are counted (res.stats["clamped_values"]).
//
// Parameters: the registration below.
#include "estimators/prt.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>

#include "core/sh.h"
#include "render/memory.h"
#include "render/pass_loop.h"
#include "render/registry.h"
#include "transport/camera_sample.h"

namespace rm {

void check_distant_lighting(const Scene& scene, const std::string& who) {
    for (const auto& e : scene.emitters)
        if (!e->is_infinite())
            throw std::invalid_argument(who + ": emitter '" + e->id + "' is a local light (area, point or spot); " +
                                        "prt transfers distant lighting only (constant, envmap, directional)");
}

std::vector<Color> project_distant_lighting(const Scene& scene, int bands, int n_theta) {
    const ShBasis basis(bands);
    const int n = basis.count();
    std::vector<double> acc(static_cast<size_t>(n) * 3, 0.0), y(static_cast<size_t>(n));
    SphereQuadrature quad;
    Vec3 centre;
    float radius;
    scene.bounding_sphere(centre, radius);
    for (const auto& e : scene.emitters) {
        if (!e->is_infinite()) continue;
        if (e->is_delta()) {
            // A directional light: radiance E delta(w - d), coefficients E y_i(d).
            DirectSample ds = e->sample_direct(centre, Vec2(0.5f, 0.5f), 0.5f);
            basis.eval(ds.d, y.data());
            for (int i = 0; i < n; ++i)
                for (int c = 0; c < 3; ++c) acc[size_t(3 * i + c)] += double(ds.radiance[c]) * y[size_t(i)];
            continue;
        }
        if (quad.dirs.empty()) quad = sphere_quadrature(n_theta);
        for (size_t k = 0; k < quad.dirs.size(); ++k) {
            Color L = e->eval_environment(quad.dirs[k]);
            if (is_black(L)) continue;
            basis.eval(quad.xyz[3 * k], quad.xyz[3 * k + 1], quad.xyz[3 * k + 2], y.data());
            for (int i = 0; i < n; ++i) {
                double wy = quad.weights[k] * y[size_t(i)];
                for (int c = 0; c < 3; ++c) acc[size_t(3 * i + c)] += double(L[c]) * wy;
            }
        }
    }
    std::vector<Color> out(static_cast<size_t>(n));
    for (int i = 0; i < n; ++i)
        out[size_t(i)] = Color(float(acc[size_t(3 * i)]), float(acc[size_t(3 * i + 1)]), float(acc[size_t(3 * i + 2)]));
    return out;
}

namespace {

enum class Transfer { Unshadowed, Shadowed, Interreflected };
// The effect classes a transfer vector is kept for: a pixel's transfer is
// kPrtEffects x 3 channels x sh_count(bands) floats.
constexpr int kPrtEffects = 3;  // kEmission, kDirect, kIndirect

double seconds_since(std::chrono::steady_clock::time_point t0) {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

class PrtIntegrator final : public Integrator {
public:
    PrtIntegrator(int bands, Transfer transfer, int bounces, int env_samples, bool hide)
        : bands_(bands), transfer_(transfer), bounces_(bounces), env_samples_(env_samples), hide_(hide) {}

    void sample(const Scene&, Sampler&, const Ray&, EffectRadiance&, ThreadStats&) const override {
        throw std::logic_error("integrator '" + type + "' renders through its own driver");
    }

    void check_scene(const Scene& scene) const override {
        const std::string who = "integrator '" + type + "'";
        check_distant_lighting(scene, who);
        for (const auto& s : scene.shapes) {
            if (s->bsdf < 0) continue;
            if (scene.bsdfs[size_t(s->bsdf)]->flags() != kDiffuseReflection)
                throw std::invalid_argument(who + ": shape '" + s->id +
                                            "' has a non-diffuse BSDF (glossy, specular or null); prt's transfer is "
                                            "the diffuse one of Sloan et al. 2002 (use path)");
        }
    }

    RenderOutput drive(const Scene& scene, const RenderOptions& opts, const PollFn& poll) const override;

    class Passes;

private:
    // Vertices a camera path may scatter at before its ray must escape.
    int max_vertices() const { return transfer_ == Transfer::Interreflected ? 1 + bounces_ : 1; }

    // One camera path of `pixel`: adds beta y(w) to the transfer `T` of
    // its class for every escaping ray, and the radiance this makes under
    // the render's own lighting (sum_i y_i(w) L_i per channel) to `value`.
    void camera_path(const Scene& scene, const ShBasis& basis, const std::vector<Color>& light,
                     const FilterSampler& filter, Sampler& sampler, int pixel, float* T, double* value,
                     std::vector<double>& y, ThreadStats& stats) const {
        const int n = basis.count();
        ++stats.paths;
        SensorRay sr = sample_camera_ray(*scene.sensor, filter, pixel, sampler);
        Ray ray = sr.ray;
        Color beta = sr.weight;
        BsdfContext ctx;
        auto escape = [&](int vertices, const Vec3& d) {
            const int cls = vertices == 0 ? kEmission : (vertices == 1 ? kDirect : kIndirect);
            if ((cls == kEmission && hide_) || !mask[cls]) return;
            if (!keep_finite(stats, beta)) return;
            basis.eval(d, y.data());
            float* t = T + size_t(cls) * 3 * size_t(n);
            for (int c = 0; c < 3; ++c) {
                double v = 0.0;
                for (int i = 0; i < n; ++i) {
                    t[c * n + i] += float(beta[c] * y[size_t(i)]);
                    v += y[size_t(i)] * double(light[size_t(i)][c]);
                }
                value[c] += double(beta[c]) * v;
            }
        };
        for (int vertices = 0;; ++vertices) {
            // 1. The next vertex, or the escape into the distant lighting.
            Interaction it;
            ++stats.rays;
            if (!scene.intersect(ray, it)) {
                escape(vertices, ray.d);
                return;
            }
            if (vertices >= max_vertices()) return;
            // 2. A diffuse bounce (check_scene: every BSDF is diffuse), cosine-sampled.
            const Bsdf& bsdf = *scene.bsdfs[size_t(scene.shapes[size_t(it.shape)]->bsdf)];
            ctx.set(it);
            BsdfSample bs = bsdf.sample(ctx, it.to_local(it.wi), sampler.next_1d(), sampler.next_2d());
            if (!(bs.pdf_w > 0.f) || is_black(bs.weight)) return;
            beta *= bs.weight;
            ray = it.spawn(it.to_world(bs.wo));
            // 3. Unshadowed transfer: the direction counts without a ray cast.
            if (transfer_ == Transfer::Unshadowed) {
                escape(1, ray.d);
                return;
            }
        }
    }

    int bands_;
    Transfer transfer_;
    int bounces_, env_samples_;
    bool hide_;
};

// The precomputation on the pass loop: one sweep over the pixels per
// sample, each pixel's transfer summed by the one work item that owns its
// row, in sample order (the same bytes whatever the thread count).
class PrtIntegrator::Passes final : public PassStep {
public:
    Passes(const PrtIntegrator& p, const Scene& scene, std::vector<Color> light, double project_seconds)
        : p_(p),
          scene_(scene),
          basis_(p.bands_),
          light_(std::move(light)),
          filter_(scene.sensor_desc.rfilter, scene.sensor_desc.filter_radius, scene.sensor_desc.filter_stddev),
          project_seconds_(project_seconds) {
        const Sensor& s = *scene.sensor;
        W_ = s.width, H_ = s.height, cx_ = s.crop_x, cy_ = s.crop_y, cw_ = s.crop_w, ch_ = s.crop_h;
        n_ = basis_.count();
        const size_t px = size_t(cw_) * size_t(ch_);
        T_.assign(px * kPrtEffects * 3 * size_t(n_), 0.f);
        sum_.assign(px * 3, 0.0);
        sq_.assign(px * 3, 0.0);
    }

    static double bytes_per_pixel(int bands) { return 4.0 * kPrtEffects * 3 * sh_count(bands) + 2 * 3 * 8.0; }

    int pass(PassLoop& loop, int s0, int s1) override {
        auto t0 = std::chrono::steady_clock::now();
        int done = s1;
        for (int s = s0; s < s1; ++s) {
            if (s > s0 && !loop.poll_once()()) {
                done = s;
                break;
            }
            // Never cancelled within a sweep: a pixel holds whole samples only.
            loop.parallel_commit(size_t(ch_), [&](size_t row, int t) {
                std::vector<double> y(static_cast<size_t>(n_));
                ThreadStats& st = loop.stats(t);
                for (int x = 0; x < cw_; ++x) {
                    const size_t q = row * size_t(cw_) + size_t(x);
                    const int pixel = (cy_ + int(row)) * W_ + cx_ + x;
                    Sampler sampler(loop.seed(), uint64_t(pixel), uint64_t(s));
                    double v[3] = {0.0, 0.0, 0.0};
                    p_.camera_path(scene_, basis_, light_, filter_, sampler, pixel,
                                   &T_[q * kPrtEffects * 3 * size_t(n_)], v, y, st);
                    for (int c = 0; c < 3; ++c) sum_[3 * q + c] += v[c], sq_[3 * q + c] += v[c] * v[c];
                }
                loop.add_done(uint64_t(cw_));
            });
        }
        precompute_seconds_ += seconds_since(t0);
        return done;
    }

    void develop(int n, std::vector<float>& image, std::vector<float>& variance,
                 std::vector<std::vector<float>>* effects) const override {
        auto t0 = std::chrono::steady_clock::now();
        const size_t film = size_t(W_) * size_t(H_);
        image.assign(3 * film, 0.f);
        variance.assign(3 * film, std::numeric_limits<float>::quiet_NaN());
        if (effects) effects->assign(kNumEffects, std::vector<float>(3 * film, 0.f));
        clamped_ = 0;
        if (n <= 0) return;
        for (int yy = 0; yy < ch_; ++yy)
            for (int x = 0; x < cw_; ++x) {
                const size_t q = size_t(yy) * size_t(cw_) + size_t(x);
                const size_t f = size_t(cy_ + yy) * size_t(W_) + size_t(cx_ + x);
                const float* t = &T_[q * kPrtEffects * 3 * size_t(n_)];
                for (int c = 0; c < 3; ++c) {
                    float total = 0.f;
                    for (int e = 0; e < kPrtEffects; ++e) {
                        // Relighting: the dot product of transfer and lighting.
                        double v = 0.0;
                        for (int i = 0; i < n_; ++i)
                            v += double(t[(e * 3 + c) * n_ + i]) * double(light_[size_t(i)][c]);
                        float ve = float(v / n);
                        if (ve < 0.f) ve = 0.f, ++clamped_;
                        total += ve;
                        if (effects) (*effects)[size_t(e)][3 * f + c] = ve;
                    }
                    image[3 * f + c] = total;
                    if (n > 1) {
                        double mean = sum_[3 * q + c] / n;
                        double var = std::max(0.0, (sq_[3 * q + c] - n * mean * mean) / (n - 1.0));
                        variance[3 * f + c] = float(var / n);
                    }
                }
            }
        relight_seconds_ = seconds_since(t0);
    }

    void finish(RenderOutput& out) const override {
        const int spp = out.spp;
        // The transfer of the spp samples kept, (h, w, effect, channel, coefficient).
        OutputArray tr;
        tr.name = "prt_transfer";
        tr.shape = {ch_, cw_, kPrtEffects, 3, n_};
        tr.data.resize(T_.size());
        const float inv = spp > 0 ? 1.f / float(spp) : 0.f;
        for (size_t k = 0; k < T_.size(); ++k) tr.data[k] = T_[k] * inv;
        OutputArray li;
        li.name = "prt_light";
        li.shape = {n_, 3};
        for (const Color& c : light_) li.data.insert(li.data.end(), {c.x, c.y, c.z});
        out.arrays.push_back(std::move(tr));
        out.arrays.push_back(std::move(li));
        out.estimator_stats = {
            {"bands", {double(p_.bands_)}},
            {"coefficients", {double(n_)}},
            {"bounces", {double(p_.transfer_ == Transfer::Interreflected ? p_.bounces_ : 0)}},
            {"env_samples", {double(p_.env_samples_)}},
            {"projection_seconds", {project_seconds_}},
            {"precompute_seconds", {precompute_seconds_}},
            {"relight_seconds", {relight_seconds_}},
            {"transfer_bytes", {double(T_.size() * sizeof(float))}},
            {"clamped_values", {double(clamped_)}},
        };
    }

private:
    const PrtIntegrator& p_;
    const Scene& scene_;
    ShBasis basis_;
    std::vector<Color> light_;
    FilterSampler filter_;
    int W_ = 0, H_ = 0, cx_ = 0, cy_ = 0, cw_ = 0, ch_ = 0, n_ = 0;
    std::vector<float> T_;          // [crop pixel][effect][channel][coefficient], sums over samples
    std::vector<double> sum_, sq_;  // per crop pixel and channel: the render's own radiance, summed and squared
    double project_seconds_ = 0, precompute_seconds_ = 0;
    mutable double relight_seconds_ = 0;
    mutable uint64_t clamped_ = 0;
};

RenderOutput PrtIntegrator::drive(const Scene& scene, const RenderOptions& opts, const PollFn& poll) const {
    const Sensor& s = *scene.sensor;
    check_memory(type, s.width, s.height,
                 {{"transfer vectors (" + std::to_string(sh_count(bands_)) + " coefficients x 3 channels x 3 effects)",
                   double(s.crop_w) * double(s.crop_h) * Passes::bytes_per_pixel(bands_), "bands or the resolution"},
                  output_memory(opts, s.width, s.height)});
    check_scene(scene);
    auto t0 = std::chrono::steady_clock::now();
    std::vector<Color> light = project_distant_lighting(scene, bands_, env_samples_);
    double project_seconds = seconds_since(t0);
    PassLoop loop(scene, opts, poll);
    loop.set_pixels(uint64_t(s.crop_w) * uint64_t(s.crop_h));
    Passes passes(*this, scene, std::move(light), project_seconds);
    return loop.run(passes);
}

[[maybe_unused]] const bool kRegistered = register_estimator([] {
    EstimatorInfo e;
    e.name = "prt";
    e.doc =
        "precomputed radiance transfer (Sloan, Kautz and Snyder 2002): per-pixel diffuse transfer vectors in "
        "spherical harmonics, relit by a dot product; distant lighting and diffuse surfaces only";
    e.params = {
        ParamSpec::integer("bands", 3, "spherical-harmonic bands l = 0 .. bands - 1 (bands^2 coefficients)")
            .at_least(1)
            .at_most(16),
        ParamSpec::string("transfer", "interreflected",
                          "'unshadowed' (cosine only), 'shadowed' (visibility too) or 'interreflected' "
                          "(plus `bounces` diffuse bounces)")
            .one_of({"unshadowed", "shadowed", "interreflected"}),
        ParamSpec::integer("bounces", 1, "interreflected transfer: diffuse bounces after the first vertex")
            .at_least(0)
            .at_most(64),
        ParamSpec::integer("env_samples", 64,
                           "Gauss-Legendre nodes in cos theta (times 2 in phi) projecting an environment onto SH; "
                           "at least `bands` are used")
            .at_least(1)
            .at_most(4096),
        hide_emitters_param(),
    };
    e.caps.driver = Driver::OwnPasses;
    // The band limit is an error more samples do not remove.
    e.caps.bias = Bias::Biased;
    e.caps.effects = effect_mask({kEmission, kDirect, kIndirect});
    e.factory = [](ParamReader& p) -> std::unique_ptr<Integrator> {
        int bands = p.get_int("bands");
        std::string t = p.get_string("transfer");
        Transfer tr = t == "unshadowed" ? Transfer::Unshadowed
                                        : (t == "shadowed" ? Transfer::Shadowed : Transfer::Interreflected);
        int bounces = p.get_int("bounces");
        // The quadrature is exact for bands < its node count: at least `bands` nodes.
        int env_samples = std::max(p.get_int("env_samples"), bands);
        return std::make_unique<PrtIntegrator>(bands, tr, bounces, env_samples, p.get_bool("hide_emitters"));
    };
    return e;
}());

}  // namespace

}  // namespace rm
