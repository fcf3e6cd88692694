// `sppm`: stochastic progressive photon mapping (Hachisuka & Jensen 2009,
// "Stochastic Progressive Photon Mapping"; the radius reduction of Hachisuka,
// Ogaki & Jensen 2008, "Progressive Photon Mapping"). Each pass (one sample
// per pixel):
//   1. a camera ray per pixel (filter importance sampled, as render.cpp does)
//      follows specular vertices to its first non-specular vertex x, the
//      pass's visible point; emission on the way and direct light at x
//      (one light sample, next event estimation) are added as in `path`;
//   2. photon_count light paths leave photons at their non-specular vertices
//      after the first (direct light came from step 1) -- photon_trace.h;
//   3. each pixel gathers the M photons within its radius r of x, Phi =
//      beta sum f_r Phi_p, and updates its statistics (H&J 2009, eqs. 6-8;
//      HOJ 2008, eqs. 6, 7 and 11):
//        N' = N + alpha M,   r'^2 = r^2 (N + alpha M) / (N + M),
//        tau' = (tau + Phi) (N + alpha M) / (N + M);
//   the pixel's photon-mapped radiance after i passes of n photon paths is
//   tau / (pi r^2 i n) (H&J 2009, eq. 10): consistent, bias and variance both
//   vanish as the passes grow, for 0 < alpha < 1.
// Determinism: pixel p's camera sample of pass s draws on Sampler(seed, p, s)
// and photon path g of pass s on its own stream (photon_trace.h); each
// pixel's gather sums in the photon map's fixed order.
// Variance (res.variance): the sample variance over passes of each pass's
// own estimate (direct part + Phi / (pi r_i^2 n)) divided by the pass
// count, i.e. the passes treated as independent estimates as Knaus & Zwicker
// 2011 ("Progressive Photon Mapping: A Probabilistic Approach") do; it does
// not see the bias.
// Effect classes: emission and direct as in `path`; photons whose light path
// was specular-only before x are `caustic`, the others `indirect`; all of x's
// light is `specular` when the camera reached x through a specular vertex.
// Limits: the visible point is the first non-specular vertex, so the
// specular lobe of a mixed BSDF (plastic's coat) there is not followed
// (pbrt-v3's SPPM shares this); glossy visible points gather photons like
// diffuse ones (their sharp highlights converge slowly).
//
// Parameters (Mitsuba 0.6's sppm names in snake_case):
//   photon_count    light paths traced per pass (photonCount, 250000)
//   initial_radius  initial gather radius in world units; 0 = automatic:
//                   1/100 of the scene's bounding-sphere radius (initialRadius)
//   alpha           radius reduction, 0 < alpha < 1 (alpha, 0.7)
//   max_depth, rr_depth, hide_emitters   as in `path`
//   (granularity is accepted and ignored.) The pass count is the spp.
#include <chrono>
#include <limits>
#include <stdexcept>
#include <thread>

#include "transport/common.h"
#include "render/parallel.h"
#include "render/render.h"
#include "transport/photon_trace.h"

namespace rm {

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

// The photon-mapped classes a pixel's tau is split into.
constexpr int kTauClasses[3] = {kCaustic, kIndirect, kSpecular};

struct VisiblePoint {
    Interaction it;
    const Bsdf* bsdf = nullptr;  // null: no visible point this pass
    Vec3 wi;                     // local
    Color beta{0.f};
    EffectRadiance er;           // the pass's ray-traced part (emission, direct)
    bool via_specular = false;
    int c = 0;                   // camera segments to x
};

struct PixelStats {
    double r2 = 0, n = 0;
    double tau[3][3] = {};    // [class][channel]
    double ray[kNumEffects][3] = {};  // sums of the ray-traced parts over passes
    double sum[3] = {}, sum_sq[3] = {};  // per-pass total estimates
};

}  // namespace

class Sppm final : public Integrator {
public:
    explicit Sppm(const IntegratorDesc& d)
        : max_depth_(d.max_depth), rr_depth_(d.rr_depth), hide_(d.hide_emitters), photon_count_(d.photon_count),
          initial_radius_(d.initial_radius), alpha_(d.alpha) {
        if (photon_count_ < 1) throw std::invalid_argument("integrator 'sppm': photon_count must be >= 1");
        if (!(initial_radius_ >= 0.f) || !std::isfinite(initial_radius_))
            throw std::invalid_argument("integrator 'sppm': initial_radius must be >= 0 (0 = automatic)");
        if (!(alpha_ > 0.f && alpha_ < 1.f))
            throw std::invalid_argument("integrator 'sppm': alpha must lie in (0, 1)");
    }
    bool owns_driver() const override { return true; }
    void sample(const Scene&, Sampler&, const Ray&, EffectRadiance&, ThreadStats&) const override {
        throw std::logic_error("integrator 'sppm' renders through its own driver");
    }
    RenderOutput drive(const Scene& scene, const RenderOptions& opts, const PollFn& poll) const override;

private:
    // Step 1: the camera path to its visible point; emission and direct light
    // along the way go to `out`.
    void camera_path(const Scene& scene, Sampler& sampler, Ray ray, EffectRadiance& out, VisiblePoint& vp,
                     ThreadStats& stats) const {
        Color beta(1.f);
        PathClass pc;
        BsdfContext ctx;
        for (int depth = 0;; ++depth) {
            Interaction it;
            int cls = pc.classify();
            if (!trace_counting_emission(scene, ray, it, beta, cls, !(depth == 0 && hide_) && mask[cls], out, stats))
                return;
            const Shape& shape = *scene.shapes[it.shape];
            if (max_depth_ >= 0 && depth + 1 >= max_depth_) return;
            const Bsdf& bsdf = *scene.bsdfs[shape.bsdf];
            Vec3 wi = it.to_local(it.wi);
            bool via_specular = pc.scatter_vertices > 0;
            if (bsdf.has_smooth()) {
                // Direct light by one light sample (no MIS partner: bsdf_frac 0).
                int cls_d = via_specular ? kSpecular : kDirect;
                if (mask[cls_d] && !scene.emitters.empty())
                    out.add(cls_d, beta * estimate_direct(scene, it, bsdf, wi, sampler, stats, 1.f, 0.f));
                vp.it = it;
                vp.bsdf = &bsdf;
                vp.wi = wi;
                vp.beta = beta;
                vp.via_specular = via_specular;
                vp.c = depth + 1;
                return;
            }
            BsdfSample bs = bsdf.sample(ctx, wi, sampler.next_1d(), sampler.next_2d());
            if (!(bs.pdf_w > 0.f) || is_black(bs.weight)) return;
            beta *= bs.weight;
            if (bsdf.flags() != kNull) pc.push(true);
            ray = it.spawn(it.to_world(bs.wo));
            if (!survives_roulette(RouletteRule::Capped, depth + 1, rr_depth_, max_component(beta), sampler.next_1d(),
                                   beta))
                return;
        }
    }

    int max_depth_, rr_depth_;
    bool hide_;
    int photon_count_;
    float initial_radius_, alpha_;
};

RenderOutput Sppm::drive(const Scene& scene, const RenderOptions& opts, const PollFn& poll) const {
    auto t0 = Clock::now();
    const Sensor& sensor = *scene.sensor;
    const SensorDesc& sd = scene.sensor_desc;
    const int W = sensor.width, H = sensor.height;
    const size_t pixels = size_t(W) * size_t(H);
    int threads = render_threads(opts);
    FilterSampler filter(sd.rfilter, sd.filter_radius, sd.filter_stddev);
    Vec3 center;
    float radius;
    scene.bounding_sphere(center, radius);
    const double r0 = initial_radius_ > 0.f ? initial_radius_ : 0.01 * radius;
    std::vector<PixelStats> px(pixels);
    for (auto& p : px) p.r2 = r0 * r0;
    std::vector<VisiblePoint> vps(pixels);
    // Photons are needed when a photon-mapped class can appear at all.
    const SceneFeatures& f = scene.features;
    bool photons_needed = !scene.emitters.empty() && f.has_smooth_bsdf && (max_depth_ < 0 || max_depth_ >= 3) &&
                          (mask[kIndirect] || (f.has_delta_bsdf && (mask[kCaustic] || mask[kSpecular])));
    PhotonTraceSpec spec;
    spec.max_depth = max_depth_ < 0 ? -1 : max_depth_ - 1;
    spec.rr_depth = rr_depth_;
    spec.store_direct = false;
    spec.stream = 3;

    RenderOutput out;
    out.width = W;
    out.height = H;
    out.threads = threads;
    PhotonMapStats pms;
    pms.name = "sppm";
    pms.bytes_per_photon = double(PhotonMap::bytes_per_photon());
    std::atomic<bool> cancel{false};
    const uint64_t total = opts.seconds > 0 ? 0 : uint64_t(pixels) * uint64_t(opts.spp);
    std::atomic<uint64_t> done{0};
    std::function<bool()> poll_once = [&] { return !poll || poll(done.load(), total); };
    std::vector<ThreadStats> tstats(static_cast<size_t>(threads));
    ThreadStats pstats;
    int passes = 0;
    double sec_per_pass = 0;
    std::vector<int> cps = checkpoint_plan(opts);

    // The estimate after `n` passes (H&J 2009, eq. 10 plus the ray-traced part).
    auto develop = [&](int n, std::vector<float>& image, std::vector<float>& variance,
                       std::vector<std::vector<float>>* effects) {
        image.assign(3 * pixels, 0.f);
        variance.assign(3 * pixels, std::numeric_limits<float>::quiet_NaN());
        if (effects) effects->assign(kNumEffects, std::vector<float>(3 * pixels, 0.f));
        if (n <= 0) return;
        for (size_t p = 0; p < pixels; ++p) {
            const PixelStats& s = px[p];
            double e[kNumEffects][3];
            for (int k = 0; k < kNumEffects; ++k)
                for (int ch = 0; ch < 3; ++ch) e[k][ch] = s.ray[k][ch] / n;
            double norm = 1.0 / (kPi * s.r2 * double(n));
            for (int j = 0; j < 3; ++j)
                for (int ch = 0; ch < 3; ++ch) e[kTauClasses[j]][ch] += s.tau[j][ch] * norm;
            for (int ch = 0; ch < 3; ++ch) {
                double t = 0;
                for (int k = 0; k < kNumEffects; ++k) {
                    t += e[k][ch];
                    if (effects) (*effects)[k][3 * p + ch] = float(e[k][ch]);
                }
                image[3 * p + ch] = float(t);
                if (n > 1) {
                    double mean = s.sum[ch] / n;
                    double var = std::max(0.0, (s.sum_sq[ch] - n * mean * mean) / (n - 1.0));
                    variance[3 * p + ch] = float(var / n);
                }
            }
        }
    };

    while (!out.cancelled) {
        int s1 = next_pass_end(opts, cps, passes, since(t0), sec_per_pass);
        if (s1 < 0) break;
        auto pass_t0 = Clock::now();
        int first = passes;
        for (int s = passes; s < s1; ++s) {
            // 1. Camera pass: visible points, emission and direct light (kept
            //    in the visible points until step 3, so a cancel leaves the
            //    finished passes untouched).
            auto camera_row = [&](size_t y, int t) {
                for (int x = 0; x < W; ++x) {
                    size_t p = y * size_t(W) + size_t(x);
                    Sampler sampler(opts.seed, p, uint64_t(s));
                    float fx = filter.sample(sampler.next_1d(), -float(x) - 0.5f, float(W - x) - 0.5f);
                    float fy = filter.sample(sampler.next_1d(), -float(y) - 0.5f, float(H - int(y)) - 0.5f);
                    Vec2 film_pos(float(x) + 0.5f + fx, float(y) + 0.5f + fy);
                    float u1 = sampler.next_1d();
                    Vec2 u2 = sampler.next_2d(), u3 = sampler.next_2d();
                    SensorRay sr = sensor.sample_ray(film_pos, u1, u2, u3);
                    VisiblePoint& vp = vps[p];
                    vp.bsdf = nullptr;
                    vp.er = EffectRadiance();
                    ++tstats[t].paths;
                    camera_path(scene, sampler, sr.ray, vp.er, vp, tstats[t]);
                    vp.beta *= sr.weight;
                    Color tot(0.f);
                    for (int k = 0; k < kNumEffects; ++k) {
                        vp.er.by_effect[k] *= sr.weight;
                        tot += vp.er.by_effect[k];
                    }
                    // A NaN or Inf sample is counted and dropped, never written.
                    if (!is_finite(tot) || (vp.bsdf && !is_finite(vp.beta))) {
                        bool nan = std::isnan(tot.x + tot.y + tot.z) || std::isnan(vp.beta.x + vp.beta.y + vp.beta.z);
                        if (nan) ++tstats[t].nan_samples; else ++tstats[t].inf_samples;
                        vp.er = EffectRadiance();
                        vp.bsdf = nullptr;
                    }
                }
                done.fetch_add(uint64_t(W), std::memory_order_relaxed);
            };
            if (!run_parallel(threads, size_t(H), camera_row, poll_once, cancel)) {
                out.cancelled = true;
                break;
            }
            // 2. Photon pass: photon_count light paths into this pass's map.
            PhotonMap map;
            if (photons_needed) {
                PhotonPass pp = trace_photon_paths(scene, spec, opts.seed, uint64_t(s), uint64_t(photon_count_),
                                                   threads, poll_once, pstats);
                if (pp.cancelled) {
                    out.cancelled = true;
                    break;
                }
                pms.photons += pp.photons.size();
                pms.paths += pp.paths;
                pms.trace_seconds += pp.seconds;
                auto tb = Clock::now();
                map.build(std::move(pp.photons), threads);
                pms.build_seconds += since(tb);
            }
            // 3. Gather and update every pixel's statistics (never cancelled:
            //    a pass is either wholly in the estimate or not at all).
            auto gather_row = [&](size_t y, int) {
                thread_local std::vector<Neighbour> nb;
                BsdfContext ctx;
                for (int x = 0; x < W; ++x) {
                    size_t p = y * size_t(W) + size_t(x);
                    const VisiblePoint& vp = vps[p];
                    PixelStats& ps = px[p];
                    Color phi[3] = {Color(0.f), Color(0.f), Color(0.f)};
                    double m = 0;
                    if (vp.bsdf && !map.empty()) {
                        int budget = max_depth_ < 0 ? 255 : max_depth_ - vp.c;
                        map.range(vp.it.p, float(ps.r2), nb);
                        for (const Neighbour& n : nb) {
                            const Photon& ph = map.photons()[n.idx];
                            if (photon_depth(ph) > budget) continue;
                            Vec3 wp = vp.it.to_local(ph.wi);
                            float c = std::fabs(wp.z);
                            if (!(c > 1e-7f)) continue;
                            Color fr = vp.bsdf->eval(ctx, vp.wi, wp) * (1.f / c);
                            if (is_black(fr)) continue;  // photons x cannot reflect (back side) do not count
                            int j = vp.via_specular ? 2 : ((ph.flags & kPhotonIndirect) ? 1 : 0);
                            m += 1;
                            if (mask[kTauClasses[j]]) phi[j] += vp.beta * fr * ph.power;
                        }
                    }
                    Color value = vp.er.total() + (phi[0] + phi[1] + phi[2]) * float(1.0 / (kPi * ps.r2));
                    for (int k = 0; k < kNumEffects; ++k)
                        for (int ch = 0; ch < 3; ++ch) ps.ray[k][ch] += vp.er.by_effect[k][ch];
                    // H&J 2009, eqs. 6-8 (radius and flux reduction).
                    double ratio = m > 0 ? (ps.n + alpha_ * m) / (ps.n + m) : 1.0;
                    for (int j = 0; j < 3; ++j)
                        for (int ch = 0; ch < 3; ++ch) ps.tau[j][ch] = (ps.tau[j][ch] + phi[j][ch]) * ratio;
                    ps.r2 *= ratio;
                    ps.n += alpha_ * m;
                    for (int ch = 0; ch < 3; ++ch) {
                        ps.sum[ch] += value[ch];
                        ps.sum_sq[ch] += double(value[ch]) * double(value[ch]);
                    }
                }
            };
            std::atomic<bool> no_cancel{false};
            run_parallel(threads, size_t(H), gather_row, [] { return true; }, no_cancel);
            passes = s + 1;
        }
        if (out.cancelled) break;
        sec_per_pass = since(pass_t0) / std::max(1, passes - first);
        if (poll && !poll(done.load(), total)) out.cancelled = true;
        if (std::binary_search(cps.begin(), cps.end(), passes)) {
            Checkpoint cp;
            cp.spp = passes;
            cp.seconds = since(t0);
            develop(passes, cp.image, cp.variance, nullptr);
            out.checkpoints.push_back(std::move(cp));
        }
    }
    for (auto& t : tstats) out.stats.merge(t);
    out.stats.merge(pstats);
    if (photons_needed) out.photon_maps.push_back(pms);
    out.spp = passes;
    out.seconds = since(t0);
    develop(passes, out.image, out.variance, &out.effects);
    return out;
}

std::unique_ptr<Integrator> make_sppm_integrator(const IntegratorDesc& d) { return std::make_unique<Sppm>(d); }

}  // namespace rm
