// Test-only bindings: hooks into production code for the statistical and
// unit tests (tests/), kept out of module.cpp. Each calls the code the
// estimators run (sample_light, light_pdf_w, Medium, Sensor, bdpt's MIS
// check, ParamReader) rather than a copy of it.
#include <pybind11/functional.h>

#include <algorithm>
#include <chrono>
#include <memory>

#include "bindings.h"
#include "convert.h"
#include "core/sampler.h"
#include "estimators/radiosity/radiosity.h"
#include "render/memory.h"
#include "render/pass_loop.h"
#include "render/registry.h"
#include "scene/scene.h"
#include "scene/texture.h"
#include "transport/common.h"

namespace rm::bind {

namespace {

const Medium& medium_at(const Scene& s, int m) {
    if (m < 0 || size_t(m) >= s.media.size()) throw py::index_error("no medium " + std::to_string(m));
    return *s.media[size_t(m)];
}

using PointArray = py::array_t<double, py::array::c_style | py::array::forcecast>;

// f(p) -> Color at each row of an (N, 3) array of world points: (N, 3).
template <class F>
py::array_t<float> per_point(const PointArray& pts, F f) {
    py::array_t<float> out({pts.shape(0), py::ssize_t(3)});
    auto p = pts.unchecked<2>();
    auto o = out.mutable_unchecked<2>();
    for (py::ssize_t i = 0; i < pts.shape(0); ++i) {
        Color c = f(Vec3(float(p(i, 0)), float(p(i, 1)), float(p(i, 2))));
        for (int k = 0; k < 3; ++k) o(i, k) = c[k];
    }
    return out;
}

}  // namespace

void bind_test_hooks(py::module_& m, py::class_<Scene>& scene) {
    // A texture evaluated at (N, 2) uvs (tests/test_textures.py): eval (N, 3),
    // eval_1 (N,), mean() and eval_1_grad (N, 2).
    m.def(
        "texture_eval",
        [](const TextureDesc& d, py::object uv) {
            auto u = flat<float>(uv, 2, "uv");
            std::shared_ptr<const Texture> t = make_texture(d);
            size_t n = u.size() / 2;
            std::vector<float> out(3 * n), one(n), grad(2 * n);
            for (size_t i = 0; i < n; ++i) {
                Color c = t->eval(Vec2(u[2 * i], u[2 * i + 1]));
                for (int k = 0; k < 3; ++k) out[3 * i + size_t(k)] = c[k];
                one[i] = t->eval_1(Vec2(u[2 * i], u[2 * i + 1]));
                const Vec2 g = t->eval_1_grad(Vec2(u[2 * i], u[2 * i + 1]));
                grad[2 * i] = g.x;
                grad[2 * i + 1] = g.y;
            }
            return py::make_tuple(to_numpy(std::move(out), {py::ssize_t(n), 3}),
                                  to_numpy(std::move(one), {py::ssize_t(n)}), t->mean(),
                                  to_numpy(std::move(grad), {py::ssize_t(n), 2}));
        },
        py::arg("desc"), py::arg("uv"));
    // The Embree-limit benchmark (benchmarks/studies/embree_limit.py): the
    // rays of a render recorded, then traced again bare or through ours.
    py::class_<RayLog>(m, "RayLog")
        .def(py::init<>())
        .def("__len__", [](const RayLog& l) { return l.rays.size(); })
        .def_readonly("samples", &RayLog::samples)
        .def_property_readonly("shadow_rays", [](const RayLog& l) {
            size_t n = 0;
            for (uint8_t s : l.shadow) n += s;
            return n;
        });
    m.def("set_camera_packets", &set_camera_packets, py::arg("on"),
          "camera rays in packets (default) or one at a time, for the same-bytes test");
    m.def(
        "attach_ray_log", [](RayLog* log) { attach_ray_log(log); }, py::arg("log").none(true),
        "record every ray any scene traces into `log` (None: stop); one render at a time, one thread");
    scene
        .def(
            "replay_rays",
            [](const Scene& s, const RayLog& log, bool bare, int repeats) {
                py::gil_scoped_release release;
                return s.replay(log, bare, repeats);
            },
            py::arg("log"), py::arg("bare"), py::arg("repeats") = 3)
        .def(
            "replay_rays_grouped",
            [](const Scene& s, const RayLog& log, int width, bool wavefront, bool coherent, int repeats) {
                ReplayTiming t;
                {
                    py::gil_scoped_release release;
                    t = s.replay_grouped(log, width, wavefront, coherent, repeats);
                }
                py::dict d;
                d["seconds"] = t.seconds;
                d["closest_seconds"] = t.closest_seconds;
                d["shadow_seconds"] = t.shadow_seconds;
                d["closest_hits"] = t.closest;
                d["occluded"] = t.occluded;
                d["calls"] = t.calls;
                return d;
            },
            py::arg("log"), py::arg("width"), py::arg("wavefront") = false, py::arg("coherent") = false,
            py::arg("repeats") = 3,
            "the log's rays by bare Embree: width 1, 4, 8, 16 (packets) or 0 (stream), in the log's order "
            "or queued as a wavefront renderer would (rank within each sample)")
        .def("set_robust", &Scene::set_robust, py::arg("on"))
        .def_property_readonly("robust", &Scene::robust)
        // The closest hits of N rays (origins and directions (N, 3)), as the
        // estimators see them (tests/test_textures.py compares the uv with
        // Mitsuba's): t (inf: miss), p, n, uv, the shading frame's tangent s
        // and normal ns (normal and bump maps applied), n_base (the
        // unperturbed normal in that frame), shape index (-1: miss); with
        // `texture` (a TextureDesc), its eval at each hit's SurfaceUv, "tex"
        // (tests/test_emitter_textures.py: mesh_attribute against Mitsuba's).
        .def(
            "intersect_rays",
            [](const Scene& s, py::object o, py::object d, bool packet, py::object texture) {
                if (!s.committed()) throw py::value_error("scene is not committed");
                auto oo = flat<float>(o, 3, "o"), dd = flat<float>(d, 3, "d");
                if (oo.size() != dd.size()) throw py::value_error("o and d differ in length");
                size_t n = oo.size() / 3;
                std::vector<float> t(n, kInf), p(3 * n, 0.f), nn(3 * n, 0.f), ss(3 * n, 0.f), ns(3 * n, 0.f),
                    nb(3 * n, 0.f), uv(2 * n, 0.f), shape(n, -1.f), tex(3 * n, 0.f);
                std::shared_ptr<const Texture> tx =
                    texture.is_none() ? nullptr : make_texture(texture.cast<const TextureDesc&>());
                std::vector<Ray> rays(n);
                std::vector<Interaction> its(n);
                std::unique_ptr<bool[]> hit(new bool[n]);
                for (size_t i = 0; i < n; ++i) {
                    rays[i].o = Vec3(oo[3 * i], oo[3 * i + 1], oo[3 * i + 2]);
                    rays[i].d = Vec3(dd[3 * i], dd[3 * i + 1], dd[3 * i + 2]);
                    if (!packet) hit[i] = s.intersect(rays[i], its[i]);
                }
                // With `packet`, as the camera driver traces: groups of kPacket rays.
                for (size_t i = 0; packet && i < n; i += Scene::kPacket)
                    s.intersect_packet(&rays[i], int(std::min<size_t>(Scene::kPacket, n - i)), &its[i], &hit[i]);
                for (size_t i = 0; i < n; ++i) {
                    const Interaction& it = its[i];
                    if (!hit[i]) continue;
                    t[i] = it.t;
                    for (int k = 0; k < 3; ++k) {
                        p[3 * i + size_t(k)] = it.p[k];
                        nn[3 * i + size_t(k)] = it.n[k];
                        ss[3 * i + size_t(k)] = it.sh.s[k];
                        ns[3 * i + size_t(k)] = it.sh.n[k];
                        nb[3 * i + size_t(k)] = it.n_base[k];
                    }
                    uv[2 * i] = it.uv.x;
                    uv[2 * i + 1] = it.uv.y;
                    shape[i] = float(it.shape);
                    if (tx) {
                        const Color c = tx->eval(it.uv);
                        for (int k = 0; k < 3; ++k) tex[3 * i + size_t(k)] = c[k];
                    }
                }
                py::ssize_t N = py::ssize_t(n);
                py::dict out;
                out["t"] = to_numpy(std::move(t), {N});
                out["p"] = to_numpy(std::move(p), {N, 3});
                out["n"] = to_numpy(std::move(nn), {N, 3});
                out["uv"] = to_numpy(std::move(uv), {N, 2});
                out["s"] = to_numpy(std::move(ss), {N, 3});
                out["ns"] = to_numpy(std::move(ns), {N, 3});
                out["n_base"] = to_numpy(std::move(nb), {N, 3});
                out["shape"] = to_numpy(std::move(shape), {N});
                if (tx) out["tex"] = to_numpy(std::move(tex), {N, 3});
                return out;
            },
            py::arg("o"), py::arg("d"), py::arg("packet") = false, py::arg("texture") = py::none())
        // Tests of the majorant grid (tests/test_majorant_grid.py): sigma_t
        // and the local majorant at N x 3 world points, N x 3 arrays.
        .def("medium_sigma_t",
             [](const Scene& s, int m, const PointArray& pts) {
                 const Medium& med = medium_at(s, m);
                 return per_point(pts, [&](const Vec3& p) {
                     Color st, ss;
                     med.coefficients(p, st, ss);
                     return st;
                 });
             })
        .def("medium_majorant",
             [](const Scene& s, int m, const PointArray& pts) {
                 const Medium& med = medium_at(s, m);
                 return per_point(pts, [&](const Vec3& p) { return med.majorant_at(p); });
             })
        .def("medium_has_majorant_grid", [](const Scene& s, int m) { return medium_at(s, m).has_majorant_grid(); })
        // `n` ratio-tracking estimates of the transmittance of o + d t, t in
        // [0, t1) (Medium::segment_transmittance), seeded: an n x 3 array.
        .def(
            "medium_transmittance_samples",
            [](const Scene& s, int m, py::object o, py::object d, float t1, int n, uint64_t seed) {
                const Medium& med = medium_at(s, m);
                Color oc = to_color(o), dc = to_color(d);
                Vec3 ov(oc.x, oc.y, oc.z), dv = normalize(Vec3(dc.x, dc.y, dc.z));
                py::array_t<float> out({py::ssize_t(n), py::ssize_t(3)});
                auto w = out.mutable_unchecked<2>();
                for (int i = 0; i < n; ++i) {
                    Sampler sampler(seed, 0, uint64_t(i));
                    Color tr = med.segment_transmittance(ov, dv, t1, sampler);
                    for (int c = 0; c < 3; ++c) w(i, c) = tr[c];
                }
                return out;
            },
            py::arg("medium"), py::arg("o"), py::arg("d"), py::arg("t1"), py::arg("n"), py::arg("seed") = 0)
        .def(
            "sample_emitter_direction",
            [](const Scene& s, py::object ref, py::object u, const std::string& light_sampler, py::object normal) {
                // Next event estimation's light sample (sample_light, as estimate_direct
                // takes it): u columns = (pick, u.x, u.y, u_extra); pdf includes the pick.
                // `normal`: None (a point in a medium) or one per reference point.
                if (!s.committed()) throw py::value_error("scene is not committed");
                LightSamplerUse use(s, parse_light_sampler(light_sampler));
                auto r = flat<float>(ref, 3, "ref");
                auto uu = flat<float>(u, 4, "u");
                size_t n = r.size() / 3;
                if (uu.size() != 4 * n) throw py::value_error("u must be (N, 4) for N reference points");
                std::vector<float> nn =
                    normal.is_none() ? std::vector<float>(3 * n, 0.f) : flat<float>(normal, 3, "normal");
                if (nn.size() != 3 * n) throw py::value_error("normal must be (N, 3) for N reference points");
                std::vector<float> d(3 * n), pdf(n), rad(3 * n), delta(n);
                for (size_t i = 0; i < n; ++i) {
                    if (s.emitters.empty()) continue;
                    DirectSample ds;
                    LightContext ctx{Vec3(r[3 * i], r[3 * i + 1], r[3 * i + 2]),
                                     Vec3(nn[3 * i], nn[3 * i + 1], nn[3 * i + 2])};
                    sample_light(s, ctx, uu[4 * i], Vec2(uu[4 * i + 1], uu[4 * i + 2]), uu[4 * i + 3], ds);
                    for (int k = 0; k < 3; ++k) {
                        d[3 * i + k] = ds.d[k];
                        rad[3 * i + k] = ds.radiance[k];
                    }
                    pdf[i] = ds.pdf_w * ds.pick;
                    delta[i] = ds.is_delta ? 1.f : 0.f;
                }
                py::dict out;
                py::ssize_t N = py::ssize_t(n);
                out["d"] = to_numpy(std::move(d), {N, 3});
                out["pdf"] = to_numpy(std::move(pdf), {N});
                out["radiance"] = to_numpy(std::move(rad), {N, 3});
                out["is_delta"] = to_numpy(std::move(delta), {N});
                return out;
            },
            py::arg("ref"), py::arg("u"), py::arg("light_sampler") = "uniform", py::arg("normal") = py::none())
        .def(
            "sample_sensor_rays",
            [](const Scene& s, py::object film, py::object u) {
                // Rays the sensor generates for film positions (N, 2) (pixels,
                // continuous) and extra samples u (N, 5) = (u1, u2.xy, u3.xy).
                if (!s.sensor) throw py::value_error("scene has no sensor");
                auto f = flat<float>(film, 2, "film");
                auto uu = flat<float>(u, 5, "u");
                size_t n = f.size() / 2;
                if (uu.size() != 5 * n) throw py::value_error("u must be (N, 5) for N film positions");
                std::vector<float> o(3 * n), d(3 * n), w(3 * n);
                for (size_t i = 0; i < n; ++i) {
                    SensorRay sr =
                        s.sensor->sample_ray(Vec2(f[2 * i], f[2 * i + 1]), uu[5 * i],
                                             Vec2(uu[5 * i + 1], uu[5 * i + 2]), Vec2(uu[5 * i + 3], uu[5 * i + 4]));
                    for (int k = 0; k < 3; ++k) {
                        o[3 * i + k] = sr.ray.o[k];
                        d[3 * i + k] = sr.ray.d[k];
                        w[3 * i + k] = sr.weight[k];
                    }
                }
                py::dict r;
                py::ssize_t N = py::ssize_t(n);
                r["o"] = to_numpy(std::move(o), {N, 3});
                r["d"] = to_numpy(std::move(d), {N, 3});
                r["weight"] = to_numpy(std::move(w), {N, 3});
                return r;
            },
            py::arg("film"), py::arg("u"))
        .def(
            "pdf_emitter_direction",
            [](const Scene& s, py::object ref, py::object dirs, const std::string& light_sampler, py::object normal) {
                // The light-sampling density that MIS assigns to a ray leaving ref
                // along d (light_pdf_w, as mis_emission_hit takes it); `normal`
                // as sample_emitter_direction's (one, or one per ref).
                if (!s.committed()) throw py::value_error("scene is not committed");
                LightSamplerUse use(s, parse_light_sampler(light_sampler));
                std::vector<float> nn = normal.is_none() ? std::vector<float>() : flat<float>(normal, 3, "normal");
                auto r = flat<float>(ref, 3, "ref");
                auto dd = flat<float>(dirs, 3, "d");
                size_t n = dd.size() / 3;
                bool one_ref = r.size() == 3;
                if (!one_ref && r.size() != dd.size()) throw py::value_error("ref must be (1, 3) or match d");
                std::vector<float> out(n, 0.f);
                {
                    py::gil_scoped_release nogil;
                    for (size_t i = 0; i < n; ++i) {
                        size_t j = one_ref ? 0 : i;
                        Ray ray;
                        ray.o = Vec3(r[3 * j], r[3 * j + 1], r[3 * j + 2]);
                        ray.d = normalize(Vec3(dd[3 * i], dd[3 * i + 1], dd[3 * i + 2]));
                        LightContext ctx{ray.o, Vec3(0.f)};
                        if (nn.size() >= 3 * (j + 1)) ctx.n = Vec3(nn[3 * j], nn[3 * j + 1], nn[3 * j + 2]);
                        Interaction it;
                        if (s.intersect(ray, it)) {
                            int e = s.shapes[it.shape]->emitter;
                            if (e >= 0) out[i] = light_pdf_w(s, *s.emitters[e], ctx, ray.o, &it, ray.d);
                        } else {
                            for (const Emitter* env : s.environment)
                                out[i] += light_pdf_w(s, *env, ctx, ray.o, nullptr, ray.d);
                        }
                    }
                }
                return to_numpy(std::move(out), {py::ssize_t(n)});
            },
            py::arg("ref"), py::arg("d"), py::arg("light_sampler") = "uniform", py::arg("normal") = py::none())
        .def(
            "light_selection",
            [](const Scene& s, const std::string& light_sampler, py::object ref, py::object normal, py::object u,
               bool start) {
                // Emitter selection (scene/light_sampler.h) from N points (normals: None for
                // none): the index that each u picks and its probability, and the (N, E)
                // matrix of every emitter's probability from each point. start: a light
                // path's selection (no point).
                if (!s.committed()) throw py::value_error("scene is not committed");
                const LightSampler& ls = s.light_sampler(parse_light_sampler(light_sampler));
                auto r = flat<float>(ref, 3, "ref");
                size_t n = r.size() / 3;
                std::vector<float> nn =
                    normal.is_none() ? std::vector<float>(3 * n, 0.f) : flat<float>(normal, 3, "normal");
                if (nn.size() != 3 * n) throw py::value_error("normal must be (N, 3) for N points");
                auto uu = py::array_t<float, py::array::c_style | py::array::forcecast>::ensure(u);
                if (!uu || uu.ndim() != 2 || size_t(uu.shape(0)) != n)
                    throw py::value_error("u must be (N, M): M numbers per point");
                size_t m = size_t(uu.shape(1));
                size_t ne = s.emitters.size();
                std::vector<int> idx(n * m);
                std::vector<float> pick(n * m), table(n * ne);
                for (size_t i = 0; i < n; ++i) {
                    Vec3 p(r[3 * i], r[3 * i + 1], r[3 * i + 2]), nv(nn[3 * i], nn[3 * i + 1], nn[3 * i + 2]);
                    for (size_t k = 0; k < m; ++k) {
                        float uk = uu.data()[i * m + k];
                        idx[i * m + k] =
                            start ? ls.sample_start(uk, pick[i * m + k]) : ls.sample(p, nv, uk, pick[i * m + k]);
                    }
                    for (size_t e = 0; e < ne; ++e)
                        table[i * ne + e] = start ? ls.pmf_start(int(e)) : ls.pmf(p, nv, int(e));
                }
                py::dict out;
                py::array_t<int> ia({py::ssize_t(n), py::ssize_t(m)});
                std::copy(idx.begin(), idx.end(), ia.mutable_data());
                out["index"] = ia;
                out["pick"] = to_numpy(std::move(pick), {py::ssize_t(n), py::ssize_t(m)});
                out["pmf"] = to_numpy(std::move(table), {py::ssize_t(n), py::ssize_t(ne)});
                out["nodes"] = ls.node_count();
                out["depth"] = ls.depth();
                out["bytes"] = ls.memory_bytes();
                return out;
            },
            py::arg("light_sampler"), py::arg("ref"), py::arg("normal"), py::arg("u"), py::arg("start") = false);

    m.def(
        "light_sampler_scale",
        [](py::object positions, py::object power, py::object normals, float half_size, const std::string& kind,
           int queries, uint64_t seed) {
            // The light-tree scale study (benchmarks/studies/light_tree_scale.py): a sampler
            // over N synthetic emitters (points, or one-sided squares of half-size
            // `half_size` facing `normals`), its build time, memory and depth, and the mean
            // time of one selection (sample) and one probability (pmf) from `queries`
            // random points with random normals in the emitters' box. A zero normal
            // makes that emitter a point light.
            auto pos = flat<float>(positions, 3, "positions");
            auto phi = flat<float>(power, 1, "power");
            size_t n = pos.size() / 3;
            if (phi.size() != n) throw py::value_error("power: one per position");
            std::vector<float> nn = normals.is_none() ? std::vector<float>() : flat<float>(normals, 3, "normals");
            if (!nn.empty() && nn.size() != 3 * n) throw py::value_error("normals: one per position");
            LightSamplerKind k = parse_light_sampler(kind);
            std::vector<LightBounds> b(n);
            Vec3 lo(kInf), hi(-kInf);
            for (size_t i = 0; i < n; ++i) {
                Vec3 p(pos[3 * i], pos[3 * i + 1], pos[3 * i + 2]);
                Vec3 nv = nn.empty() ? Vec3(0.f) : Vec3(nn[3 * i], nn[3 * i + 1], nn[3 * i + 2]);
                float len = length(nv);
                bool square = len > 0.f;  // a zero normal: a point light
                b[i].lo = p - Vec3(square ? half_size : 0.f);
                b[i].hi = p + Vec3(square ? half_size : 0.f);
                b[i].phi = phi[i];
                b[i].w = square ? nv / len : Vec3(0.f, 0.f, 1.f);
                b[i].cos_o = square ? 1.f : -1.f;
                b[i].cos_e = 0.f;
                lo = vmin(lo, b[i].lo);
                hi = vmax(hi, b[i].hi);
            }
            py::dict out;
            py::gil_scoped_release nogil;
            auto t0 = std::chrono::steady_clock::now();
            LightSampler ls(k, std::move(b), std::vector<bool>(n, false));
            auto t1 = std::chrono::steady_clock::now();
            Sampler sampler(seed, 0, 0);
            const size_t nq = size_t(std::max(queries, 0));
            std::vector<Vec3> qp(nq), qn(nq);
            std::vector<float> qu(nq);
            for (int q = 0; q < queries; ++q) {
                Vec3 u3(sampler.next_1d(), sampler.next_1d(), sampler.next_1d());
                qp[size_t(q)] = lo + (hi - lo) * u3;
                Vec2 u = sampler.next_2d();
                float z = 1.f - 2.f * u.x, r = std::sqrt(std::max(0.f, 1.f - z * z)), a = 2.f * kPi * u.y;
                qn[size_t(q)] = Vec3(r * std::cos(a), r * std::sin(a), z);
                qu[size_t(q)] = sampler.next_1d();
            }
            std::vector<int> picked(nq);
            double check = 0.0;
            auto t2 = std::chrono::steady_clock::now();
            for (int q = 0; q < queries; ++q) {
                float pm;
                picked[size_t(q)] = ls.sample(qp[size_t(q)], qn[size_t(q)], qu[size_t(q)], pm);
                check += pm;
            }
            auto t3 = std::chrono::steady_clock::now();
            for (int q = 0; q < queries; ++q) check += ls.pmf(qp[size_t(q)], qn[size_t(q)], picked[size_t(q)]);
            auto t4 = std::chrono::steady_clock::now();
            auto sec = [](auto a, auto b) { return std::chrono::duration<double>(b - a).count(); };
            py::gil_scoped_acquire gil;
            out["build_seconds"] = sec(t0, t1);
            out["sample_ns"] = 1e9 * sec(t2, t3) / std::max(queries, 1);
            out["pmf_ns"] = 1e9 * sec(t3, t4) / std::max(queries, 1);
            out["bytes"] = ls.memory_bytes();
            out["nodes"] = ls.node_count();
            out["depth"] = ls.depth();
            out["checksum"] = check;
            return out;
        },
        py::arg("positions"), py::arg("power"), py::arg("normals") = py::none(), py::arg("half_size") = 0.f,
        py::arg("kind") = "tree", py::arg("queries") = 100000, py::arg("seed") = 0,
        "test hook: build and query a light sampler over synthetic emitters (the light-tree scale study)");

    m.def(
        "bdpt_mis_check",
        [](const Scene& scene, const IntegratorDesc& idesc, uint64_t seed, int n) {
            if (!scene.committed()) throw py::value_error("bdpt_mis_check: scene is not committed");
            std::unique_ptr<Integrator> bdpt = make_integrator(idesc, all_effects());
            std::vector<float> fast, brute, sums;
            std::vector<int> strategy;
            {
                py::gil_scoped_release nogil;
                LightSamplerUse lights(scene, bdpt->light_sampler);
                bdpt_mis_check(scene, *bdpt, seed, n, fast, brute, sums, strategy);
            }
            return py::make_tuple(
                py::array_t<float>(fast.size(), fast.data()), py::array_t<float>(brute.size(), brute.data()),
                py::array_t<float>(sums.size(), sums.data()), py::array_t<int>(strategy.size(), strategy.data()));
        },
        py::arg("scene"), py::arg("integrator"), py::arg("seed"), py::arg("n"),
        "test hook: bdpt's MIS weights (linear-time), brute-force ones and the linear-time weights' sum over "
        "each path's strategies, for the strategies of n sample pairs");

    m.def(
        "vcm_mis_check",
        [](const Scene& scene, const IntegratorDesc& idesc, uint64_t seed, int n, int iteration, int mutation) {
            if (!scene.committed()) throw py::value_error("vcm_mis_check: scene is not committed");
            std::unique_ptr<Integrator> vcm = make_integrator(idesc, all_effects());
            std::vector<float> fast, brute, sums, own_fast, own_brute;
            std::vector<int> technique;
            {
                py::gil_scoped_release nogil;
                LightSamplerUse lights(scene, vcm->light_sampler);
                vcm_mis_check(scene, *vcm, seed, n, iteration, mutation, fast, brute, technique, sums, own_fast,
                              own_brute);
            }
            auto arr = [](const std::vector<float>& v) { return py::array_t<float>(v.size(), v.data()); };
            return py::make_tuple(arr(fast), arr(brute), py::array_t<int>(technique.size(), technique.data()),
                                  arr(sums), arr(own_fast), arr(own_brute));
        },
        py::arg("scene"), py::arg("integrator"), py::arg("seed"), py::arg("n"), py::arg("iteration") = 0,
        py::arg("mutation") = 0,
        "test hook: vcm's recursive MIS weights of every technique of each sampled path, the brute-force ones, "
        "technique codes, per-path sums and the pairs' own weights");

    m.def(
        "radiosity_solution",
        [](const Scene& scene, const IntegratorDesc& idesc, int threads) {
            if (!scene.committed()) throw py::value_error("radiosity_solution: scene is not committed");
            std::unique_ptr<Integrator> r = make_integrator(idesc, all_effects());
            RadiositySolution sol;
            {
                py::gil_scoped_release nogil;
                sol = radiosity_solution(scene, *r, threads);
            }
            auto arr = [](const std::vector<double>& v, py::ssize_t cols) {
                py::array_t<double> a({py::ssize_t(v.size()) / cols, cols});
                std::copy(v.begin(), v.end(), a.mutable_data());
                return a;
            };
            py::dict d;
            d["centre"] = arr(sol.centre, 3);
            d["normal"] = arr(sol.normal, 3);
            d["corners"] = arr(sol.corners, 12);
            d["area"] = py::array_t<double>(sol.area.size(), sol.area.data());
            d["shape"] = py::array_t<int>(sol.shape.size(), sol.shape.data());
            d["emitted"] = arr(sol.emitted, 3);
            d["direct"] = arr(sol.direct, 3);
            d["indirect"] = arr(sol.indirect, 3);
            py::dict st;
            for (const auto& kv : sol.stats) st[py::str(kv.first)] = kv.second;
            d["stats"] = st;
            return d;
        },
        py::arg("scene"), py::arg("integrator"), py::arg("threads") = 1,
        "test hook: radiosity's solved patches (centre, normal, corners (P, 12), area, shape) and per element (2p "
        "front, 2p + 1 "
        "back) the emitted, direct and indirect radiosity, with the solver's stats");

    // The unused-parameter check of a factory that reads only `reads`:
    // resolves `params` for estimator `type` against its declaration, reads
    // the parameters named in `reads` through a ParamReader and reports
    // the rest (ParamError: SceneError naming the first unread one).
    m.def(
        "param_reader_check",
        [](const std::string& type, const py::dict& params, const std::vector<std::string>& reads) {
            const EstimatorInfo* info = find_estimator(type);
            if (!info) throw py::value_error("param_reader_check: no estimator '" + type + "'");
            ParamSet resolved = resolve_params(*info, type, to_param_set(params, type));
            ParamReader reader(*info, type, resolved);
            for (const std::string& r : reads) {
                const ParamSpec* s = info->param(r);
                if (!s) throw py::value_error("param_reader_check: '" + type + "' declares no '" + r + "'");
                switch (s->type) {
                    case ParamType::Bool:
                        reader.get_bool(s->name);
                        break;
                    case ParamType::Int:
                        reader.get_int(s->name);
                        break;
                    case ParamType::Float:
                        reader.get_float(s->name);
                        break;
                    case ParamType::String:
                        reader.get_string(s->name);
                        break;
                }
            }
            reader.get_string("light_sampler");  // read by make_integrator for every estimator
            reader.report_unused();
            return from_param_set(resolved);
        },
        py::arg("type"), py::arg("params"), py::arg("reads"));

    // The memory a render may use (render/memory.h), in bytes: the machine's,
    // or `bytes` when the tests set it (0 restores the machine's), so that
    // the limit tests do not depend on the machine they run on.
    // Samplers (tests/test_samplers.py): the values samples [0, samples) of
    // `pixel` draw through Sampler, for a draw pattern (1: next_1d, 2:
    // next_2d), as the camera driver makes them: a (samples, dims) array;
    // tables=False: the plan without its tables (SamplerPlan::drop_tables).
    m.def(
        "sampler_draws",
        [](const std::string& type, int sample_count, bool jitter, uint64_t seed, int width, int height, int spp,
           uint64_t pixel, int samples, const std::vector<int>& draws, bool tables) {
            SamplerDesc d;
            d.type = type;
            d.sample_count = sample_count;
            d.jitter = jitter;
            SamplerPlan plan(d, spp, width, height, seed);
            if (!tables) plan.drop_tables();
            int dims = 0;
            for (int k : draws) {
                if (k != 1 && k != 2) throw py::value_error("sampler_draws: draws are 1 or 2");
                dims += k;
            }
            py::array_t<float> out({py::ssize_t(samples), py::ssize_t(dims)});
            auto o = out.mutable_unchecked<2>();
            for (int s = 0; s < samples; ++s) {
                PixelSampleSource source(plan, pixel, uint64_t(s));
                Sampler sampler = plan.independent() ? Sampler(seed, pixel, uint64_t(s)) : Sampler(&source);
                int c = 0;
                for (int k : draws) {
                    if (k == 1) {
                        o(s, c++) = sampler.next_1d();
                    } else {
                        Vec2 v = sampler.next_2d();
                        o(s, c++) = v.x;
                        o(s, c++) = v.y;
                    }
                }
            }
            return out;
        },
        py::arg("type"), py::arg("sample_count"), py::arg("jitter"), py::arg("seed"), py::arg("width"),
        py::arg("height"), py::arg("spp"), py::arg("pixel"), py::arg("samples"), py::arg("draws"),
        py::arg("tables") = true);
    m.def(
        "set_shading_correction_for_tests", [](bool on) { g_shading_correction.store(on, std::memory_order_relaxed); },
        py::arg("on"), "false drops the adjoint shading-normal correction (transport/common.h), for a power check");
    m.def("sobol_u32", &sobol_u32, py::arg("i"), py::arg("dim"), "Sobol dimension dim (0, 1) of index i, unscrambled");
    m.def("owen_scramble", &owen_scramble, py::arg("v"), py::arg("seed"));
    m.def("permute_index", &permute_index, py::arg("i"), py::arg("n"), py::arg("key"));
    m.def(
        "stratum_values",
        [](const std::vector<uint32_t>& strata, const std::vector<float>& offsets, uint32_t n) {
            if (strata.size() != offsets.size()) throw py::value_error("stratum_values: as many offsets as strata");
            const SizeConstants d(n);
            py::array_t<float> out(py::ssize_t(strata.size()));
            auto o = out.mutable_unchecked<1>();
            for (size_t i = 0; i < strata.size(); ++i) o(py::ssize_t(i)) = stratum_value(strata[i], offsets[i], d);
            return out;
        },
        py::arg("strata"), py::arg("offsets"), py::arg("n"), "stratum_value of each (stratum, offset) for size n");
    m.def("memory_limit", &memory_limit_bytes, "bytes of memory a render may use (render/memory.h)");
    m.def("set_memory_limit_for_tests", &set_memory_limit_override, py::arg("bytes"),
          "test hook: the memory limit of render/memory.h (0: the machine's)");
}

}  // namespace rm::bind
