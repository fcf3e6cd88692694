#include "render/pass_loop.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <thread>

#include "scene/sensor.h"

namespace rm {

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

}  // namespace

int render_threads(const RenderOptions& opts) {
    return opts.threads > 0 ? opts.threads : int(std::max(1u, std::thread::hardware_concurrency()));
}

std::vector<int> checkpoint_plan(const RenderOptions& opts) {
    std::vector<int> cps = opts.checkpoints;
    std::sort(cps.begin(), cps.end());
    cps.erase(std::unique(cps.begin(), cps.end()), cps.end());
    return cps;
}

int next_pass_end(const RenderOptions& opts, const std::vector<int>& checkpoints, int spp_done, double elapsed,
                  double sec_per_spp) {
    // Under an spp budget the passes are fixed by the budget and checkpoints
    // alone, so the summation order and hence the bytes do not depend on
    // timing; a cancel keeps every finished pass. Under a time budget, passes
    // take ~1/8 of what is left.
    int cap = opts.spp > 0 ? opts.spp : (1 << 30);
    if (spp_done >= cap) return -1;
    int s1 = cap;
    for (int c : checkpoints)
        if (c > spp_done) {
            s1 = std::min(s1, c);
            break;
        }
    if (opts.seconds > 0) {
        double left = opts.seconds - elapsed;
        if (left <= 0) return -1;
        if (spp_done == 0) return std::min(s1, 1);
        if (sec_per_spp > left) return -1;  // one more sample per pixel would overrun the budget
        int n = int(std::min(1e6, std::max(1.0, std::floor(left / 8.0 / std::max(sec_per_spp, 1e-9)))));
        return std::min(s1, spp_done + n);
    }
    // 1, 2, 4, ... 64, then 64 more at a time (the waves of pbrt-v4's
    // ImageTileIntegrator::Render): early passes are quick, so a cancel soon
    // keeps something, and the plan ignores timing.
    return std::min(s1, spp_done == 0 ? 1 : spp_done + std::min(spp_done, 64));
}

PassLoop::PassLoop(const Scene& scene, const RenderOptions& opts, const PollFn& poll)
    : scene_(scene), opts_(opts), poll_(poll), threads_(render_threads(opts)), t0_(Clock::now()) {
    uint64_t pixels = uint64_t(scene.sensor->width) * uint64_t(scene.sensor->height);
    total_ = opts.seconds > 0 ? 0 : pixels * uint64_t(opts.spp);
    poll_once_ = [this] { return !poll_ || poll_(done_.load(), total_); };
    stats_.resize(size_t(threads_));
}

double PassLoop::elapsed() const { return since(t0_); }

void PassLoop::set_pixels(uint64_t pixels) { total_ = opts_.seconds > 0 ? 0 : pixels * uint64_t(opts_.spp); }

namespace {

// The crop window's part of a film-sized image of `ch` channels.
void crop_image(const Sensor& s, int ch, std::vector<float>& img) {
    if (img.empty() || (s.crop_w == s.width && s.crop_h == s.height)) return;
    std::vector<float> out(size_t(s.crop_w) * size_t(s.crop_h) * size_t(ch));
    for (int y = 0; y < s.crop_h; ++y)
        std::copy_n(&img[(size_t(s.crop_y + y) * size_t(s.width) + size_t(s.crop_x)) * size_t(ch)],
                    size_t(s.crop_w) * size_t(ch), &out[size_t(y) * size_t(s.crop_w) * size_t(ch)]);
    img.swap(out);
}

void crop_output(const Sensor& s, RenderOutput& out) {
    out.width = s.crop_w;
    out.height = s.crop_h;
    crop_image(s, 3, out.image);
    crop_image(s, 3, out.variance);
    for (auto* v : {&out.effects, &out.strategies, &out.strategies_unweighted, &out.merges, &out.merges_unweighted})
        for (auto& img : *v) crop_image(s, 3, img);
    for (Checkpoint& cp : out.checkpoints) {
        crop_image(s, 3, cp.image);
        crop_image(s, 3, cp.variance);
    }
}

}  // namespace

RenderOutput PassLoop::cancelled_output() const {
    RenderOutput out;
    out.width = scene_.sensor->width;
    out.height = scene_.sensor->height;
    size_t n = size_t(out.width) * size_t(out.height) * 3;
    out.image.assign(n, 0.f);
    out.variance.assign(n, std::numeric_limits<float>::quiet_NaN());
    out.effects.assign(kNumEffects, std::vector<float>(n, 0.f));
    out.cancelled = true;
    out.threads = threads_;
    out.seconds = elapsed();
    crop_output(*scene_.sensor, out);
    return out;
}

RenderOutput PassLoop::run(PassStep& step) {
    RenderOutput out;
    out.width = scene_.sensor->width;
    out.height = scene_.sensor->height;
    out.threads = threads_;
    // 1. The budget of the passes: a time budget counts the setup before
    //    run(), but leaves the passes at least 1 ms, so that it always gets
    //    a first pass.
    RenderOptions budget = opts_;
    if (budget.seconds > 0) budget.seconds = std::max(opts_.seconds - elapsed(), 1e-3);
    const std::vector<int> cps = checkpoint_plan(opts_);
    auto passes_t0 = Clock::now();
    int spp = 0;
    double sec_per_spp = 0;
    for (;;) {
        // 2. The next pass, from the budget and the checkpoints.
        int s1 = next_pass_end(budget, cps, spp, since(passes_t0), sec_per_spp);
        if (s1 < 0) break;
        // 3. The step renders it; a cancel keeps what the step kept of it.
        auto pass_t0 = Clock::now();
        int reached = step.pass(*this, spp, s1);
        if (reached < s1) {
            out.cancelled = true;
            spp = reached;
            break;
        }
        sec_per_spp = since(pass_t0) / (s1 - spp);
        spp = s1;
        // 4. Progress and cancellation between passes.
        if (!poll_once_()) out.cancelled = true;
        // 5. A checkpoint; its time counts the setup (error-vs-time curves).
        if (std::binary_search(cps.begin(), cps.end(), spp)) {
            Checkpoint cp;
            cp.spp = spp;
            cp.seconds = elapsed();
            step.develop(spp, cp.image, cp.variance, nullptr);
            out.checkpoints.push_back(std::move(cp));
        }
        if (out.cancelled) break;
    }
    // 6. The estimate, the counters of every thread, and the step's own extras.
    out.spp = spp;
    out.seconds = elapsed();
    for (const PaddedStats& t : stats_) out.stats.merge(t.s);
    step.develop(spp, out.image, out.variance, &out.effects);
    if (opts_.effect_variance) step.develop_effect_variance(spp, out.effect_variance);
    step.finish(out);
    crop_output(*scene_.sensor, out);
    return out;
}

PassSums::PassSums(size_t pixels) : px_(pixels) {
    iter_.assign(px_ * kNumEffects * 3, 0.0);
    sum_.assign(px_ * kNumEffects * 3, 0.0);
    tot_.assign(px_ * 3, 0.0);
    tot_sq_.assign(px_ * 3, 0.0);
}

void PassSums::clear_pass() { std::fill(iter_.begin(), iter_.end(), 0.0); }

void PassSums::set(size_t p, const EffectRadiance& er) {
    double* e = &iter_[p * kNumEffects * 3];
    for (int k = 0; k < kNumEffects; ++k)
        for (int c = 0; c < 3; ++c) e[k * 3 + c] = double(er.by_effect[k][c]);
}

void PassSums::commit() {
    for (size_t p = 0; p < px_; ++p)
        for (int c = 0; c < 3; ++c) {
            double t = 0;
            for (int k = 0; k < kNumEffects; ++k) {
                double e = iter_[(p * kNumEffects + k) * 3 + c];
                sum_[(p * kNumEffects + k) * 3 + c] += e;
                t += e;
            }
            tot_[3 * p + c] += t;
            tot_sq_[3 * p + c] += t * t;
        }
    ++passes_;
}

void PassSums::develop(int n, std::vector<float>& image, std::vector<float>& variance,
                       std::vector<std::vector<float>>* effects) const {
    image.assign(3 * px_, 0.f);
    variance.assign(3 * px_, std::numeric_limits<float>::quiet_NaN());
    if (effects) effects->assign(kNumEffects, std::vector<float>(3 * px_, 0.f));
    if (n <= 0) return;
    for (size_t p = 0; p < px_; ++p)
        for (int c = 0; c < 3; ++c) {
            double t = 0;
            for (int k = 0; k < kNumEffects; ++k) {
                double e = sum_[(p * kNumEffects + k) * 3 + c] / n;
                t += e;
                if (effects) (*effects)[k][3 * p + c] = float(e);
            }
            image[3 * p + c] = float(t);
            if (n > 1) {
                double mean = tot_[3 * p + c] / n;
                double var = std::max(0.0, (tot_sq_[3 * p + c] - n * mean * mean) / (n - 1.0));
                variance[3 * p + c] = float(var / n);
            }
        }
}

}  // namespace rm
