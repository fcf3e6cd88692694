#include "render/memory.h"

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cstdio>
#include <fstream>
#include <stdexcept>

#include "film/film.h"
#include "photon/photon_map.h"

namespace rm {

namespace {

std::atomic<double> g_override{0.0};

double physical_bytes() {
    long pages = sysconf(_SC_PHYS_PAGES), page = sysconf(_SC_PAGE_SIZE);
    return pages > 0 && page > 0 ? double(pages) * double(page) : 0.0;
}

// cgroup v2's memory.max of this process's group ("max": no limit); 0 when none.
double cgroup_bytes() {
    std::ifstream f("/sys/fs/cgroup/memory.max");
    std::string s;
    if (!(f >> s) || s.empty() || s == "max") return 0.0;
    try {
        return std::stod(s);
    } catch (...) {
        return 0.0;
    }
}

}  // namespace

std::string format_bytes(double bytes) {
    char buf[32];
    if (bytes >= double(1ull << 30))
        std::snprintf(buf, sizeof buf, "%.3g GiB", bytes / double(1ull << 30));
    else if (bytes >= double(1ull << 20))
        std::snprintf(buf, sizeof buf, "%.3g MiB", bytes / double(1ull << 20));
    else
        std::snprintf(buf, sizeof buf, "%.3g KiB", bytes / 1024.0);
    return buf;
}

double memory_limit_bytes() {
    double o = g_override.load();
    if (o > 0) return o;
    double phys = physical_bytes(), cg = cgroup_bytes();
    return cg > 0 && (phys <= 0 || cg < phys) ? cg : phys;
}

void set_memory_limit_override(double bytes) { g_override.store(bytes > 0 ? bytes : 0.0); }

void check_memory(const std::string& integrator, int width, int height, const std::vector<MemoryPart>& parts) {
    const double limit = memory_limit_bytes();
    double total = 0;
    for (const MemoryPart& p : parts) total += p.bytes;
    if (!(limit > 0) || total <= limit) return;
    std::string list;
    const MemoryPart* largest = nullptr;
    for (const MemoryPart& p : parts) {
        if (!(p.bytes > 0)) continue;
        if (!list.empty()) list += ", ";
        list += p.what + " " + format_bytes(p.bytes);
        if (!largest || p.bytes > largest->bytes) largest = &p;
    }
    throw std::invalid_argument("render: integrator '" + integrator + "' on a " + std::to_string(width) + "x" +
                                std::to_string(height) + " film needs " + format_bytes(total) + " (" + list +
                                "), more than this machine's " + format_bytes(limit) + " of memory; lower " +
                                (largest ? largest->param : std::string("the resolution")));
}

MemoryPart output_memory(const RenderOptions& opts, int width, int height) {
    const double pixels = double(width) * double(height);
    // image and variance, kNumEffects effect images; a checkpoint keeps an image and a variance
    const double floats = 3.0 * (2 + kNumEffects) + 6.0 * double(opts.checkpoints.size());
    return {"output images", pixels * floats * sizeof(float),
            opts.checkpoints.empty() ? "the resolution (film width, height)"
                                     : "the resolution (film width, height) or the number of checkpoints"};
}

MemoryPart camera_film_memory(int width, int height, bool effect_variance) {
    // Two films (film.h) of sums, squares and kNumEffects effect sums (and
    // their squares with effect_variance), 3 doubles each.
    const double pixels = double(width) * double(height);
    const double per_pixel = 2 + kNumEffects * (effect_variance ? 2 : 1);
    return {"accumulation films", 2.0 * pixels * 3.0 * per_pixel * sizeof(double),
            "the resolution (film width, height)"};
}

double photon_map_build_bytes(double photons) {
    // The larger of two peaks: while tracing, the work items' photons and
    // the array they are joined into (photon_trace.cpp); while building,
    // that array (reordered in place) and the build's keys and axes.
    const double per = double(PhotonMap::bytes_per_photon());
    return photons * std::max(2.0 * per, per + double(PhotonMap::build_bytes_per_photon()));
}

}  // namespace rm
