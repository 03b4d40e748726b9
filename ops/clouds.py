"""Clouds over a fleet's targets, and forecasts of them, specified so that they can be checked.

The field.  A latent Gaussian field X(s, t) of zero mean and unit variance, with the separable exponential
covariance ``exp(-|s - s'| / L) exp(-|t - t'| / tau)`` (|s - s'| the chord between two points of the Earth's
surface, L hundreds of km; tau hours): cloud systems are correlated over hundreds of kilometres and hours.  It is
drawn as random Fourier features: ``X(s, t) = sum over m of (a_m(t) cos(w_m . s) + b_m(t) sin(w_m . s)) /
sqrt(M)``, the frequencies w_m drawn from the exponential covariance's spectral density in three dimensions (a
multivariate t with one degree of freedom, scaled by 1/L) and each a_m, b_m an independent Ornstein-Uhlenbeck
process of correlation time tau on a time grid (:data:`TIME_STEP_S`; a query takes the grid instant at or before
it).  Given the frequencies X is exactly Gaussian with variance 1; its covariance is the exponential one up to
the features' sampling error (O(1/sqrt(M)), :data:`FEATURES` = 2,000).

The cloud fraction.  ``F = Beta^-1(Phi(X); alpha, beta)``: the latent value's rank mapped onto a Beta distribution,
so F has exactly the Beta marginal of its latitude and month (:class:`Climatology`); cloud fraction is U-shaped
(mostly clear or mostly overcast), which a mean alone does not give.  An acquisition succeeds when F at its
target and start is below the threshold (:attr:`CloudModel.threshold`): since F is increasing in X, when X is below
``q = Phi^-1(BetaCDF(threshold))``.

Forecasts.  A forecast issued at time t for an acquisition at s >= t (lead l = s - t) sees ``Y = X(target, s) +
e(l)``, an error of variance ``sigma^2(l) = sigma_day^2 * l / 1 day`` (errors grow with lead; ``sigma_day`` the
error a day ahead), and gives the success probability ``P(X < q | Y) = Phi((q - Y / (1 + sigma^2)) /
sqrt(sigma^2 / (1 + sigma^2)))``: the exact posterior, so the forecast is calibrated by construction (among
acquisitions given p, a share p succeeds).  The errors of successive forecasts of one acquisition are nested (the
later one knows all the earlier one knew: ``e(l1) = e(l2) + independent noise`` for l1 > l2), so forecasts
sharpen as the lead shrinks.  ``sigma_day = 0`` is the perfect forecast (p is 0 or 1), ``inf`` climatology only (p
= BetaCDF(threshold) of the target's latitude and month).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

R_EARTH_KM = 6371.0
TIME_STEP_S = 300.0  # the latent processes' time grid
FEATURES = 2000  # random Fourier features of the latent field
DAY_S = 86400.0


@dataclass(frozen=True)
class Climatology:
    """Beta parameters of the cloud fraction by latitude band (edges in degrees, ascending, from -90 to 90) and
    month (12 columns, January first): ``alpha[band, month]``, ``beta[band, month]``; `source` says where the
    figures come from."""

    edges_deg: tuple[float, ...]
    alpha: np.ndarray
    beta: np.ndarray
    source: str

    def params(self, lat_deg: np.ndarray, month: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """alpha and beta at each latitude and month (1-12)."""
        band = np.clip(np.searchsorted(np.asarray(self.edges_deg), np.asarray(lat_deg), side="right") - 1, 0,
                       len(self.edges_deg) - 2)
        m = np.asarray(month, dtype=np.int64) - 1
        return self.alpha[band, m], self.beta[band, m]

    @classmethod
    def from_moments(cls, edges_deg: tuple[float, ...], mean: np.ndarray, clear: np.ndarray, clear_below: float,
                     source: str) -> Climatology:
        """The Beta law of each band and month with the given mean cloud fraction and the given frequency of
        clear skies (fraction below `clear_below`), solved for by bisection on the concentration alpha + beta
        (for a fixed mean the frequency of clear skies falls as the concentration grows)."""
        from scipy.stats import beta as beta_law

        mean, clear = np.asarray(mean, dtype=np.float64), np.asarray(clear, dtype=np.float64)
        kappa = np.empty_like(mean)
        for idx in np.ndindex(mean.shape):
            m, p = float(mean[idx]), float(clear[idx])
            lo, hi = math.log(1e-3), math.log(1e3)
            for _ in range(80):
                mid = 0.5 * (lo + hi)
                k = math.exp(mid)
                if beta_law.cdf(clear_below, m * k, (1 - m) * k) > p:
                    lo = mid
                else:
                    hi = mid
            kappa[idx] = math.exp(0.5 * (lo + hi))
        return cls(tuple(edges_deg), mean * kappa, (1 - mean) * kappa, source)


def default_climatology() -> Climatology:
    """The land climatology the scenarios use unless told otherwise: two latitude bands, the same in every month.

    What could be cited here: the annual mean cloud fraction over land, 0.55 (MODIS Terra and Aqua, King, Platnick,
    Menzel, Ackerman and Hubanks, "Spatial and Temporal Distribution of Clouds Observed by MODIS Onboard the Terra
    and Aqua Satellites", IEEE TGRS 51(7), 2013, abstract); over land north of 60 N, 0.67 +/- 0.03 (the mean of 16
    climatologies, Chernokulsky and Mokhov, "Climatology of Total Cloudiness in the Arctic", Adv. Meteorol. 2012,
    542093); about 30% of land skies completely cloud-free (NASA Earth Observatory, "Cloudy Earth", 2015, Aqua
    MODIS 2002-2015), taken as the frequency of a cloud fraction below 0.1 in both bands.  Not found in what could
    be read here: land figures band by band below 60 N and month by month (the zonal and seasonal figures of King
    et al. are in the paper's plots), so the 0.55 of all land stands for every band south of 60 N and the months
    do not differ.  A finer table goes in through :meth:`Climatology.from_moments`."""
    edges = (-90.0, 60.0, 90.0)
    mean = np.repeat(np.array([[0.55], [0.67]]), 12, axis=1)
    clear = np.full((2, 12), 0.30)
    return Climatology.from_moments(edges, mean, clear, 0.1, "land: King et al. 2013 (0.55), Chernokulsky and "
                                    "Mokhov 2012 (0.67 north of 60 N), NASA Earth Observatory 2015 (30% clear)")


@dataclass(frozen=True)
class CloudModel:
    """The cloud model's parameters (see the module docstring)."""

    length_km: float = 300.0  # L: the latent field's correlation length
    tau_h: float = 6.0  # tau: its correlation time
    threshold: float = 0.2  # an acquisition succeeds below this cloud fraction at its target and start
    sigma_day: float = 1.0  # the forecast error a day ahead (latent units); 0: perfect, inf: climatology

    def validate(self) -> None:
        if not (self.length_km > 0 and self.tau_h > 0 and 0 < self.threshold < 1 and self.sigma_day >= 0):
            raise ValueError(f"cloud model: length_km > 0, tau_h > 0, 0 < threshold < 1, sigma_day >= 0 ({self})")


@dataclass(frozen=True)
class Field:
    """One draw of the latent field: its features' frequencies (M, 3; per km) and their processes on the time grid
    (K, M) each for the cosines and the sines, from time 0."""

    freq: np.ndarray
    cos_amp: np.ndarray
    sin_amp: np.ndarray
    step_s: float

    def at(self, xyz_km: np.ndarray, t_s: np.ndarray, chunk: int = 4096) -> np.ndarray:
        """X at surface points `xyz_km` (n, 3) and times `t_s` (n; seconds from the field's start, within its
        horizon), one value per row."""
        k = np.clip((np.asarray(t_s, dtype=np.float64) // self.step_s).astype(np.int64), 0, len(self.cos_amp) - 1)
        out = np.empty(len(k))
        m = self.freq.shape[0]
        for a in range(0, len(k), chunk):
            phase = xyz_km[a:a + chunk] @ self.freq.T
            out[a:a + chunk] = (np.einsum("nm,nm->n", self.cos_amp[k[a:a + chunk]], np.cos(phase))
                                + np.einsum("nm,nm->n", self.sin_amp[k[a:a + chunk]], np.sin(phase))) / math.sqrt(m)
        return out


def surface_km(lat_deg: np.ndarray, lon_deg: np.ndarray) -> np.ndarray:
    """Points of the Earth's surface (a sphere of radius :data:`R_EARTH_KM`) as (n, 3) km."""
    la, lo = np.radians(np.asarray(lat_deg, dtype=np.float64)), np.radians(np.asarray(lon_deg, dtype=np.float64))
    return R_EARTH_KM * np.stack([np.cos(la) * np.cos(lo), np.cos(la) * np.sin(lo), np.sin(la)], axis=-1)


def draw_field(model: CloudModel, horizon_s: float, rng: np.random.Generator, features: int = FEATURES) -> Field:
    """A draw of the latent field over ``[0, horizon_s]`` (see the module docstring)."""
    z = rng.standard_normal((features, 3))
    g = rng.chisquare(1, features)  # a multivariate t with one degree of freedom: z / sqrt(chi2_1)
    freq = z / np.sqrt(g)[:, None] / model.length_km
    n_steps = int(math.floor(horizon_s / TIME_STEP_S)) + 1
    rho = math.exp(-TIME_STEP_S / (model.tau_h * 3600.0))
    amps = []
    for _ in range(2):
        a = np.empty((n_steps, features))
        a[0] = rng.standard_normal(features)
        shocks = rng.standard_normal((n_steps - 1, features)) * math.sqrt(1 - rho * rho)
        for i in range(1, n_steps):
            a[i] = rho * a[i - 1] + shocks[i - 1]
        amps.append(a)
    return Field(freq, amps[0], amps[1], TIME_STEP_S)


def success_threshold(model: CloudModel, alpha: np.ndarray, beta: np.ndarray) -> np.ndarray:
    """q = Phi^-1(BetaCDF(threshold)) per acquisition: it succeeds when its latent value is below q."""
    from scipy.special import ndtri
    from scipy.stats import beta as beta_law

    return ndtri(np.clip(beta_law.cdf(model.threshold, alpha, beta), 1e-12, 1 - 1e-12))


def cloud_fraction(x: np.ndarray, alpha: np.ndarray, beta: np.ndarray) -> np.ndarray:
    """F = Beta^-1(Phi(X)) (see the module docstring)."""
    from scipy.special import ndtr
    from scipy.stats import beta as beta_law

    return beta_law.ppf(ndtr(x), alpha, beta)


def forecast_errors(model: CloudModel, leads_s: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Nested forecast errors of acquisitions at several leads: `leads_s` (n, k), each row one acquisition's leads
    at k issue times (any order; negative: issued after it, no error); returns e (n, k) with variance
    sigma^2(lead) and, along a row, ``e(l1) = e(l2) + independent`` for l1 > l2 (see the module docstring)."""
    leads = np.maximum(np.asarray(leads_s, dtype=np.float64), 0.0)
    var = model.sigma_day ** 2 * leads / DAY_S
    order = np.argsort(var, axis=1, kind="stable")
    v = np.take_along_axis(var, order, axis=1)
    steps = np.diff(np.concatenate([np.zeros((len(v), 1)), v], axis=1), axis=1)
    e_sorted = np.cumsum(rng.standard_normal(v.shape) * np.sqrt(np.maximum(steps, 0.0)), axis=1)
    out = np.empty_like(e_sorted)
    np.put_along_axis(out, order, e_sorted, axis=1)
    return out


def forecast_probability(model: CloudModel, x: np.ndarray, error: np.ndarray, lead_s: np.ndarray,
                         q: np.ndarray) -> np.ndarray:
    """P(success | Y = x + error) at lead `lead_s`: the posterior of the latent value (see the module docstring);
    climatology (``Phi(q)``) when ``sigma_day`` is infinite, 0 or 1 when the forecast is perfect or the lead 0."""
    from scipy.special import ndtr

    q = np.broadcast_to(np.asarray(q, dtype=np.float64), np.shape(x))
    if math.isinf(model.sigma_day):
        return ndtr(q)
    var = model.sigma_day ** 2 * np.maximum(np.asarray(lead_s, dtype=np.float64), 0.0) / DAY_S
    y = np.asarray(x) + np.asarray(error)
    sharp = var <= 0
    with np.errstate(divide="ignore", invalid="ignore"):
        p = ndtr((q - y / (1 + var)) / np.sqrt(var / (1 + var)))
    return np.where(sharp, (np.asarray(x) < q).astype(np.float64), p)
