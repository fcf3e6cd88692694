#include "core/sh.h"

#include <cmath>

namespace rm {

namespace {
constexpr double kPiD = 3.14159265358979323846;
}

ShBasis::ShBasis(int bands) : bands_(bands), k_(size_t(bands) * size_t(bands), 0.0) {
    for (int l = 0; l < bands; ++l)
        for (int m = 0; m <= l; ++m) {
            // (l - m)! / (l + m)! as a product, which stays in range for every l.
            double ratio = 1.0;
            for (int j = l - m + 1; j <= l + m; ++j) ratio /= double(j);
            double k = std::sqrt((2.0 * l + 1.0) / (4.0 * kPiD) * ratio);
            k_[size_t(l * (l + 1) + m)] = m == 0 ? k : std::sqrt(2.0) * k;
        }
}

void ShBasis::eval(double x, double y, double z, double* out) const {
    // c_m + i s_m = (x + i y)^m; q_l = P_l^m(z) / sin^m theta, by
    // q_m^m = (2m - 1)!!, q_{m+1}^m = (2m + 1) z q_m^m and
    // (l - m) q_l^m = (2l - 1) z q_{l-1}^m - (l + m - 1) q_{l-2}^m.
    double c = 1.0, s = 0.0, qmm = 1.0;
    for (int m = 0; m < bands_; ++m) {
        if (m > 0) {
            double c1 = c * x - s * y;
            s = c * y + s * x;
            c = c1;
            qmm *= double(2 * m - 1);
        }
        double q2 = 0.0, q1 = qmm;
        for (int l = m; l < bands_; ++l) {
            double q = q1;
            if (l == m + 1)
                q = double(2 * m + 1) * z * qmm;
            else if (l > m + 1)
                q = (double(2 * l - 1) * z * q1 - double(l + m - 1) * q2) / double(l - m);
            if (l > m) q2 = q1, q1 = q;
            const int i = l * (l + 1);
            const double kq = k_[size_t(i + m)] * q;
            if (m == 0) {
                out[i] = kq;
            } else {
                out[i + m] = kq * c;
                out[i - m] = kq * s;
            }
        }
    }
}

void gauss_legendre(int n, std::vector<double>& z, std::vector<double>& w) {
    z.assign(static_cast<size_t>(n), 0.0);
    w.assign(static_cast<size_t>(n), 0.0);
    for (int i = 0; i < n; ++i) {
        // Newton's method on P_n from Tricomi's initial guess of the i-th root.
        double r = std::cos(kPiD * (i + 0.75) / (n + 0.5)), dp = 1.0;
        for (int it = 0; it < 100; ++it) {
            double p0 = 1.0, p1 = r;
            for (int k = 2; k <= n; ++k) {
                double p2 = ((2.0 * k - 1.0) * r * p1 - (k - 1.0) * p0) / k;
                p0 = p1, p1 = p2;
            }
            dp = n * (r * p1 - p0) / (r * r - 1.0);
            double step = p1 / dp;
            r -= step;
            if (std::abs(step) < 1e-15) break;
        }
        z[size_t(i)] = r;
        w[size_t(i)] = 2.0 / ((1.0 - r * r) * dp * dp);
    }
}

SphereQuadrature sphere_quadrature(int n_theta) {
    const int n = n_theta, nphi = 2 * n_theta;
    std::vector<double> z, w;
    gauss_legendre(n, z, w);
    SphereQuadrature q;
    q.dirs.reserve(size_t(n) * size_t(nphi));
    q.weights.reserve(size_t(n) * size_t(nphi));
    const double dphi = 2.0 * kPiD / nphi;
    for (int i = 0; i < n; ++i) {
        double st = std::sqrt(std::max(0.0, 1.0 - z[size_t(i)] * z[size_t(i)]));
        for (int j = 0; j < nphi; ++j) {
            double phi = (j + 0.5) * dphi;
            const double x = st * std::cos(phi), y = st * std::sin(phi);
            q.dirs.emplace_back(float(x), float(y), float(z[size_t(i)]));
            q.xyz.insert(q.xyz.end(), {x, y, z[size_t(i)]});
            q.weights.push_back(w[size_t(i)] * dphi);
        }
    }
    return q;
}

}  // namespace rm
