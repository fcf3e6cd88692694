// A work queue over `threads` threads that the calling thread polls while it
// runs: the threads of every driver (through the pass loop, pass_loop.h) and
// of the photon tracers.
#pragma once
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <exception>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

namespace rm {

// Runs fn(i, thread) for i in [0, n) on `threads` threads while the calling
// thread polls; returns false when the poll asked to cancel (the items then
// may be unfinished). Worker exceptions are rethrown here.
template <class Fn>
bool run_parallel(int threads, size_t n, Fn fn, const std::function<bool()>& poll_once, std::atomic<bool>& cancel) {
    std::atomic<size_t> next{0};
    std::atomic<int> running{threads};
    std::mutex mu;
    std::condition_variable cv;
    std::exception_ptr error;
    std::mutex error_mu;
    auto worker = [&](int t) {
        try {
            for (;;) {
                size_t i = next.fetch_add(1);
                if (i >= n || cancel.load()) break;
                fn(i, t);
            }
        } catch (...) {
            std::lock_guard<std::mutex> lk(error_mu);
            if (!error) error = std::current_exception();
            cancel = true;
        }
        if (running.fetch_sub(1) == 1) {
            std::lock_guard<std::mutex> lk(mu);
            cv.notify_all();
        }
    };
    std::vector<std::thread> pool;
    for (int t = 0; t < threads; ++t) pool.emplace_back(worker, t);
    {
        std::unique_lock<std::mutex> lk(mu);
        while (running.load() > 0) {
            cv.wait_for(lk, std::chrono::milliseconds(50));
            if (running.load() == 0) break;
            lk.unlock();
            bool go_on = true;
            try {
                go_on = poll_once();
            } catch (...) {
                std::lock_guard<std::mutex> elk(error_mu);
                if (!error) error = std::current_exception();
                go_on = false;
            }
            if (!go_on) cancel = true;
            lk.lock();
        }
    }
    for (auto& th : pool) th.join();
    if (error) std::rethrow_exception(error);
    return !cancel.load();
}

// A loop of short run_parallel calls (photon tracing's chunks, a kd-tree
// build's levels) polls between them through this gate: run_parallel
// polls only when one call outlasts its 50 ms wait, so calls that each
// finish sooner would never see a cancel (Ctrl-C during a photon pass
// came back only after the whole map was traced and built). The gate
// calls `poll` when 50 ms have passed since its last call (or its start).
class PollGate {
public:
    explicit PollGate(const std::function<bool()>& poll) : poll_(poll), last_(std::chrono::steady_clock::now()) {}
    // False when the poll asked to cancel.
    bool operator()() {
        const auto now = std::chrono::steady_clock::now();
        if (now - last_ < std::chrono::milliseconds(50)) return true;
        last_ = now;
        return !poll_ || poll_();
    }

private:
    const std::function<bool()>& poll_;
    std::chrono::steady_clock::time_point last_;
};

}  // namespace rm
