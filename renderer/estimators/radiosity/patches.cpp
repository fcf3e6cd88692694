#include "estimators/radiosity/patches.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <unordered_map>

namespace rm {

namespace {

constexpr double kPiD = 3.14159265358979323846;

Vec3d normalized(const Vec3d& v) {
    double l = length(v);
    return l > 0 && std::isfinite(l) ? v * (1.0 / l) : Vec3d(0, 0, 0);
}

// Twice the vector area of a polygon (Newell's method): its length is twice the area.
Vec3d polygon_normal2(const Vec3d* v, int nv) {
    Vec3d s;
    for (int i = 0; i < nv; ++i) s = s + cross(v[i], v[(i + 1) % nv]);
    return s;
}

// Chords per arc of `angle` radians: at most 2 pi / 48 each, and few
// enough that a cell's two arcs fit in Patch::kMaxCorners.
int arc_segments(double angle) {
    int n = int(std::ceil(angle / (2.0 * kPiD / 48.0) - 1e-9));
    return std::clamp(n, 1, Patch::kMaxCorners / 2 - 1);
}

int cells(double extent, double size) {
    double c = std::ceil(extent / size - 1e-9);
    if (!(c >= 1)) return 1;
    return int(std::min(c, 1e6));
}

// Mesh: the subdivision of a triangle with corners p (n from its longest edge).
int tri_subdivision(const Vec3d p[3], double size) {
    double e = std::max({length(p[1] - p[0]), length(p[2] - p[1]), length(p[0] - p[2])});
    return cells(e, size);
}

void load_tri(const Mesh& m, size_t f, Vec3d p[3]) {
    for (int j = 0; j < 3; ++j) p[j] = Vec3d(m.corner(f, j));
}

double tri_area(const Vec3d p[3]) { return 0.5 * length(cross(p[1] - p[0], p[2] - p[0])); }

// Sphere cells: z bands (equal area) by phi sectors.
// At least two bands: a single band's cells run pole to pole, and their
// polygon (the chords of the two arcs, both collapsed to a pole) is a
// segment, against which every point-to-polygon factor is 0, so a small
// sphere light's emission all escaped when its cells were the larger end
// of a pair.
void sphere_cut(const Sphere& s, double size, int& nz, int& nphi) {
    nz = std::max(2, cells(2.0 * s.r_, size));
    nphi = std::max(3, cells(2.0 * kPiD * s.r_, size));
}
// Disk cells: equal-area rings (r^2 uniform) by phi sectors; R the radius of a disk of its area.
void disk_cut(const Disk& d, double size, int& nr, int& nphi) {
    double R = std::sqrt(double(d.area()) / kPiD);
    nr = cells(R, size);
    nphi = std::max(3, cells(2.0 * kPiD * R, size));
}

}  // namespace

size_t count_patches(const Scene& scene, double size) {
    size_t total = 0;
    for (const auto& sh : scene.shapes) {
        if (const auto* m = dynamic_cast<const Mesh*>(sh.get())) {
            for (size_t f = 0; f < m->triangle_count(); ++f) {
                Vec3d p[3];
                load_tri(*m, f, p);
                if (!(tri_area(p) > 0)) continue;
                size_t n = size_t(tri_subdivision(p, size));
                total += n * n;
            }
        } else if (const auto* s = dynamic_cast<const Sphere*>(sh.get())) {
            int a, b;
            sphere_cut(*s, size, a, b);
            total += size_t(a) * size_t(b);
        } else if (const auto* d = dynamic_cast<const Disk*>(sh.get())) {
            int a, b;
            disk_cut(*d, size, a, b);
            total += size_t(a) * size_t(b);
        }
        if (total > (size_t(1) << 40)) break;
    }
    return total;
}

double patch_size_for(const Scene& scene, size_t max_patches) {
    // Bisection on log(size): the count falls as the size grows.
    Vec3 ext = scene.bbox_hi - scene.bbox_lo;
    double hi = std::max(double(max_component(ext)), 1e-30) * 4.0;  // one patch per triangle / cell minimum
    double lo = hi * 1e-6;
    if (count_patches(scene, hi) > max_patches) return hi;  // as coarse as it gets
    for (int it = 0; it < 60; ++it) {
        double mid = std::sqrt(lo * hi);
        if (count_patches(scene, mid) > max_patches)
            lo = mid;
        else
            hi = mid;
    }
    return hi;
}

PatchMesh build_patches(const Scene& scene, double size, int m) {
    PatchMesh pm;
    pm.k = m * m;
    pm.cuts.resize(scene.shapes.size());
    auto add = [&](Patch p, const Vec3d* pts, const Vec3d* nrm) {
        Vec3d n2 = polygon_normal2(p.v, p.nv);
        double pa = 0.5 * length(n2);
        p.poly_scale = pa > 0 ? p.area / pa : 1.0;
        p.first_point = uint32_t(pm.pts.size());
        for (int i = 0; i < pm.k; ++i) {
            pm.pts.push_back(pts[i]);
            pm.nrm.push_back(nrm[i]);
        }
        pm.patches.push_back(p);
    };
    std::vector<Vec3d> pts(size_t(pm.k)), nrm(size_t(pm.k));
    // Display corners of every patch (4 each; a triangle's 4th unused): the
    // point and the surface normal there, merged into vertices at the end.
    std::vector<Vec3d> cpos, cnrm;
    std::vector<char> cused;
    auto corners = [&](int nc, const Vec3d* cp, const Vec3d* cn) {
        for (int c = 0; c < 4; ++c) {
            cpos.push_back(c < nc ? cp[c] : Vec3d());
            cnrm.push_back(c < nc ? cn[c] : Vec3d());
            cused.push_back(c < nc ? 1 : 0);
        }
    };
    for (size_t si = 0; si < scene.shapes.size(); ++si) {
        const Shape* sh = scene.shapes[si].get();
        PatchMesh::ShapeCut& cut = pm.cuts[si];
        cut.base = int(pm.patches.size());
        const double flip = sh->flip_normals ? -1.0 : 1.0;
        if (const auto* mesh = dynamic_cast<const Mesh*>(sh)) {
            cut.kind = 0;
            size_t nf = mesh->triangle_count();
            cut.tri_n.assign(nf, 0);
            cut.tri_base.assign(nf, -1);
            for (size_t f = 0; f < nf; ++f) {
                Vec3d p[3];
                load_tri(*mesh, f, p);
                double A = tri_area(p);
                if (!(A > 0) || !std::isfinite(A)) continue;
                Vec3d nf_ = normalized(cross(p[1] - p[0], p[2] - p[0])) * flip;
                int n = tri_subdivision(p, size);
                cut.tri_n[f] = n;
                cut.tri_base[f] = int(pm.patches.size());
                Vec3d e1 = (p[1] - p[0]) * (1.0 / n), e2 = (p[2] - p[0]) * (1.0 / n);
                auto P = [&](double a, double b) { return p[0] + e1 * a + e2 * b; };
                // Row a: lower (a, b) for b < n - a, upper (a, b) for b < n - a - 1,
                // interleaved (PatchMesh::locate's order).
                for (int a = 0; a < n; ++a)
                    for (int b = 0; b < n - a; ++b)
                        for (int up = 0; up < 2; ++up) {
                            if (up && a + b > n - 2) continue;
                            Patch q;
                            q.shape = int(si);
                            q.nv = 3;
                            if (!up) {
                                q.v[0] = P(a, b), q.v[1] = P(a + 1, b), q.v[2] = P(a, b + 1);
                            } else {
                                q.v[0] = P(a + 1, b), q.v[1] = P(a + 1, b + 1), q.v[2] = P(a, b + 1);
                            }
                            q.area = A / (double(n) * n);
                            q.n = nf_;
                            q.c = (q.v[0] + q.v[1] + q.v[2]) * (1.0 / 3.0);
                            // m^2 centroids of the patch's own m x m subdivision.
                            Vec3d g1 = (q.v[1] - q.v[0]) * (1.0 / m), g2 = (q.v[2] - q.v[0]) * (1.0 / m);
                            int i = 0;
                            for (int s = 0; s < m; ++s)
                                for (int t = 0; t < m - s; ++t) {
                                    pts[size_t(i)] = q.v[0] + g1 * (s + 1.0 / 3.0) + g2 * (t + 1.0 / 3.0);
                                    nrm[size_t(i++)] = nf_;
                                    if (s + t <= m - 2) {
                                        pts[size_t(i)] = q.v[0] + g1 * (s + 2.0 / 3.0) + g2 * (t + 2.0 / 3.0);
                                        nrm[size_t(i++)] = nf_;
                                    }
                                }
                            add(q, pts.data(), nrm.data());
                            const Vec3d cn[3] = {nf_, nf_, nf_};
                            corners(3, q.v, cn);
                        }
            }
        } else if (const auto* sp = dynamic_cast<const Sphere*>(sh)) {
            cut.kind = 1;
            int nz, nphi;
            sphere_cut(*sp, size, nz, nphi);
            cut.n1 = nz, cut.n2 = nphi;
            Vec3d ctr(sp->cx_, sp->cy_, sp->cz_);
            double r = sp->r_;
            auto on = [&](double z, double phi) {
                double s = std::sqrt(std::max(0.0, 1.0 - z * z));
                return Vec3d(s * std::cos(phi), s * std::sin(phi), z);
            };
            for (int i = 0; i < nz; ++i)
                for (int j = 0; j < nphi; ++j) {
                    double z0 = 1.0 - 2.0 * i / nz, z1 = 1.0 - 2.0 * (i + 1) / nz;
                    double f0 = 2.0 * kPiD * j / nphi, f1 = 2.0 * kPiD * (j + 1) / nphi;
                    Patch q;
                    q.shape = int(si);
                    // Top arc (z0) from f0 to f1, bottom arc (z1) back: chains of
                    // chords; at a pole the top or bottom points coincide.
                    const int seg = arc_segments(f1 - f0);
                    Vec3d c[Patch::kMaxCorners];
                    int nc = 0;
                    for (int t = 0; t <= seg; ++t) c[nc++] = on(z0, f0 + (f1 - f0) * t / seg);
                    for (int t = seg; t >= 0; --t) c[nc++] = on(z1, f0 + (f1 - f0) * t / seg);
                    int nv = 0;
                    for (int t = 0; t < nc; ++t) {
                        Vec3d w = ctr + c[t] * r;
                        if (nv > 0 && length(w - q.v[nv - 1]) <= 1e-12 * r) continue;
                        q.v[nv++] = w;
                    }
                    while (nv > 1 && length(q.v[nv - 1] - q.v[0]) <= 1e-12 * r) --nv;
                    q.nv = nv;
                    q.area = r * r * (z0 - z1) * (f1 - f0);
                    Vec3d dc = on(0.5 * (z0 + z1), 0.5 * (f0 + f1));
                    q.c = ctr + dc * r;
                    q.n = dc * flip;
                    int t = 0;
                    for (int a = 0; a < m; ++a)
                        for (int b = 0; b < m; ++b) {
                            Vec3d d = on(z0 + (z1 - z0) * (a + 0.5) / m, f0 + (f1 - f0) * (b + 0.5) / m);
                            pts[size_t(t)] = ctr + d * r;
                            nrm[size_t(t++)] = d * flip;
                        }
                    add(q, pts.data(), nrm.data());
                    Vec3d cp[4], cn[4];
                    for (int c = 0; c < 4; ++c) {
                        Vec3d d = on(c < 2 ? z0 : z1, c % 2 ? f1 : f0);
                        cp[c] = ctr + d * r;
                        cn[c] = d * flip;
                    }
                    corners(4, cp, cn);
                }
        } else if (const auto* dk = dynamic_cast<const Disk*>(sh)) {
            cut.kind = 2;
            int nr, nphi;
            disk_cut(*dk, size, nr, nphi);
            cut.n1 = nr, cut.n2 = nphi;
            Vec3d nd = normalized(Vec3d(dk->xf_.normal(Vec3(0, 0, 1)))) * flip;
            auto at = [&](double rr, double phi) {
                return Vec3d(dk->xf_.point(Vec3(float(rr * std::cos(phi)), float(rr * std::sin(phi)), 0.f)));
            };
            double A = double(dk->area());
            for (int i = 0; i < nr; ++i)
                for (int j = 0; j < nphi; ++j) {
                    double r0 = std::sqrt(double(i) / nr), r1 = std::sqrt(double(i + 1) / nr);
                    double f0 = 2.0 * kPiD * j / nphi, f1 = 2.0 * kPiD * (j + 1) / nphi;
                    Patch q;
                    q.shape = int(si);
                    const int seg = arc_segments(f1 - f0);
                    int nv = 0;
                    if (i == 0) {
                        q.v[nv++] = at(0, 0);
                    } else {
                        for (int t = seg; t >= 0; --t) q.v[nv++] = at(r0, f0 + (f1 - f0) * t / seg);
                    }
                    for (int t = 0; t <= seg; ++t) q.v[nv++] = at(r1, f0 + (f1 - f0) * t / seg);
                    q.nv = nv;
                    q.area = A / (double(nr) * nphi);
                    q.c = at(std::sqrt((i + 0.5) / nr), 0.5 * (f0 + f1));
                    q.n = nd;
                    int t = 0;
                    for (int a = 0; a < m; ++a)
                        for (int b = 0; b < m; ++b) {
                            double rr = std::sqrt((i + (a + 0.5) / m) / nr);
                            pts[size_t(t)] = at(rr, f0 + (f1 - f0) * (b + 0.5) / m);
                            nrm[size_t(t++)] = nd;
                        }
                    add(q, pts.data(), nrm.data());
                    Vec3d cp[4], cn[4];
                    for (int c = 0; c < 4; ++c) {
                        cp[c] = at(c < 2 ? r0 : r1, c % 2 ? f1 : f0);
                        cn[c] = nd;
                    }
                    corners(4, cp, cn);
                }
        } else {
            throw std::invalid_argument("shape '" + sh->id + "': no patches for this kind of shape");
        }
    }
    // Merge the corners into vertices: a hash grid of cell `tol`, each
    // corner looked up in its cell and the 26 around it.
    const double tol = 1e-5 * size;
    pm.corner_vertex.assign(cpos.size(), -1);
    std::vector<Vec3d>&vpos = pm.vpos, &vnrm = pm.vnrm;
    std::vector<int> vshape;
    std::unordered_map<uint64_t, std::vector<int>> grid;
    auto cell = [&](double x) { return int64_t(std::floor(x / tol)); };
    auto key = [](int64_t a, int64_t b, int64_t c) {
        return uint64_t(a) * 0x9E3779B97F4A7C15ull ^ uint64_t(b) * 0xC2B2AE3D27D4EB4Full ^
               uint64_t(c) * 0x165667B19E3779F9ull;
    };
    for (size_t c = 0; c < cpos.size(); ++c) {
        if (!cused[c]) continue;
        const Vec3d& p = cpos[c];
        if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z)) continue;
        const int shape = pm.patches[c / 4].shape;
        const int64_t ix = cell(p.x), iy = cell(p.y), iz = cell(p.z);
        int found = -1;
        for (int dx = -1; dx <= 1 && found < 0; ++dx)
            for (int dy = -1; dy <= 1 && found < 0; ++dy)
                for (int dz = -1; dz <= 1 && found < 0; ++dz) {
                    auto hit = grid.find(key(ix + dx, iy + dy, iz + dz));
                    if (hit == grid.end()) continue;
                    for (int v : hit->second)
                        if (vshape[size_t(v)] == shape && length(vpos[size_t(v)] - p) <= tol &&
                            dot(vnrm[size_t(v)], cnrm[c]) >= 1.0 - 1e-6) {
                            found = v;
                            break;
                        }
                }
        if (found < 0) {
            found = int(vpos.size());
            vpos.push_back(p);
            vnrm.push_back(cnrm[c]);
            vshape.push_back(shape);
            grid[key(ix, iy, iz)].push_back(found);
        }
        pm.corner_vertex[c] = found;
    }
    pm.vertex_count = vpos.size();
    return pm;
}

int PatchMesh::locate(const Scene& scene, const Interaction& it) const {
    double w[4];
    return locate(scene, it, w);
}

int PatchMesh::locate(const Scene& scene, const Interaction& it, double wt[4]) const {
    wt[0] = 1, wt[1] = wt[2] = wt[3] = 0;
    // Bilinear weights of a cell's corners (z0 or r0 first, then phi) at
    // fractions fi, fj of the cell.
    auto bilinear = [&](double fi, double fj) {
        fi = std::clamp(fi, 0.0, 1.0), fj = std::clamp(fj, 0.0, 1.0);
        wt[0] = (1 - fi) * (1 - fj), wt[1] = (1 - fi) * fj, wt[2] = fi * (1 - fj), wt[3] = fi * fj;
    };
    if (it.shape < 0 || size_t(it.shape) >= cuts.size()) return -1;
    const ShapeCut& cut = cuts[size_t(it.shape)];
    const Shape* sh = scene.shapes[size_t(it.shape)].get();
    if (cut.kind == 0) {
        if (it.prim < 0 || size_t(it.prim) >= cut.tri_n.size() || cut.tri_base[size_t(it.prim)] < 0) return -1;
        const auto* mesh = static_cast<const Mesh*>(sh);
        const int n = cut.tri_n[size_t(it.prim)];
        Vec3d p0(mesh->corner(size_t(it.prim), 0)), p1(mesh->corner(size_t(it.prim), 1)),
            p2(mesh->corner(size_t(it.prim), 2));
        // Barycentrics of the hit by least squares in the triangle's plane.
        Vec3d e1 = p1 - p0, e2 = p2 - p0, w = Vec3d(it.p) - p0;
        double a11 = dot(e1, e1), a12 = dot(e1, e2), a22 = dot(e2, e2), det = a11 * a22 - a12 * a12;
        double b1 = 0, b2 = 0;
        if (det > 0) {
            b1 = (a22 * dot(w, e1) - a12 * dot(w, e2)) / det;
            b2 = (a11 * dot(w, e2) - a12 * dot(w, e1)) / det;
        }
        double u = std::clamp(b1, 0.0, 1.0) * n, v = std::clamp(b2, 0.0, 1.0) * n;
        int a = std::clamp(int(std::floor(u)), 0, n - 1);
        int b = std::clamp(int(std::floor(v)), 0, n - 1 - a);
        int up = (u - a) + (v - b) > 1.0 && a + b <= n - 2 ? 1 : 0;
        // Barycentric weights of the sub-triangle's corners (build_patches'
        // order): lower (a, b), (a + 1, b), (a, b + 1); upper (a + 1, b),
        // (a + 1, b + 1), (a, b + 1).
        const double s = u - a, t = v - b;
        if (!up) {
            wt[0] = 1 - s - t, wt[1] = s, wt[2] = t;
        } else {
            wt[0] = 1 - t, wt[1] = s + t - 1, wt[2] = 1 - s;
        }
        double sum = 0;
        for (int c = 0; c < 3; ++c) sum += (wt[c] = std::max(0.0, wt[c]));
        if (sum > 0)
            for (int c = 0; c < 3; ++c) wt[c] /= sum;
        else
            wt[0] = 1, wt[1] = wt[2] = 0;
        return cut.tri_base[size_t(it.prim)] + a * (2 * n - a) + 2 * b + up;
    }
    if (cut.kind == 1) {
        const auto* sp = static_cast<const Sphere*>(sh);
        double x = it.p.x - sp->cx_, y = it.p.y - sp->cy_, z = it.p.z - sp->cz_;
        double l = std::sqrt(x * x + y * y + z * z);
        if (!(l > 0)) return cut.base;
        double zz = std::clamp(z / l, -1.0, 1.0);
        double phi = std::atan2(y, x);
        if (phi < 0) phi += 2.0 * kPiD;
        int i = std::clamp(int((1.0 - zz) * 0.5 * cut.n1), 0, cut.n1 - 1);
        int j = std::clamp(int(phi / (2.0 * kPiD) * cut.n2), 0, cut.n2 - 1);
        bilinear((1.0 - zz) * 0.5 * cut.n1 - i, phi / (2.0 * kPiD) * cut.n2 - j);
        return cut.base + i * cut.n2 + j;
    }
    const auto* dk = static_cast<const Disk*>(sh);
    Vec3 q = dk->xf_.inv_point(it.p);
    double r2 = double(q.x) * q.x + double(q.y) * q.y;
    double phi = std::atan2(double(q.y), double(q.x));
    if (phi < 0) phi += 2.0 * kPiD;
    int i = std::clamp(int(r2 * cut.n1), 0, cut.n1 - 1);
    int j = std::clamp(int(phi / (2.0 * kPiD) * cut.n2), 0, cut.n2 - 1);
    bilinear(r2 * cut.n1 - i, phi / (2.0 * kPiD) * cut.n2 - j);
    return cut.base + i * cut.n2 + j;
}

}  // namespace rm
