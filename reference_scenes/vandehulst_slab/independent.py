"""An independent answer for vandehulst_slab: analog Monte Carlo of photon
transport in a plane-parallel slab (optical thickness 2, albedo 0.9,
Henyey-Greenstein g = 0.75, normal incidence, index-matched boundaries), in
numpy, sharing nothing with Mitsuba or radiometer. Survival is carried as a
weight (w *= albedo at each scattering, the expected value of analog
absorption); photons below weight 1e-6 are dropped (bias < 1e-6).

    python reference_scenes/vandehulst_slab/independent.py [photons]

prints the diffuse transmittance T_d (photons that left through the bottom
after at least one scattering: what the scene's irradiancemeter measures,
since a sensor ray never sees the directional light directly), the
unscattered transmittance (exp(-2) exactly) and the reflectance, each with
its standard error over 10 independent batches. van de Hulst's tables give
R = 0.09739 and T = 0.66096 (T_d = T - exp(-2) = 0.52562) for this slab;
measured with 4e7 photons (seed 1): T_d = 0.52561 +- 0.00004,
R = 0.09743 +- 0.00003, unscattered 0.13529 +- 0.00006.
"""
import sys

import numpy as np

TAU, ALBEDO, G = 2.0, 0.9, 0.75


def batch(n, rng):
    z = np.zeros(n)  # depth below the lit face, in mean free paths
    mu = np.ones(n)  # direction cosine (downwards positive)
    w = np.ones(n)
    scattered = np.zeros(n, bool)
    alive = np.ones(n, bool)
    t_d = t_0 = r = 0.0
    while alive.any():
        i = np.nonzero(alive)[0]
        zn = z[i] + mu[i] * -np.log1p(-rng.random(i.size))  # free flight, exponential (mean 1 / sigma_t)
        out_b, out_t = zn >= TAU, zn <= 0.0
        t_d += w[i][out_b & scattered[i]].sum()
        t_0 += w[i][out_b & ~scattered[i]].sum()
        r += w[i][out_t].sum()
        alive[i[out_b | out_t]] = False
        j = i[~(out_b | out_t)]
        z[j] = zn[~(out_b | out_t)]
        w[j] *= ALBEDO
        # Henyey-Greenstein deflection cosine (inverse CDF, g relative to the
        # propagation direction), then rotate the direction cosine about z.
        u = rng.random(j.size)
        s_ = (1 - G * G) / (1 - G + 2 * G * u)
        ct = np.clip((1 + G * G - s_ * s_) / (2 * G), -1.0, 1.0)
        phi = 2 * np.pi * rng.random(j.size)
        m = mu[j]
        mu[j] = np.clip(m * ct + np.sqrt(np.maximum(0.0, 1 - m * m)) * np.sqrt(np.maximum(0.0, 1 - ct * ct))
                        * np.cos(phi), -1.0, 1.0)
        scattered[j] = True
        alive &= w >= 1e-6
    return t_d / n, t_0 / n, r / n


def main(photons=40_000_000, batches=10, seed=1):
    rng = np.random.default_rng(seed)
    res = np.array([batch(photons // batches, rng) for _ in range(batches)])
    mean, se = res.mean(0), res.std(0, ddof=1) / np.sqrt(batches)
    for name, m, s in zip(("diffuse transmittance T_d", "unscattered transmittance", "reflectance R"), mean, se):
        print(f"{name}: {m:.5f} +- {s:.5f}")
    return mean, se


if __name__ == "__main__":
    main(int(float(sys.argv[1])) if len(sys.argv) > 1 else 40_000_000)
