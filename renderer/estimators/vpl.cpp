// `vpl`: instant radiosity (Keller 1997, "Instant Radiosity"): each pass
// traces vpl_count light paths whose non-specular vertices become virtual
// point lights, and every camera sample's gather points sum all of them;
// direct light by next event estimation (vpl_internal.h has the pass and
// the effect classes; docs/vpl.md the measurements).
//
// Clamping: the contribution's distance is clamped from below as Mitsuba
// 0.6's vpl does (vpl_internal.h), which removes the VPLs' bright spots
// near corners and darkens them: a bias towards less light. `compensate`
// adds it back (Kollig and Keller 2004, "Illumination in the Presence of
// Weak Singularities"; the structure of pbrt-v2's IGIIntegrator::Li, whose
// code is not ours): at each gather point x one direction w is drawn from
// x's smooth lobes and traced to the first hit y'; the clamp took the
// fraction r = max(0, 1 - d^2 / d_min(y')^2) of the light y' sends to x,
// and that fraction of an estimate of y''s reflected radiance towards x --
// its direct light (one light sample), its VPL sum (clamped again) and, in
// turn, its own compensation -- is added with the weight f cos / pdf of w.
// Emission at y' is not counted (x's direct light has it). The expectation
// is then the unclamped VPL estimate's, where y' reflects through a smooth
// lobe; light that reaches y' only through delta vertices (a caustic on
// y') is not compensated.
//
// Bias: each pass's VPLs are fresh, so the passes are independent and the
// unclamped estimator (clamping 0), or the compensated one, is unbiased for
// the classes it renders; with clamping > 0 and no compensation (the
// default, Mitsuba's) it is biased: declared Bias::Biased.
#include <algorithm>
#include <chrono>
#include <climits>
#include <cmath>
#include <limits>

#include "core/warp.h"
#include "estimators/vpl_internal.h"
#include "render/memory.h"
#include "transport/camera_sample.h"
#include "transport/subpath_walk.h"

namespace rm {

using Clock = std::chrono::steady_clock;

// ---- shared with rowcolumn (vpl_internal.h) -------------------------------

std::vector<ParamSpec> vpl_shared_params() {
    return {
        ParamSpec::integer("vpl_count", 32, "light paths traced per pass; their non-specular vertices are the VPLs")
            .at_least(1)
            .at_most(1 << 22)
            .alias("vplCount"),
        ParamSpec::real("clamping", 0.1,
                        "relative clamping distance (Mitsuba 0.6's vpl): d_min = near + clamping (far - near) of "
                        "each VPL's hemisphere; 0: none")
            .at_least(0)
            .at_most(1),
        max_depth_param().alias("maxDepth"),
        rr_depth_param().alias("rrDepth"),
        hide_emitters_param().alias("hideEmitters"),
    };
}

VplConfig read_vpl_config(ParamReader& p) {
    VplConfig c;
    c.vpl_count = p.get_int("vpl_count");
    c.clamping = p.get_float("clamping");
    c.max_depth = p.get_int("max_depth");
    c.rr_depth = p.get_int("rr_depth");
    c.hide = p.get_bool("hide_emitters");
    return c;
}

VplEngine::VplEngine(const Scene& scene, const VplConfig& cfg, const EffectMask& mask, const std::string& name)
    : scene_(scene),
      cfg_(cfg),
      mask_(mask),
      filter_(scene.sensor_desc.rfilter, scene.sensor_desc.filter_radius, scene.sensor_desc.filter_stddev) {
    needs_ = !scene.emitters.empty() && scene.features.has_smooth_bsdf && (mask[kIndirect] || mask[kSpecular]) &&
             (cfg.max_depth < 0 || cfg.max_depth >= 3);
    stats_out.name = "vpl";
    stats_out.bytes_per_photon = double(sizeof(Vpl));
}

float VplEngine::clamp_distance2(const Interaction& it, bool back, ThreadStats& stats) const {
    if (!(cfg_.clamping > 0.f)) return 0.f;
    const Vec3 n = back ? -it.n : it.n;
    const Frame frame(n);
    float near_d = kInf, far_d = -kInf;
    for (int k = 0; k < kClampRays; ++k) {
        // Hammersley point k: ((k + 1/2) / K, radical inverse of k in base 2).
        uint32_t b = uint32_t(k);
        b = (b << 16) | (b >> 16);
        b = ((b & 0x55555555u) << 1) | ((b & 0xAAAAAAAAu) >> 1);
        b = ((b & 0x33333333u) << 2) | ((b & 0xCCCCCCCCu) >> 2);
        b = ((b & 0x0F0F0F0Fu) << 4) | ((b & 0xF0F0F0F0u) >> 4);
        b = ((b & 0x00FF00FFu) << 8) | ((b & 0xFF00FF00u) >> 8);
        Vec2 u((float(k) + 0.5f) / float(kClampRays), float(b) * 2.3283064365386963e-10f);
        Ray ray = it.spawn(frame.to_world(warp::square_to_cosine_hemisphere(u)));
        Interaction hit;
        ++stats.rays;
        if (scene_.intersect(ray, hit)) {
            near_d = std::min(near_d, hit.t);
            far_d = std::max(far_d, hit.t);
        }
    }
    if (!(far_d >= near_d)) return 0.f;  // nothing around (an open scene): no clamping, as Mitsuba
    float d = near_d + cfg_.clamping * (far_d - near_d);
    return d * d;
}

bool VplEngine::trace(PassLoop& loop, int pass, std::vector<Vpl>& out) {
    out.clear();
    if (!needs_) return true;
    auto t0 = Clock::now();
    constexpr size_t kItem = 64;  // light paths per work item
    const size_t n = size_t(cfg_.vpl_count);
    const size_t items = (n + kItem - 1) / kItem;
    std::vector<std::vector<Vpl>> per(items);
    // y_0 .. y_{max_depth - 2}: a VPL y_i lights x at >= 1 segment from the camera.
    const int max_vertices = cfg_.max_depth < 0 ? INT_MAX : cfg_.max_depth - 1;
    const float inv_n = 1.f / float(n);
    auto item = [&](size_t i, int th) {
        ThreadStats& stats = loop.stats(th);
        std::vector<PathVertex> light;
        std::vector<Vpl>& dst = per[i];
        auto deposit = [&](const std::vector<PathVertex>& p) {
            const size_t k = p.size() - 1;
            const PathVertex& y = p[k];
            if (k >= 1 && y.type == VType::Surface && y.bsdf->has_smooth() && !is_black(y.beta)) {
                Vpl v;
                v.v = y;
                v.v.beta = y.beta * inv_n;
                v.depth = int(k);
                const bool front = dot(y.it.wi, y.it.n) >= 0.f;
                const bool transmits = (y.bsdf->flags() & (kDiffuseTransmission | kGlossyTransmission)) != 0;
                float own = clamp_distance2(y.it, !front, stats);
                v.dmin2[front ? 0 : 1] = own;
                v.dmin2[front ? 1 : 0] = transmits ? clamp_distance2(y.it, front, stats) : own;
                dst.push_back(v);
            }
            return true;
        };
        const VertexVisitor visit(deposit);
        EmissionSample es;
        for (size_t g = i * kItem; g < std::min(n, (i + 1) * kItem); ++g) {
            if (loop.cancelled()) return;
            Sampler sampler = vpl_light_sampler(loop.seed(), g, pass);
            light_subpath(scene_, sampler, max_vertices, cfg_.rr_depth, light, es, stats, &visit, false);
        }
    };
    if (!loop.parallel_for(items, item)) return false;
    for (auto& v : per) out.insert(out.end(), v.begin(), v.end());
    stats_out.photons += out.size();
    stats_out.paths += n;
    stats_out.trace_seconds += std::chrono::duration<double>(Clock::now() - t0).count();
    return true;
}

int VplEngine::camera_sample(Sampler& sampler, int pixel, EffectRadiance& er, GatherPoint* gp,
                             ThreadStats& stats) const {
    SensorRay sr = sample_camera_ray(*scene_.sensor, filter_, pixel, sampler);
    ++stats.paths;
    int n = 0;
    const int md = cfg_.max_depth;
    walk_specular_chain(scene_, sampler, sr.ray, SpecularChain{md, cfg_.rr_depth, cfg_.hide}, mask_, er, stats,
                        [&](const Interaction& it, const Bsdf& bsdf, const Vec3& wi, const Color& beta,
                            const PathClass& pc, int depth) {
                            if (!bsdf.has_smooth()) return true;
                            const bool via_specular = pc.scatter_vertices > 0;
                            const int cls_d = via_specular ? kSpecular : kDirect;
                            // Direct light by one light sample (no MIS partner: bsdf fraction 0).
                            if (mask_[cls_d])
                                er.add(cls_d, beta * estimate_direct(scene_, it, bsdf, wi, sampler, stats, 1.f, 0.f));
                            else  // the same random numbers whatever the mask (a light sample draws 4)
                                sampler.next_1d(), sampler.next_2d(), sampler.next_1d();
                            const int cls = via_specular ? kSpecular : kIndirect;
                            if (needs_ && mask_[cls] && n < kMaxGather && (md < 0 || depth + 3 <= md)) {
                                GatherPoint& g = gp[n++];
                                g.v = PathVertex();
                                g.v.type = VType::Surface;
                                g.v.it = it;
                                g.v.bsdf = &bsdf;
                                g.v.beta = beta * sr.weight;
                                g.depth = depth + 1;
                                g.cls = cls;
                            }
                            return true;
                        });
    for (Color& c : er.by_effect) c *= sr.weight;
    return n;
}

Color VplEngine::contribution(const PathVertex& x, int depth, const Vpl& y, ThreadStats& stats) const {
    if (cfg_.max_depth >= 0 && depth + 1 + y.depth > cfg_.max_depth) return Color(0.f);
    Vec3 d = y.v.it.p - x.it.p;
    const float d2 = length_sq(d);
    if (!(d2 > 0.f)) return Color(0.f);
    const float dist = std::sqrt(d2);
    d = d / dist;
    const Color fx = scatter_value(x, d, TransportMode::Radiance);
    if (is_black(fx)) return Color(0.f);
    const Color fy = scatter_value(y.v, -d, TransportMode::Importance);
    if (is_black(fy)) return Color(0.f);
    DirectSample ds;
    ds.p = y.v.it.p;
    ds.n = y.v.it.n;
    ds.eps = y.v.it.eps;
    ds.d = d;
    ds.dist = dist;
    ++stats.shadow_rays;
    if (!scene_.visible(x.it, ds)) return Color(0.f);
    const float den = std::max(d2, y.dmin2[dot(d, y.v.it.n) > 0.f ? 1 : 0]);  // x on the side of -d
    return fx * fy * y.v.beta / den;
}

Color VplEngine::gather(const PathVertex& x, int depth, const std::vector<Vpl>& vpls, ThreadStats& stats) const {
    Color sum(0.f);
    for (const Vpl& y : vpls) sum += contribution(x, depth, y, stats);
    return sum;
}

// ---- vpl ------------------------------------------------------------------

namespace {

std::unique_ptr<Integrator> make_vpl(ParamReader& p);

[[maybe_unused]] const bool kRegistered = register_estimator([] {
    EstimatorInfo e;
    e.name = "vpl";
    e.doc =
        "instant radiosity: each pass's light paths leave virtual point lights that every camera sample gathers "
        "(Keller 1997); clamping as Mitsuba 0.6, optional bias compensation (Kollig & Keller 2004)";
    e.params = vpl_shared_params();
    e.params.push_back(ParamSpec::mitsuba_ignored("shadowMapResolution",
                                                  "Mitsuba 0.6's shadow maps: changes nothing here (shadow rays)"));
    e.params.push_back(ParamSpec::boolean(
        "compensate", false, "add back what clamping removes: one gather ray per gather point (Kollig & Keller 2004)"));
    e.caps.driver = Driver::OwnPasses;
    e.caps.bias = Bias::Biased;                          // the default clamping, uncompensated
    e.caps.effects = effect_mask({kEmission, kDirect});  // indirect misses L .. D S+ D E
    e.factory = make_vpl;
    return e;
}());

constexpr int kMaxCompensation = 64;  // levels of the compensation's recursion

class VplIntegrator final : public Integrator {
public:
    explicit VplIntegrator(ParamReader& p) : cfg_(read_vpl_config(p)), compensate_(p.get_bool("compensate")) {}
    void sample(const Scene&, Sampler&, const Ray&, EffectRadiance&, ThreadStats&) const override {
        throw std::logic_error("integrator 'vpl' renders through its own driver");
    }
    RenderOutput drive(const Scene& scene, const RenderOptions& opts, const PollFn& poll) const override;

    // The compensation at gather point g (before its beta): see the top of the file.
    Color compensation(const VplEngine& eng, const GatherPoint& g, const std::vector<Vpl>& vpls, Sampler& sampler,
                       ThreadStats& stats) const {
        const Scene& scene = eng.scene();
        const int md = cfg_.max_depth;
        Color total(0.f), thr(1.f);
        PathVertex x = g.v;
        int depth = g.depth;
        BsdfContext ctx;
        for (int level = 0; level < kMaxCompensation; ++level) {
            ctx.set(x.it);
            BsdfSample bs = x.bsdf->sample(ctx, x.it.to_local(x.it.wi), sampler.next_1d(), sampler.next_2d());
            if (!(bs.pdf_w > 0.f) || is_black(bs.weight) || bs.is_delta) break;
            Ray ray = x.it.spawn(x.it.to_world(bs.wo));
            Interaction it;
            ++stats.rays;
            if (!scene.intersect(ray, it)) break;
            const Bsdf& b = *scene.bsdfs[scene.shapes[it.shape]->bsdf];
            if (!b.has_smooth()) break;
            const float t2 = length_sq(it.p - x.it.p);
            const float dm2 = eng.clamp_distance2(it, dot(x.it.p - it.p, it.n) < 0.f, stats);
            const float r = dm2 > t2 ? 1.f - t2 / dm2 : 0.f;
            if (!(r > 0.f)) break;
            thr *= bs.weight * r;
            PathVertex y;
            y.type = VType::Surface;
            y.it = it;
            y.bsdf = &b;
            const int yd = depth + 1;
            // y''s direct light (paths of yd + 1 segments; no emission of y').
            if (md < 0 || yd + 1 <= md)
                total += thr * estimate_direct(scene, it, b, it.to_local(it.wi), sampler, stats, 1.f, 0.f);
            total += thr * eng.gather(y, yd, vpls, stats);
            if (md >= 0 && yd + 2 > md) break;  // the next level's direct light needs yd + 2 segments
            if (!survives_roulette(RouletteRule::Capped, level + 1, cfg_.rr_depth, max_component(thr),
                                   sampler.next_1d(), thr))
                break;
            x = y;
            depth = yd;
        }
        return total;
    }

    VplConfig cfg_;
    bool compensate_;
};

class VplPasses final : public PassStep {
public:
    VplPasses(const VplIntegrator& v, const Scene& scene)
        : v_(v),
          scene_(scene),
          eng_(scene, v.cfg_, v.mask, v.type),
          sums_(size_t(scene.sensor->width) * size_t(scene.sensor->height)) {}

    int pass(PassLoop& loop, int s0, int s1) override {
        for (int s = s0; s < s1; ++s) {
            if (!eng_.trace(loop, s, vpls_)) return s;
            sums_.clear_pass();
            const int W = scene_.sensor->width;
            auto row = [&](size_t y, int th) {
                ThreadStats& stats = loop.stats(th);
                GatherPoint gp[kMaxGather];
                for (int x = 0; x < W; ++x) {
                    if (loop.cancelled()) return;
                    const size_t p = y * size_t(W) + size_t(x);
                    Sampler sampler(loop.seed(), p, uint64_t(s));
                    EffectRadiance er;
                    const int n = eng_.camera_sample(sampler, int(p), er, gp, stats);
                    for (int k = 0; k < n; ++k) {
                        Color L = eng_.gather(gp[k].v, gp[k].depth, vpls_, stats);
                        if (v_.compensate_) L += v_.compensation(eng_, gp[k], vpls_, sampler, stats);
                        er.add(gp[k].cls, gp[k].v.beta * L);
                    }
                    if (!keep_finite(stats, er.total())) continue;
                    sums_.set(p, er);
                }
                loop.add_done(uint64_t(W));
            };
            if (!loop.parallel_for(size_t(scene_.sensor->height), row)) return s;
            sums_.commit();
        }
        return s1;
    }
    void develop(int n, std::vector<float>& image, std::vector<float>& variance,
                 std::vector<std::vector<float>>* effects) const override {
        sums_.develop(n, image, variance, effects);
    }
    void finish(RenderOutput& out) const override {
        if (eng_.needs_vpls()) out.photon_maps.push_back(eng_.stats_out);
    }

private:
    const VplIntegrator& v_;
    const Scene& scene_;
    VplEngine eng_;
    PassSums sums_;
    std::vector<Vpl> vpls_;
};

RenderOutput VplIntegrator::drive(const Scene& scene, const RenderOptions& opts, const PollFn& poll) const {
    const int W = scene.sensor->width, H = scene.sensor->height;
    const double px = double(W) * double(H);
    // VPLs: up to one per light-path vertex; 4 per path budgeted.
    check_memory(type, W, H,
                 {{"per-pixel sums", px * 8.0 * (2.0 * kNumEffects * 3 + 6), "the resolution (film width, height)"},
                  {"VPLs", 4.0 * double(cfg_.vpl_count) * double(sizeof(Vpl)), "vpl_count"},
                  output_memory(opts, W, H)});
    PassLoop loop(scene, opts, poll);
    VplPasses passes(*this, scene);
    return loop.run(passes);
}

std::unique_ptr<Integrator> make_vpl(ParamReader& p) { return std::make_unique<VplIntegrator>(p); }

}  // namespace

}  // namespace rm
