#include "render/render.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <mutex>
#include <stdexcept>
#include <thread>

namespace rm {

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

constexpr int kTile = 16;

struct PassJob {
    const Scene* scene;
    const Integrator* integrator;
    const FilterSampler* filter;
    Film* film;
    uint64_t seed;
    int s0, s1;  // sample indices [s0, s1) of this pass
    int tiles_x, tiles_y;
    std::atomic<int> next_tile{0};
    std::atomic<uint64_t> done{0};
    std::atomic<bool>* cancel;
    std::vector<ThreadStats> stats;
};

void render_tile(PassJob& job, int tile, ThreadStats& stats) {
    const Scene& scene = *job.scene;
    const Sensor& sensor = *scene.sensor;
    int W = sensor.width, H = sensor.height;
    int tx = tile % job.tiles_x, ty = tile / job.tiles_x;
    int x0 = tx * kTile, y0 = ty * kTile;
    int x1 = std::min(x0 + kTile, W), y1 = std::min(y0 + kTile, H);
    for (int y = y0; y < y1; ++y)
        for (int x = x0; x < x1; ++x) {
            if (job.cancel->load(std::memory_order_relaxed)) return;
            int pixel = y * W + x;
            for (int s = job.s0; s < job.s1; ++s) {
                Sampler sampler(job.seed, uint64_t(pixel), uint64_t(s));
                // Filter importance sampling, kept inside the film.
                float fx = job.filter->sample(sampler.next_1d(), -float(x) - 0.5f, float(W - x) - 0.5f);
                float fy = job.filter->sample(sampler.next_1d(), -float(y) - 0.5f, float(H - y) - 0.5f);
                Vec2 film_pos(float(x) + 0.5f + fx, float(y) + 0.5f + fy);
                float u1 = sampler.next_1d();
                Vec2 u2 = sampler.next_2d(), u3 = sampler.next_2d();
                SensorRay sr = sensor.sample_ray(film_pos, u1, u2, u3);
                EffectRadiance er;
                ++stats.paths;
                job.integrator->sample(scene, sampler, sr.ray, er, stats);
                Color total(0.f);
                for (int k = 0; k < kNumEffects; ++k) {
                    er.by_effect[k] *= sr.weight;
                    total += er.by_effect[k];
                }
                // A NaN or Inf sample is counted and dropped, never written.
                if (!is_finite(total)) {
                    bool nan = std::isnan(total.x) || std::isnan(total.y) || std::isnan(total.z);
                    if (nan) ++stats.nan_samples; else ++stats.inf_samples;
                    er = EffectRadiance();
                }
                job.film->add(pixel, er);
            }
        }
    job.done.fetch_add(uint64_t(job.s1 - job.s0) * uint64_t((x1 - x0) * (y1 - y0)), std::memory_order_relaxed);
}

}  // namespace

RenderOutput Integrator::drive(const Scene&, const RenderOptions&, const PollFn&) const {
    throw std::logic_error("Integrator::drive called on an estimator that does not own its driver");
}

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
        if (c > spp_done) { s1 = std::min(s1, c); break; }
    if (opts.seconds > 0) {
        double left = opts.seconds - elapsed;
        if (left <= 0) return -1;
        if (spp_done == 0) return std::min(s1, 1);
        if (sec_per_spp > left) return -1;  // one more sample per pixel would overrun the budget
        int n = int(std::min(1e6, std::max(1.0, std::floor(left / 8.0 / std::max(sec_per_spp, 1e-9)))));
        return std::min(s1, spp_done + n);
    }
    // 1, 2, 4, ... 64, then 64 more at a time: early passes are quick, so a
    // cancel soon keeps something, and the plan ignores timing.
    return std::min(s1, spp_done == 0 ? 1 : spp_done + std::min(spp_done, 64));
}

RenderOutput render(const Scene& scene, const Integrator& requested, const RenderOptions& opts, const PollFn& poll) {
    if (!scene.committed()) throw std::logic_error("render: scene is not committed");
    const Integrator& integrator = requested.for_scene(scene);
    if (opts.spp < 0) throw std::invalid_argument("render: spp must be >= 0");
    if (!(opts.seconds >= 0)) throw std::invalid_argument("render: seconds must be >= 0");
    if (opts.spp == 0 && opts.seconds <= 0) throw std::invalid_argument("render: give spp or seconds");
    if (scene.features.has_media && !integrator.supports_media())
        throw std::invalid_argument("integrator '" + integrator.type +
                                    "' does not support participating media yet, and this scene has media; "
                                    "use integrator 'volpath' (or 'path', the same estimator), 'bdpt', 'ptracer', or "
                                    "'photonmapper' (volume photon map and ray marching)");
    if (scene.features.has_dipole && !integrator.supports_dipole()) {
        std::string shape;
        for (const auto& s : scene.shapes)
            if (s->dipole >= 0) { shape = s->id; break; }
        throw std::invalid_argument("integrator '" + integrator.type + "' cannot render the dipole BSSRDF (subsurface "
                                    "'dipole' on shape '" + shape + "'): only the camera-path estimators sample its "
                                    "exit points; use integrator 'path' (or 'volpath')");
    }
    if (integrator.owns_driver()) return integrator.drive(scene, opts, poll);
    if (integrator.is_light_tracer()) return render_light_paths(scene, integrator, opts, poll);
    const Sensor& sensor = *scene.sensor;
    const SensorDesc& sd = scene.sensor_desc;
    int W = sensor.width, H = sensor.height;
    FilterSampler filter(sd.rfilter, sd.filter_radius, sd.filter_stddev);
    // Two films of 27 doubles per pixel (estimate, squares, 7 effects): say
    // so up front rather than fail inside an allocation.
    double film_bytes = 2.0 * double(W) * double(H) * (3 + 3 + 3 * kNumEffects) * sizeof(double);
    if (film_bytes > 16.0 * (1ull << 30))
        throw std::invalid_argument("render: a " + std::to_string(W) + "x" + std::to_string(H) + " film needs " +
                                    std::to_string(int(film_bytes / (1ull << 30))) +
                                    " GiB of accumulation buffers (limit 16 GiB); lower the resolution");
    Film film(W, H);       // finished passes
    Film pass_film(W, H);  // the pass in flight; merged only when complete

    int threads = render_threads(opts);
    RenderOutput out;
    out.width = W;
    out.height = H;
    out.threads = threads;
    std::atomic<bool> cancel{false};
    auto t0 = Clock::now();
    std::vector<int> cps = checkpoint_plan(opts);

    int tiles_x = (W + kTile - 1) / kTile, tiles_y = (H + kTile - 1) / kTile;
    uint64_t pixels = uint64_t(W) * uint64_t(H);
    uint64_t total = opts.seconds > 0 ? 0 : pixels * uint64_t(opts.spp);
    uint64_t done_before = 0;
    int spp_done = 0;
    double sec_per_spp = 0;
    ThreadStats stats;

    while (true) {
        int s1 = next_pass_end(opts, cps, spp_done, since(t0), sec_per_spp);
        if (s1 < 0) break;
        PassJob job;
        job.scene = &scene;
        job.integrator = &integrator;
        job.filter = &filter;
        job.film = &pass_film;
        job.seed = opts.seed;
        job.s0 = spp_done;
        job.s1 = s1;
        job.tiles_x = tiles_x;
        job.tiles_y = tiles_y;
        job.cancel = &cancel;
        job.stats.resize(threads);
        int n_tiles = tiles_x * tiles_y;
        std::mutex mu;
        std::condition_variable cv;
        std::atomic<int> running{threads};
        auto pass_t0 = Clock::now();
        std::exception_ptr error;
        auto worker = [&](int t) {
            ThreadStats local;  // thread-local: shared counters would ping-pong cache lines
            try {
                for (;;) {
                    int tile = job.next_tile.fetch_add(1);
                    if (tile >= n_tiles || cancel.load()) break;
                    render_tile(job, tile, local);
                }
            } catch (...) {  // rethrown by the calling thread (an exception may not leave a thread)
                std::lock_guard<std::mutex> lk(mu);
                if (!error) error = std::current_exception();
                cancel = true;
            }
            job.stats[t] = local;
            if (running.fetch_sub(1) == 1) {
                std::lock_guard<std::mutex> lk(mu);
                cv.notify_all();
            }
        };
        std::vector<std::thread> pool;
        try {
            for (int t = 0; t < threads; ++t) pool.emplace_back(worker, t);
        } catch (...) {
            error = std::current_exception();
            cancel = true;
        }
        // The calling thread polls progress and cancellation while workers run.
        {
            std::unique_lock<std::mutex> lk(mu);
            while (running.load() > 0 && !error) {
                cv.wait_for(lk, std::chrono::milliseconds(50));
                if (running.load() == 0) break;
                lk.unlock();
                bool go_on = true;
                try {
                    go_on = !poll || poll(done_before + job.done.load(), total);
                } catch (...) {
                    std::lock_guard<std::mutex> elk(mu);
                    if (!error) error = std::current_exception();
                    go_on = false;
                }
                if (!go_on) cancel = true;
                lk.lock();
            }
        }
        for (auto& th : pool) th.join();
        if (error) std::rethrow_exception(error);
        for (auto& s : job.stats) stats.merge(s);
        if (cancel.load()) {
            out.cancelled = true;
            break;  // the unfinished pass is dropped; finished passes stand
        }
        film.merge_and_clear(pass_film);
        double pass_sec = since(pass_t0);
        done_before += job.done.load();
        int n = s1 - spp_done;
        sec_per_spp = pass_sec / n;
        spp_done = s1;
        if (poll && !poll(done_before, total)) {
            out.cancelled = true;
        }
        if (std::binary_search(cps.begin(), cps.end(), spp_done)) {
            Checkpoint cp;
            cp.spp = spp_done;
            cp.seconds = since(t0);
            film.develop(spp_done, cp.image, cp.variance, nullptr);
            out.checkpoints.push_back(std::move(cp));
        }
        if (out.cancelled) break;
    }
    out.spp = spp_done;
    out.seconds = since(t0);
    out.stats = stats;
    film.develop(spp_done, out.image, out.variance, &out.effects);
    return out;
}

}  // namespace rm
