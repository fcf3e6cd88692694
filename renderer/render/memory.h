// The one memory check of every render, made before its buffers are
// allocated: each driver (camera, light, photonmapper, sppm) lists what it
// will allocate, and check_memory refuses the render when the sum exceeds
// the machine's memory, naming the estimate, the machine's memory and the
// parameter that sizes the largest part. Better a clear error up front
// than a std::bad_alloc, or the OOM killer, an hour into a render.
#pragma once
#include <string>
#include <vector>

#include "render/render.h"

namespace rm {

// One buffer (or group of buffers) a render allocates.
struct MemoryPart {
    std::string what;   // "accumulation films", "global photon map (250000 photons)"
    double bytes = 0;   // estimated peak bytes
    std::string param;  // what sizes it: "the resolution (film width, height)", "global_photons"
};

// The memory a render may use: the machine's physical memory
// (sysconf(_SC_PHYS_PAGES) * sysconf(_SC_PAGE_SIZE)), or the cgroup v2
// limit of the process's container when that is lower. Not MemAvailable:
// whether a render is refused must depend on the machine and the inputs,
// not on what other processes happen to hold at the moment (the same
// command would pass or fail by chance), and what is cached or swapped out
// can be reclaimed. 0 when unknown (then nothing is refused).
double memory_limit_bytes();
// Tests only: use `bytes` as the limit instead (0: the machine's again).
void set_memory_limit_override(double bytes);

// Throws std::invalid_argument when the parts' sum exceeds
// memory_limit_bytes(): "render: integrator 'sppm' on a WxH film needs
// X GiB (part a, part b, ...), more than this machine's Y GiB of memory;
// lower <param of the largest part>".
void check_memory(const std::string& integrator, int width, int height, const std::vector<MemoryPart>& parts);

// Bytes as "12.3 GiB" (three digits; MiB, KiB below a GiB).
std::string format_bytes(double bytes);

// The output every driver develops (pass_loop.h): image, variance and the
// effect images, and each checkpoint's image and variance.
MemoryPart output_memory(const RenderOptions& opts, int width, int height);

// The camera driver's two films (finished passes, the pass in flight).
MemoryPart camera_film_memory(int width, int height, bool effect_variance = false);

// Peak bytes of a photon map of n photons while it is traced and built
// (photon_trace.cpp: the work items' photons and the joined array;
// photon_map.h: the array, reordered in place, its keys and axes).
double photon_map_build_bytes(double photons);

}  // namespace rm
