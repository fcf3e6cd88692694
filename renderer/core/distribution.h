// A piecewise-constant distribution over the cells of an nx x ny grid: a
// marginal CDF over the rows and, per row, a conditional CDF over its
// columns (pbrt 3rd ed., sec. 13.6.7, "Piecewise-Constant 2D
// Distributions"; pbrt-v4's PiecewiseConstant2D), accumulated in double.
// The envmap emitter samples its cells of solid angle with it, the
// projector its image plane. Our own rather than a library's: the two
// emitters need the cell index and the position inside the cell, and the
// envmap's images must keep their bytes (the same sums in the same order).
#pragma once
#include <algorithm>
#include <vector>

#include "core/math.h"

namespace rm {

class PiecewiseConstant2D {
public:
    PiecewiseConstant2D() = default;
    // weights: ny rows of nx non-negative cell weights (row-major).
    PiecewiseConstant2D(const std::vector<double>& weights, int nx, int ny) : nx_(nx), ny_(ny) {
        cond_.assign(size_t(ny) * size_t(nx + 1), 0.0);
        marg_.assign(size_t(ny) + 1, 0.0);
        for (int j = 0; j < ny; ++j) {
            double* c = &cond_[size_t(j) * size_t(nx + 1)];
            for (int i = 0; i < nx; ++i) c[i + 1] = c[i] + weights[size_t(j) * size_t(nx) + size_t(i)];
            marg_[size_t(j) + 1] = marg_[size_t(j)] + c[nx];
        }
        total_ = marg_[size_t(ny)];
    }
    int nx() const { return nx_; }
    int ny() const { return ny_; }
    double total() const { return total_; }
    // The probability of cell (i, j): its weight over the total.
    double prob(int i, int j) const {
        const double* c = &cond_[size_t(j) * size_t(nx_ + 1)];
        return (c[i + 1] - c[i]) / total_;
    }
    // Picks cell (i, j) with probability prob(i, j) (u.y the row, u.x the
    // column) and the position (rx, ry) in [0, 1]^2 inside it; false where
    // the total is 0 or rounding lands on an empty cell.
    bool sample(Vec2 u, int& i, int& j, double& rx, double& ry, double& p) const {
        if (!(total_ > 0.0)) return false;
        double t = double(u.y) * total_;
        j = find(marg_.data(), ny_, t);
        while (j > 0 && !(marg_[size_t(j) + 1] > marg_[size_t(j)])) --j;  // skip empty rows at the top end
        double row = marg_[size_t(j) + 1] - marg_[size_t(j)];
        if (!(row > 0.0)) return false;
        ry = std::clamp((t - marg_[size_t(j)]) / row, 0.0, 1.0);
        const double* c = &cond_[size_t(j) * size_t(nx_ + 1)];
        double s = double(u.x) * c[nx_];
        i = find(c, nx_, s);
        while (i > 0 && !(c[i + 1] > c[i])) --i;
        double cell = c[i + 1] - c[i];
        if (!(cell > 0.0)) return false;
        rx = std::clamp((s - c[i]) / cell, 0.0, 1.0);
        p = cell / total_;
        return true;
    }

private:
    static int find(const double* cdf, int n, double t) {  // last k in [0, n) with cdf[k] <= t
        int k = int(std::upper_bound(cdf, cdf + n + 1, t) - cdf) - 1;
        return std::clamp(k, 0, n - 1);
    }
    int nx_ = 0, ny_ = 0;
    double total_ = 0.0;
    std::vector<double> cond_;  // per row: CDF over its columns (nx + 1 entries)
    std::vector<double> marg_;  // CDF over the rows
};

}  // namespace rm
