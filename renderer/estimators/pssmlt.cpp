// `pssmlt`: primary-sample-space Metropolis light transport (Kelemen,
// Szirmay-Kalos, Antal and Csonka 2002) over the unidirectional path tracer
// (`path`) or bidirectional path tracing (`bdpt`, parameter
// `bidirectional`, Mitsuba 0.6's name). The sampled point u of the unit
// hypercube (mlt_sampler.h) drives the whole sample: its first two
// coordinates pick a pixel of the film uniformly, the rest are what the
// inner estimator draws (its camera ray through that pixel, by filter
// importance sampling, and its paths). The sample's splats g(u) (one per
// effect class at the pixel, and for bdpt the light-tracing splats of t = 1
// anywhere on the film) have the scalar contribution f(u) = the sum of
// their luminances, and a pixel's value is I_j = E[g_j(u)] (u uniform) =
// b E_pi[g_j / f] with b = E[f] and pi = f / b (Veach 1997, sec. 11.3).
//
// Chains: `chains` independent Markov chains, each with a bootstrap of its
// own (bootstrap_samples / chains independent points u_i, b_c their mean
// f) and a start u_{i*} drawn from it with probability f_i / sum f (pbrt-v4
// MLTIntegrator's bootstrap; Veach 1997, sec. 11.3.3 for the start-up bias
// it removes). That start makes each chain's estimate b_c mean_k g(x_k) /
// f(x_k) exactly unbiased at any chain length: E[b_c h(x_0)] = E[(1/n) sum_i
// f_i h(u_i)] = b E_pi[h], and the chain's kernel keeps pi (detailed
// balance), so E[b_c h(x_k)] = b E_pi[h] for every k. Hence `bias` is
// declared unbiased (the matrix test holds it to that); what remains is the
// chains' correlation, which only the variance sees.
//
// Mutations: a large step (probability large_step_probability) or a small
// one (normals of deviation `sigma`, mlt_sampler.h), accepted with
// a = min(1, f(y) / f(x)) (Metropolis et al. 1953: both kernels are
// symmetric). Expected-value splatting (Veach 1997, sec. 11.5): every
// proposal adds (1 - a) g(x) / f(x) and a g(y) / f(y); the current state's
// weights are summed and splatted once, when it is left (or at the end of a
// work chunk), which changes nothing in the sums but their rounding.
//
// Budget: one sample per pixel is mutations_per_pixel x W x H mutations
// (the crop window's pixels), dealt to the chains in turn (mutation m to
// chain m mod chains), so the plan is fixed by the budget alone.
//
// Variance (res.variance): batch means over independent chains (Law and
// Kelton, "Simulation Modeling and Analysis", sec. 9.5): chain c belongs to
// batch c mod B (B = min(32, chains)), I_b the estimate of batch b's n_b
// mutations, I that of all N; var = sum_b n_b (I_b - I)^2 / ((B - 1) N),
// as the light driver's (light_render.cpp). The batches are independent
// (own bootstraps, own streams), so this sees the correlation along each
// chain and the bootstrap's noise in b_c, which a variance over one chain's
// samples would not. Neighbouring pixels are correlated too (a chain
// lingers): a block mean's variance is not the sum of its pixels'.
//
// Determinism: each chain draws on its own streams and its splats join the
// film in chain order, so the result is the seed's whatever the thread
// count.
//
// res.stats: "mlt_b" (mean of the chains' b_c) and "mlt_b_variance" (its
// variance, from all bootstrap samples), "mlt_acceptance" (overall),
// "mlt_acceptance_per_chain", "mlt_large_step_acceptance",
// "mlt_small_step_acceptance", "mlt_max_rejections_per_chain" (the longest
// run of consecutive rejections of each chain, the stuck-chain symptom;
// "mlt_longest_rejection_run" its maximum, "mlt_stuck_chains" the chains
// whose run exceeds `stuck_rejections`, a threshold that is only reported),
// "mlt_dead_chains" (chains whose bootstrap found no light: they add 0).
//
// `mmlt`: multiplexed MLT (Hachisuka, Kaplanyan and Dachsbacher 2014) on
// the same chains: after the pixel, two more coordinates choose a depth d
// in 1..max_depth and one strategy (s, t) of bdpt with s + t = d + 1, each
// uniformly; the sample is that strategy alone on subpaths of s and t
// vertices (bdpt_internal.h), its MIS-weighted contribution times
// max_depth (d + 1), so its expectation is bdpt's image truncated at
// max_depth. Its bootstrap evaluates each point with every strategy of
// its depth (bootstrap(), below): b's variance without the strategy
// choice's. Small steps keep the strategy mostly fixed, large steps
// change it; "mlt_acceptance_per_depth" in res.stats, and
// "mlt_b_per_strategy" (each strategy's share of b, with its variance: the
// check against bdpt's strategy images, docs/mlt.md). pbrt-v4's
// MLTIntegrator runs separate chains per depth instead.
//
// Limits: no participating media, no dipole (refused by name: caps); no
// per-strategy images; the path tracer's samples reach only their pixel
// (filter importance sampling, as the camera driver's).
#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <numeric>

#include "estimators/bdpt_internal.h"
#include "estimators/mlt_sampler.h"
#include "render/memory.h"
#include "render/pass_loop.h"
#include "render/registry.h"
#include "transport/camera_sample.h"

namespace rm {

namespace {

constexpr int kMaxBatches = 32;
constexpr uint32_t kStrategyDim = 3;                     // mmlt's coordinates: pixel (0, 1), depth (2), strategy (3)
constexpr uint64_t kChunkMutations = uint64_t(1) << 19;  // mutations of all chains between commits (bounds memory)

// The chains' parameters, shared by pssmlt and mmlt (`bootstrap`: the default sample count).
std::vector<ParamSpec> chain_params(int64_t bootstrap) {
    return {
        ParamSpec::integer("chains", 256, "independent Markov chains (the variance's batches: min(32, chains))")
            .at_least(2)
            .at_most(1 << 20),
        ParamSpec::integer("bootstrap_samples", bootstrap,
                           "independent samples estimating b, shared out among the chains (each gets at least one)")
            .at_least(1)
            .at_most(int64_t(1) << 30),
        ParamSpec::integer("mutations_per_pixel", 1, "mutations per pixel in one sample per pixel of the budget")
            .at_least(1)
            .at_most(1 << 16),
        ParamSpec::real("large_step_probability", 0.3, "probability of a large step (a fresh independent sample)")
            .greater_than(0)
            .at_most(1),
        ParamSpec::real("sigma", 0.01, "standard deviation of a small step in primary sample space")
            .greater_than(0)
            .at_most(1),
        ParamSpec::integer("stuck_rejections", 256,
                           "a chain whose longest run of consecutive rejections exceeds this is counted as stuck "
                           "(res.stats mlt_stuck_chains); only reported, nothing is changed")
            .at_least(1)
            .at_most(int64_t(1) << 30),
    };
}

std::unique_ptr<Integrator> make_pssmlt(ParamReader& p);

[[maybe_unused]] const bool kRegistered = register_estimator([] {
    EstimatorInfo e;
    e.name = "pssmlt";
    e.doc =
        "primary-sample-space Metropolis light transport over path or bdpt (Kelemen et al. 2002), independent "
        "chains with their own bootstrap";
    e.params = {
        max_depth_param(),
        rr_depth_param(),
        hide_emitters_param(),
        ParamSpec::boolean("bidirectional", true, "mutate bdpt's samples (false: the unidirectional path tracer's)"),
    };
    for (ParamSpec& q : chain_params(16384)) e.params.push_back(q);
    e.caps.driver = Driver::OwnPasses;
    e.caps.bias = Bias::Unbiased;
    e.caps.correlated_pixels = true;
    e.factory = make_pssmlt;
    return e;
}());

std::unique_ptr<Integrator> make_mmlt(ParamReader& p);

// mmlt: the chains of pssmlt over one bdpt strategy per sample.
[[maybe_unused]] const bool kRegisteredMmlt = register_estimator([] {
    EstimatorInfo e;
    e.name = "mmlt";
    e.doc =
        "multiplexed Metropolis light transport: one bdpt strategy per sample, chosen by a mutated coordinate "
        "(Hachisuka et al. 2014)";
    e.params = {
        ParamSpec::integer("max_depth", 5, "longest path in segments (the depths a sample chooses among)")
            .at_least(1)
            .at_most(1024),
        rr_depth_param(),
        hide_emitters_param(),
    };
    for (ParamSpec& q : chain_params(65536)) e.params.push_back(q);
    e.caps.driver = Driver::OwnPasses;
    e.caps.bias = Bias::Unbiased;
    e.caps.correlated_pixels = true;
    e.factory = make_mmlt;
    return e;
}());

// Mutation index m goes to chain m mod C: chain c's share of the first n.
inline uint64_t chain_share(uint64_t n, uint64_t chains, uint64_t c) { return n / chains + (c < n % chains ? 1 : 0); }

}  // namespace

class PssmltIntegrator final : public Integrator {
public:
    PssmltIntegrator(ParamReader& p, bool multiplexed)
        : max_depth_(p.get_int("max_depth")),
          rr_depth_(p.get_int("rr_depth")),
          hide_(p.get_bool("hide_emitters")),
          bidir_(multiplexed || p.get_bool("bidirectional")),
          multiplexed_(multiplexed),
          chains_(p.get_int("chains")),
          bootstrap_(p.get_int("bootstrap_samples")),
          mpp_(p.get_int("mutations_per_pixel")),
          large_p_(p.get_float("large_step_probability")),
          sigma_(p.get_float("sigma")),
          stuck_(p.get_int("stuck_rejections")) {}

    void sample(const Scene&, Sampler&, const Ray&, EffectRadiance&, ThreadStats&) const override {
        throw std::logic_error("integrator '" + type + "' renders through its own driver");
    }
    RenderOutput drive(const Scene& scene, const RenderOptions& opts, const PollFn& poll) const override;

    class Passes;

private:
    int max_depth_, rr_depth_;
    bool hide_, bidir_, multiplexed_;
    int chains_, bootstrap_, mpp_;
    float large_p_, sigma_;
    int64_t stuck_;
};

class PssmltIntegrator::Passes final : public PassStep {
public:
    Passes(const PssmltIntegrator& m, const Scene& scene, const Integrator& inner)
        : m_(m),
          scene_(scene),
          inner_(inner),
          filter_(scene.sensor_desc.rfilter, scene.sensor_desc.filter_radius, scene.sensor_desc.filter_stddev),
          W_(scene.sensor->width),
          H_(scene.sensor->height),
          C_(uint64_t(m.chains_)),
          B_(int(std::min<uint64_t>(kMaxBatches, C_))),
          per_spp_(uint64_t(m.mpp_) * uint64_t(scene.sensor->crop_w) * uint64_t(scene.sensor->crop_h)),
          n_boot_(std::max<uint64_t>(1, (uint64_t(m.bootstrap_) + C_ - 1) / C_)) {
        const Sensor& sn = *scene.sensor;
        cx0_ = sn.crop_x, cx1_ = sn.crop_x + sn.crop_w, cy0_ = sn.crop_y, cy1_ = sn.crop_y + sn.crop_h;
        norm_x_ = splat_norms(filter_, W_, cx0_, cx1_);
        norm_y_ = splat_norms(filter_, H_, cy0_, cy1_);
        const size_t px = size_t(W_) * size_t(H_);
        sums_.assign(px * kNumEffects * 3, 0.0);
        batches_.assign(px * size_t(B_) * 3, 0.0);
        chains_.reserve(size_t(C_));
        for (uint64_t c = 0; c < C_; ++c) chains_.emplace_back(m.sigma_, m.large_p_);
        stripes_ = std::max(1, std::min(H_, 64));
    }

    int pass(PassLoop& loop, int s0, int s1) override {
        if (!started_) {
            auto boot = [&](size_t c, int th) { bootstrap(loop, c, loop.stats(th)); };
            if (!loop.parallel_for(size_t(C_), boot)) return s0;
            started_ = true;
        }
        const int step = int(std::max<uint64_t>(1, kChunkMutations / std::max<uint64_t>(per_spp_, 1)));
        for (int a = s0; a < s1;) {
            const int b = std::min(s1, a + step);
            auto run = [&](size_t c, int th) {
                Chain& ch = chains_[c];
                ch.out.clear();
                const uint64_t n0 = chain_share(uint64_t(a) * per_spp_, C_, c);
                const uint64_t n1 = chain_share(uint64_t(b) * per_spp_, C_, c);
                for (uint64_t k = n0; k < n1; ++k) {
                    if (loop.cancelled()) return;
                    mutate(ch, loop.stats(th));
                }
                flush(ch);
            };
            if (!loop.parallel_for(size_t(C_), run)) return a;
            auto merge = [&](size_t i, int) {
                int y0 = int(int64_t(H_) * int64_t(i) / stripes_), y1 = int(int64_t(H_) * int64_t(i + 1) / stripes_);
                merge_rows(y0, y1);
            };
            loop.parallel_commit(size_t(stripes_), merge);
            loop.add_done(uint64_t(b - a) * uint64_t(scene_.sensor->crop_w) * uint64_t(scene_.sensor->crop_h));
            a = b;
        }
        return s1;
    }

    void develop(int spp, std::vector<float>& image, std::vector<float>& variance,
                 std::vector<std::vector<float>>* effects) const override {
        const size_t px = size_t(W_) * size_t(H_);
        image.assign(3 * px, 0.f);
        variance.assign(3 * px, std::numeric_limits<float>::quiet_NaN());
        if (effects) effects->assign(kNumEffects, std::vector<float>(3 * px, 0.f));
        const uint64_t n = uint64_t(std::max(spp, 0)) * per_spp_;
        if (n == 0) return;
        std::vector<double> n_b(size_t(B_), 0.0);
        for (uint64_t c = 0; c < C_; ++c) n_b[c % uint64_t(B_)] += double(chain_share(n, C_, c));
        int b_eff = 0;
        for (double v : n_b) b_eff += v > 0 ? 1 : 0;
        const double inv_n = 1.0 / double(n);
        for (size_t p = 0; p < px; ++p)
            for (int c = 0; c < 3; ++c) {
                double total = 0;
                for (int k = 0; k < kNumEffects; ++k) {
                    double e = sums_[(p * kNumEffects + k) * 3 + c] * inv_n;
                    total += e;
                    if (effects) (*effects)[k][3 * p + c] = float(e);
                }
                image[3 * p + c] = float(total);
                if (b_eff < 2) continue;  // too few batches: NaN, never a fake 0
                double ss = 0;
                for (int b = 0; b < B_; ++b)
                    if (n_b[size_t(b)] > 0) {
                        double d = batches_[(p * size_t(B_) + size_t(b)) * 3 + c] / n_b[size_t(b)] - total;
                        ss += n_b[size_t(b)] * d * d;
                    }
                variance[3 * p + c] = float(ss / (double(b_eff - 1) * double(n)));
            }
    }

    void finish(RenderOutput& out) const override {
        double b_sum = 0, f_sum = 0, f_sq = 0, n_f = 0, dead = 0, stuck = 0, longest = 0;
        uint64_t acc = 0, prop = 0, lacc = 0, lprop = 0;
        std::vector<double> per_chain, max_rej;
        for (const Chain& ch : chains_) {
            b_sum += ch.b;
            f_sum += ch.f_sum;
            f_sq += ch.f_sq;
            n_f += double(ch.n_f);
            dead += ch.b > 0 ? 0 : 1;
            acc += ch.accepted;
            prop += ch.proposed;
            lacc += ch.large_accepted;
            lprop += ch.large_proposed;
            per_chain.push_back(ch.proposed ? double(ch.accepted) / double(ch.proposed)
                                            : std::numeric_limits<double>::quiet_NaN());
            max_rej.push_back(double(ch.max_run));
            stuck += ch.max_run > uint64_t(m_.stuck_) ? 1 : 0;
            longest = std::max(longest, double(ch.max_run));
        }
        auto ratio = [](uint64_t a, uint64_t b) {
            return b ? double(a) / double(b) : std::numeric_limits<double>::quiet_NaN();
        };
        // b: the mean of the chains' b_c (each the mean of an equal share of
        // the bootstrap), its variance from the bootstrap samples' spread.
        const double b = started_ ? b_sum / double(C_) : 0.0;
        const double mean_f = n_f > 0 ? f_sum / n_f : 0.0;
        const double var_f = n_f > 1 ? std::max(0.0, (f_sq - n_f * mean_f * mean_f) / (n_f - 1.0)) : 0.0;
        auto& st = out.estimator_stats;
        st.push_back({"mlt_b", {b}});
        st.push_back({"mlt_b_variance", {n_f > 0 ? var_f / n_f : std::numeric_limits<double>::quiet_NaN()}});
        st.push_back({"mlt_bootstrap_samples", {n_f}});
        st.push_back({"mlt_chains", {double(C_)}});
        st.push_back({"mlt_dead_chains", {dead}});
        st.push_back({"mlt_mutations", {double(prop)}});
        st.push_back({"mlt_acceptance", {ratio(acc, prop)}});
        st.push_back({"mlt_large_step_acceptance", {ratio(lacc, lprop)}});
        st.push_back({"mlt_small_step_acceptance", {ratio(acc - lacc, prop - lprop)}});
        st.push_back({"mlt_acceptance_per_chain", per_chain});
        st.push_back({"mlt_max_rejections_per_chain", max_rej});
        st.push_back({"mlt_longest_rejection_run", {longest}});
        st.push_back({"mlt_stuck_rejections", {double(m_.stuck_)}});
        st.push_back({"mlt_stuck_chains", {stuck}});
        image_mean_variance(st);
        if (m_.multiplexed_) {
            // Acceptance by the proposal's depth 1 .. max_depth.
            std::vector<double> per_depth;
            for (int d = 1; d <= m_.max_depth_; ++d) {
                uint64_t a = 0, p = 0;
                for (const Chain& ch : chains_)
                    if (size_t(d) < ch.depth_proposed.size()) {
                        a += ch.depth_accepted[size_t(d)];
                        p += ch.depth_proposed[size_t(d)];
                    }
                per_depth.push_back(ratio(a, p));
            }
            st.push_back({"mlt_acceptance_per_depth", per_depth});
            // b by strategy: each (d, s)'s share of b (their sum is mlt_b)
            // and the variance of that share's mean, from all bootstrap
            // points (independent across chains). A strategy's share is the
            // expectation of its MIS-weighted contribution, the luminance sum
            // of bdpt's strategy image (s, d + 1 - s): the check that each
            // strategy is unbiased, which b alone cannot localise.
            std::vector<double> share(strategy_slots(), 0.0), share_var(strategy_slots(), 0.0);
            std::vector<double> sq(strategy_slots(), 0.0);
            for (const Chain& ch : chains_)
                for (size_t k = 0; k < ch.fs_sum.size(); ++k) share[k] += ch.fs_sum[k], sq[k] += ch.fs_sq[k];
            for (size_t k = 0; k < share.size(); ++k) {
                const double m = n_f > 0 ? share[k] / n_f : 0.0;
                share_var[k] = n_f > 1 ? std::max(0.0, (sq[k] - n_f * m * m) / (n_f - 1.0)) / n_f
                                       : std::numeric_limits<double>::quiet_NaN();
                share[k] = m;
            }
            st.push_back({"mlt_b_per_strategy", share});
            st.push_back({"mlt_b_per_strategy_variance", share_var});
        }
    }

private:
    // "mlt_image_mean_variance" (R, G, B): the variance of the image mean by
    // the batch means res.variance uses per pixel. A chain's normalisation
    // b_c scales every pixel it visits, so the pixels' errors share one
    // component across the image, which no sum of their variances gives;
    // the batches are independent (own chains, own bootstraps), so their
    // image means carry it. NaN with fewer than 2 batches.
    void image_mean_variance(std::vector<std::pair<std::string, std::vector<double>>>& st) const {
        std::vector<double> n_b(size_t(B_), 0.0);
        for (uint64_t c = 0; c < C_; ++c) n_b[c % uint64_t(B_)] += double(chains_[c].proposed);
        double n = 0;
        int b_eff = 0;
        for (double v : n_b) {
            n += v;
            b_eff += v > 0 ? 1 : 0;
        }
        const size_t px = size_t(W_) * size_t(H_);
        std::vector<double> out(3, std::numeric_limits<double>::quiet_NaN());
        if (b_eff >= 2 && px > 0) {
            for (int c = 0; c < 3; ++c) {
                std::vector<double> m(size_t(B_), 0.0);
                double total = 0;
                for (size_t p = 0; p < px; ++p)
                    for (int b = 0; b < B_; ++b) m[size_t(b)] += batches_[(p * size_t(B_) + size_t(b)) * 3 + c];
                for (double v : m) total += v;
                total /= n * double(px);
                double ss = 0;
                for (int b = 0; b < B_; ++b)
                    if (n_b[size_t(b)] > 0) {
                        const double d = m[size_t(b)] / (n_b[size_t(b)] * double(px)) - total;
                        ss += n_b[size_t(b)] * d * d;
                    }
                out[size_t(c)] = ss / (double(b_eff - 1) * n);
            }
        }
        st.push_back({"mlt_image_mean_variance", out});
    }

    struct Chain {
        Chain(float sigma, float large_p) : pss(sigma, large_p) {}
        PssSampler pss;
        double b = 0;                // the chain's bootstrap estimate of b
        double f_sum = 0, f_sq = 0;  // its bootstrap samples' f: sum, sum of squares
        uint64_t n_f = 0;            // and their count
        // mmlt: per strategy (d, s) (strategy_slot), the sum and the sum of
        // squares of its share f / (d + 1) of each bootstrap point's f_mean.
        std::vector<double> fs_sum, fs_sq;
        std::vector<Splat> cur, prop;         // the current state's splats, the proposal's
        float f_cur = 0;                      // f of the current state
        double pending = 0;                   // expected-value weight the current state has gathered
        std::vector<Splat> out;               // this chunk's splats, values weighted
        uint64_t accepted = 0, proposed = 0;  // acceptance counts
        uint64_t large_accepted = 0, large_proposed = 0;
        uint64_t run = 0, max_run = 0;                         // consecutive rejections: now, longest
        std::vector<uint64_t> depth_accepted, depth_proposed;  // mmlt: by the proposal's depth
    };

    // The sample of the point `pss` holds: its splats inside the crop
    // window (finite ones; the others are counted) and f, their luminance.
    float evaluate(PssSampler& pss, std::vector<Splat>& out, ThreadStats& stats, int* depth = nullptr) const {
        out.clear();
        Sampler sampler(&pss);
        const Vec2 u = sampler.next_2d();
        const int x = std::min(int(u.x * float(W_)), W_ - 1), y = std::min(int(u.y * float(H_)), H_ - 1);
        const int pixel = y * W_ + x;
        const float film_scale = float(W_) * float(H_);
        if (m_.multiplexed_) {
            // mmlt (Hachisuka et al. 2014, sec. 4): a depth d in 1..D and a
            // strategy (s, t), s + t = d + 1, each chosen uniformly by a
            // coordinate of its own; the contribution times D (d + 1).
            const int D = m_.max_depth_;
            const int d = 1 + std::min(int(sampler.next_1d() * float(D)), D - 1);
            const int s = std::min(int(sampler.next_1d() * float(d + 1)), d);
            if (depth) *depth = d;
            bdpt_trace_strategy(inner_, scene_, sampler, pixel, s, d + 1 - s, float(D) * float(d + 1), out, stats);
        } else if (m_.bidir_) {
            // bdpt's camera splats (pixel >= 0) are already scaled by W H:
            // its samples pick their pixel uniformly, as here.
            inner_.trace_light_path(scene_, sampler, pixel, out, stats);
        } else {
            SensorRay sr = sample_camera_ray(*scene_.sensor, filter_, pixel, sampler);
            EffectRadiance er;
            ++stats.paths;
            inner_.sample(scene_, sampler, sr.ray, er, stats);
            for (int k = 0; k < kNumEffects; ++k) {
                Color v = er.by_effect[k] * sr.weight * film_scale;
                if (is_black(v)) continue;
                Splat sp;
                sp.pixel = pixel;
                sp.effect = k;
                sp.value = v;
                out.push_back(sp);
            }
        }
        double f = 0;
        size_t kept = 0;
        for (const Splat& sp : out) {
            if (!keep_finite(stats, sp.value)) continue;
            if (sp.pixel >= 0) {
                if (!scene_.sensor->in_crop(sp.pixel % W_, sp.pixel / W_)) continue;
            } else if (sp.film.x < float(cx0_) || sp.film.x > float(cx1_) || sp.film.y < float(cy0_) ||
                       sp.film.y > float(cy1_)) {
                continue;
            }
            const float l = luminance(sp.value);
            if (!(l > 0.f)) continue;
            f += double(l);
            out[kept++] = sp;
        }
        out.resize(kept);
        return std::isfinite(f) ? float(f) : 0.f;
    }

    // Chain c's bootstrap: its share of independent points, b_c, and its
    // start drawn from them in proportion to f (replayed from its stream).
    // mmlt: each point is evaluated with every strategy of its depth (the
    // strategy coordinate moved into each strategy's interval at the same
    // relative place), b_c the mean over points of their strategies' mean f
    // and the start drawn among all (point, strategy) pairs in proportion
    // to f / (d + 1). For u uniform, the moved point is uniform given its
    // strategy, so E[(1/n) sum_i (1/(d_i+1)) sum_s f(u_i^s) h(u_i^s)] =
    // E[f h] = b E_pi[h]: the chains stay unbiased, while b loses the
    // variance of the strategy choice (a strategy alone times d + 1).
    void bootstrap(PassLoop& loop, size_t c, ThreadStats& stats) {
        Chain& ch = chains_[c];
        const uint64_t stream = mix64(loop.seed() ^ mix64(uint64_t(c) + 0x6d6c74626f6f7473ULL));
        std::vector<double> cdf(1, 0.0);
        std::vector<std::pair<uint64_t, float>> point;  // per cdf entry: bootstrap point, strategy coordinate
        cdf.reserve(size_t(n_boot_) + 1);
        point.reserve(size_t(n_boot_));
        std::vector<Splat> tmp;
        for (uint64_t i = 0; i < n_boot_; ++i) {
            if (loop.cancelled()) return;
            ch.pss.restart(stream, i);
            int d = 0;
            const double f0 = evaluate(ch.pss, tmp, stats, &d);
            double f_mean = f0;
            if (!m_.multiplexed_) {
                cdf.push_back(cdf.back() + f0);
                point.push_back({i, -1.f});
            } else {
                const int n = d + 1;
                const float v = ch.pss.value(kStrategyDim);
                const int s0 = std::min(int(v * float(n)), d);
                const float xi = std::min(std::max(v * float(n) - float(s0), 0.f), 1.f);
                double sum = 0;
                if (ch.fs_sum.empty()) ch.fs_sum.assign(strategy_slots(), 0.0), ch.fs_sq.assign(strategy_slots(), 0.0);
                for (int st = 0; st < n; ++st) {
                    const float vs = st == s0 ? v : strategy_coordinate(st, n, xi);
                    double f = f0;
                    if (st != s0) {
                        ch.pss.restart(stream, i, int(kStrategyDim), vs);
                        f = evaluate(ch.pss, tmp, stats);
                    }
                    sum += f;
                    const double share = f / double(n);
                    if (d >= 1 && d <= m_.max_depth_) {
                        ch.fs_sum[strategy_slot(d, st)] += share;
                        ch.fs_sq[strategy_slot(d, st)] += share * share;
                    }
                    cdf.push_back(cdf.back() + f / double(n));
                    point.push_back({i, vs});
                }
                f_mean = sum / double(n);
            }
            ch.f_sum += f_mean;
            ch.f_sq += f_mean * f_mean;
        }
        ch.n_f = n_boot_;
        ch.b = ch.f_sum / double(n_boot_);
        // The chain's own stream: the start's choice, then every mutation.
        const uint64_t own = mix64(loop.seed() ^ mix64(uint64_t(c) + 0x6d6c74636861696eULL));
        if (!(ch.f_sum > 0)) {
            ch.pss.reseed(own, uint64_t(c));
            return;  // no light found: the chain adds 0 (its mutations still count)
        }
        Pcg32 pick(own, uint64_t(c) ^ 0x5bd1e995ULL);
        const double target = double(pick.next_float()) * cdf.back();
        size_t j = size_t(std::upper_bound(cdf.begin() + 1, cdf.end(), target) - cdf.begin()) - 1;
        while (j + 1 < cdf.size() && !(cdf[j + 1] > cdf[j])) ++j;  // never a point with f = 0
        j = std::min(j, point.size() - 1);
        if (point[j].second < 0.f)
            ch.pss.restart(stream, point[j].first);
        else
            ch.pss.restart(stream, point[j].first, int(kStrategyDim), point[j].second);
        ch.f_cur = evaluate(ch.pss, ch.cur, stats);
        ch.pss.reseed(own, uint64_t(c));
    }

    // mmlt's strategies (d, s), d = 1 .. max_depth, s = 0 .. d, in that
    // order: slot d (d + 1) / 2 - 1 + s.
    size_t strategy_slots() const { return size_t(m_.max_depth_) * size_t(m_.max_depth_ + 3) / 2; }
    static size_t strategy_slot(int d, int s) { return size_t(d) * size_t(d + 1) / 2 - 1 + size_t(s); }

    // mmlt's strategy coordinate: s of n strategies at relative place xi
    // in [0, 1) of its interval, kept inside it against rounding.
    static float strategy_coordinate(int s, int n, float xi) {
        float v = (float(s) + xi) / float(n);
        for (int k = 0; k < 8; ++k) {
            const int got = std::min(int(v * float(n)), n - 1);
            if (got == s) break;
            v = std::nextafter(v, got > s ? 0.f : 1.f);
        }
        return v;
    }

    void mutate(Chain& ch, ThreadStats& stats) {
        if (!(ch.b > 0) || !(ch.f_cur > 0.f)) return;  // a chain without light
        PssSampler& pss = ch.pss;
        pss.start_iteration();
        const bool large = pss.large_step();
        int depth = 0;
        const float fy = evaluate(pss, ch.prop, stats, &depth);
        if (m_.multiplexed_) {
            ch.depth_proposed.resize(size_t(m_.max_depth_) + 1, 0);
            ch.depth_accepted.resize(size_t(m_.max_depth_) + 1, 0);
            ++ch.depth_proposed[size_t(depth)];
        }
        const double a = std::min(1.0, double(fy) / double(ch.f_cur));
        ++ch.proposed;
        if (large) ++ch.large_proposed;
        ch.pending += 1.0 - a;
        if (a > 0) emit(ch, ch.prop, a * ch.b / double(fy));
        if (double(pss.uniform()) < a) {
            flush(ch);
            std::swap(ch.cur, ch.prop);
            ch.f_cur = fy;
            pss.accept();
            ++ch.accepted;
            if (large) ++ch.large_accepted;
            if (m_.multiplexed_) ++ch.depth_accepted[size_t(depth)];
            ch.run = 0;
        } else {
            pss.reject();
            ch.max_run = std::max(ch.max_run, ++ch.run);
        }
    }

    // The current state's gathered weight, splatted.
    void flush(Chain& ch) {
        if (ch.pending > 0 && ch.f_cur > 0.f) emit(ch, ch.cur, ch.pending * ch.b / double(ch.f_cur));
        ch.pending = 0;
    }

    static void emit(Chain& ch, const std::vector<Splat>& splats, double w) {
        for (Splat sp : splats) {
            sp.value = sp.value * float(w);
            ch.out.push_back(sp);
        }
    }

    // The chunk's splats, in chain order, into rows [y0, y1).
    void merge_rows(int y0, int y1) {
        for (uint64_t c = 0; c < C_; ++c) {
            const size_t b = size_t(c % uint64_t(B_));
            for (const Splat& sp : chains_[size_t(c)].out) {
                if (sp.pixel >= 0) {
                    const int py = sp.pixel / W_;
                    if (py < y0 || py >= y1) continue;
                    add(size_t(sp.pixel), b, sp.effect, sp.value, 1.0);
                    continue;
                }
                for_each_splat_pixel(filter_, norm_x_, norm_y_, W_, y0, y1, sp.film.x, sp.film.y,
                                     [&](size_t p, double wgt) { add(p, b, sp.effect, sp.value, wgt); });
            }
        }
    }

    void add(size_t p, size_t batch, int effect, const Color& v, double wgt) {
        double* e = &sums_[(p * kNumEffects + size_t(effect)) * 3];
        double* bb = &batches_[(p * size_t(B_) + batch) * 3];
        for (int c = 0; c < 3; ++c) {
            e[c] += wgt * double(v[c]);
            bb[c] += wgt * double(v[c]);
        }
    }

    const PssmltIntegrator& m_;
    const Scene& scene_;
    const Integrator& inner_;
    FilterSampler filter_;
    const int W_, H_;
    const uint64_t C_;
    const int B_;
    const uint64_t per_spp_;  // mutations per sample per pixel of the budget
    const uint64_t n_boot_;   // bootstrap samples per chain
    int cx0_ = 0, cx1_ = 0, cy0_ = 0, cy1_ = 0;
    std::vector<double> norm_x_, norm_y_;
    std::vector<double> sums_, batches_;  // [pixel][effect][rgb], [pixel][batch][rgb]
    std::vector<Chain> chains_;
    int stripes_ = 1;
    bool started_ = false;
};

RenderOutput PssmltIntegrator::drive(const Scene& scene, const RenderOptions& opts, const PollFn& poll) const {
    const int W = scene.sensor->width, H = scene.sensor->height;
    const double px = double(W) * double(H);
    check_memory(type, W, H,
                 {{"per-pixel sums", px * 8.0 * 3.0 * (kNumEffects + std::min(kMaxBatches, chains_)),
                   "the resolution (film width, height)"},
                  {"chains", double(chains_) * 512.0, "chains"},
                  output_memory(opts, W, H)});
    IntegratorDesc d;
    d.type = bidir_ ? "bdpt" : "path";
    d.params.set("max_depth", int64_t(max_depth_));
    d.params.set("rr_depth", int64_t(rr_depth_));
    d.params.set("hide_emitters", hide_);
    // No truncation probe inside the chains: its tally counts camera samples
    // of its own, and its draws would only lengthen the primary sample vector.
    if (!bidir_) d.params.set("truncation_probe", 0.0);
    std::unique_ptr<Integrator> made = make_integrator(d, mask);
    const Integrator& inner = made->for_scene(scene);
    inner.check_scene(scene);
    PassLoop loop(scene, opts, poll);
    loop.set_pixels(uint64_t(scene.sensor->crop_w) * uint64_t(scene.sensor->crop_h));
    Passes passes(*this, scene, inner);
    return loop.run(passes);
}

namespace {

std::unique_ptr<Integrator> make_pssmlt(ParamReader& p) { return std::make_unique<PssmltIntegrator>(p, false); }
std::unique_ptr<Integrator> make_mmlt(ParamReader& p) { return std::make_unique<PssmltIntegrator>(p, true); }

}  // namespace

}  // namespace rm
