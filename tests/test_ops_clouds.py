"""The cloud model (eosp.ops.clouds): the latent field's covariance in space and time, the Beta marginal of the
cloud fraction, forecasts calibrated by construction that sharpen with lead, the two ends (perfect, climatology)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from eosp.ops.clouds import (DAY_S, R_EARTH_KM, Climatology, CloudModel, cloud_fraction, default_climatology,
                             draw_field, forecast_errors, forecast_probability, success_threshold, surface_km)


def chord_km(lat1, lon1, lat2, lon2) -> float:
    return float(np.linalg.norm(surface_km([lat1], [lon1])[0] - surface_km([lat2], [lon2])[0]))


def test_the_latent_field_has_unit_variance_and_the_exponential_covariance():
    """Over 600 draws: each point's value has variance 1; two points a correlation length apart correlate at
    exp(-1), two far apart not at all; one point a correlation time apart at exp(-1)."""
    model = CloudModel(length_km=300.0, tau_h=6.0)
    rng = np.random.default_rng(0)
    lat0, lon0 = 45.0, 5.0
    dlon = math.degrees(2 * math.asin(300.0 / (2 * R_EARTH_KM)) / math.cos(math.radians(lat0)))
    pts = surface_km([lat0, lat0, lat0], [lon0, lon0 + dlon, lon0 + 60.0])
    assert chord_km(lat0, lon0, lat0, lon0 + dlon) == pytest.approx(300.0, rel=1e-3)
    draws = []
    for _ in range(600):
        f = draw_field(model, 6 * 3600.0, rng, features=400)
        xs = f.at(np.vstack([pts, pts[:1]]), np.array([0.0, 0.0, 0.0, 6 * 3600.0]))
        draws.append(xs)
    d = np.array(draws)
    assert d.var(axis=0) == pytest.approx(np.ones(4), abs=0.15)
    corr = np.corrcoef(d.T)
    assert corr[0, 1] == pytest.approx(math.exp(-1), abs=0.08)  # a correlation length apart
    assert abs(corr[0, 2]) < 0.1  # about 4,700 km apart
    assert corr[0, 3] == pytest.approx(math.exp(-1), abs=0.08)  # a correlation time apart


def test_the_cloud_fraction_has_the_beta_marginal_of_its_band():
    """F = Beta^-1(Phi(X)) at one point over many draws follows the band's Beta law (Kolmogorov-Smirnov), and an
    acquisition succeeds exactly when X is below q."""
    model = CloudModel()
    rng = np.random.default_rng(1)
    x = np.array([draw_field(model, 0.0, rng, features=50).at(surface_km([10.0], [20.0]), np.zeros(1))[0]
                  for _ in range(1500)])
    a, b = np.full(len(x), 0.6), np.full(len(x), 0.5)  # U-shaped: mostly clear or mostly overcast
    f = cloud_fraction(x, a, b)
    assert stats.kstest(f, stats.beta(0.6, 0.5).cdf).pvalue > 1e-3
    q = success_threshold(model, a, b)
    assert np.array_equal(f < model.threshold, x < q)


def test_forecasts_are_calibrated_and_sharpen_as_the_lead_shrinks():
    """Predicted against observed frequency within +/- 0.02 in every decile of the predictions, over 400,000
    acquisitions at leads from an hour to two days; the Brier score falls as the lead shrinks; perfect and
    climatology at the two ends."""
    rng = np.random.default_rng(2)
    n = 400_000
    x = rng.standard_normal(n)
    q = stats.norm.ppf(rng.uniform(0.2, 0.6, n))  # the success thresholds of many bands and months
    ok = x < q
    model = CloudModel(sigma_day=1.0)
    leads = rng.uniform(3600.0, 2 * DAY_S, n)
    p = forecast_probability(model, x, forecast_errors(model, leads[:, None], rng)[:, 0], leads, q)
    bins = np.minimum((p * 10).astype(int), 9)
    for k in range(10):
        sel = bins == k
        assert sel.sum() > 1000
        assert abs(p[sel].mean() - ok[sel].mean()) <= 0.02, k
    brier = [np.mean((forecast_probability(model, x[:50_000], forecast_errors(model, np.full((50_000, 1), lead),
                                                                               rng)[:, 0], lead, q[:50_000])
                      - ok[:50_000]) ** 2) for lead in (2 * DAY_S, DAY_S, 6 * 3600.0, 3600.0)]
    assert brier == sorted(brier, reverse=True) and brier[-1] < 0.6 * brier[0]
    perfect = forecast_probability(CloudModel(sigma_day=0.0), x, np.zeros(n), leads, q)
    assert np.array_equal(perfect, ok.astype(float))
    clim = forecast_probability(CloudModel(sigma_day=math.inf), x, np.zeros(n), leads, q)
    assert np.allclose(clim, stats.norm.cdf(q))


def test_forecast_errors_are_nested_over_the_issues():
    """One acquisition forecast at three issue times: each error's variance is sigma^2(lead), and an earlier
    (longer-lead) error is the later one plus independent noise: Cov(e(l1), e(l2)) = Var(e(min(l1, l2)))."""
    model = CloudModel(sigma_day=1.2)
    rng = np.random.default_rng(3)
    leads = np.tile(np.array([DAY_S, 6 * 3600.0, 2 * DAY_S]), (200_000, 1))
    e = forecast_errors(model, leads, rng)
    var = model.sigma_day ** 2 * leads[0] / DAY_S
    assert np.cov(e.T) == pytest.approx(np.minimum.outer(var, var), abs=0.03)
    assert np.all(forecast_errors(model, np.array([[-5.0, 0.0]]), rng) == 0.0)  # issued at or after it: no error


def test_a_climatology_from_moments_has_them():
    """Beta laws solved from a mean cloud fraction and a frequency of clear skies give both back."""
    mean = np.array([[0.4, 0.7], [0.55, 0.62]])
    clear = np.array([[0.45, 0.15], [0.3, 0.25]])
    clim = Climatology.from_moments((-90.0, 0.0, 90.0), mean, clear, 0.2, "test")
    a, b = clim.params(np.array([-10.0, -10.0, 10.0, 10.0]), np.array([1, 2, 1, 2]))
    assert a / (a + b) == pytest.approx(mean.ravel(), abs=1e-9)
    assert stats.beta.cdf(0.2, a, b) == pytest.approx(clear.ravel(), abs=1e-6)
    with pytest.raises(ValueError):
        CloudModel(threshold=1.5).validate()


def test_the_default_climatology_has_its_cited_figures():
    """Land south of 60 N: mean 0.55; north of it: 0.67; 30% of skies below a tenth of cloud in both; every month
    alike (see default_climatology: what could be cited)."""
    clim = default_climatology()
    a, b = clim.params(np.array([-30.0, 10.0, 59.9, 60.0, 75.0]), np.array([1, 7, 12, 3, 9]))
    assert a / (a + b) == pytest.approx([0.55, 0.55, 0.55, 0.67, 0.67])
    assert stats.beta.cdf(0.1, a, b) == pytest.approx(np.full(5, 0.30), abs=1e-6)
    assert (a < 1).all() and (b < 1).all()  # U-shaped: mostly clear or mostly overcast
    assert "King" in clim.source
