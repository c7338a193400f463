"""The surfaces' reflectance and the sensor's response, fitted jointly by differentiating the
``lidar`` plugin's own return model with Dr.Jit.

For a training sample (:mod:`.observations`) of laser ``l`` hitting the surfaces at range
``d`` with incidence cosine ``cos θ``, the plugin's model in ``compensated`` mode without
extinction gives

    E = G_l · ρ(x) · cos θ · r(d) · m_l(d)    (:func:`nidar_mi.lidar.return_model.expected_intensity`
                                               times :func:`~nidar_mi.lidar.return_model.range_response`)

with ``ρ(x)`` read by the surfaces' BSDF (a ``mesh_attribute`` texture interpolating the
per-vertex ``vertex_rho``; :func:`nidar_mi.lidar.raycast.monostatic_reflectance`), ``G_l`` the
per-laser gain (``laser_gains``), ``r(d)`` the range response (``range_response``: piecewise
linear through :data:`KNOTS_M`) and ``m_l(d)`` laser ``l``'s own factor through the same knots
(``laser_range_response``: each laser of a real unit compensates range its own way, as an
HDL-64E's per-laser focal distance and slope do). The sensor reports ``max(E - b, 0)``
(``intensity_offset`` b: an encoding that reads 0 below it, as KITTI's HDL-64E does for about
a quarter of its returns) and detects a return with probability ``(1 - q) · Φ((E - T) / σ_n)``
(``detection_threshold``, ``receiver_noise_std``,
:func:`~nidar_mi.lidar.return_model.detection_probability`; ``dropout`` q: the returns lost
whatever their intensity, through glass, past an object's edge, as the plugin drops them).

The loss, minimised with :class:`mitsuba.ad.Adam` on the gradients of ``dr.backward``:

* intensity: mean over returns of ``(max(E - b, 0) - y)²``, where a return read as 0 counts
  only when ``E - b`` exceeds 0 (it says ``E <= b``, nothing more);
* detection: ``w_det`` times the mean binary cross-entropy of ``(1 - q) Φ((E - T)/σ_n)``
  against hit/miss over the detection samples;
* smoothness: ``w_smooth`` times the mean of ``(ρ_a - ρ_b)²`` over the mesh's edges (the prior
  where the data are thin);
* prior: ``w_prior`` times the mean of ``(ρ_v - s·R_v)²`` over the vertices that NIDAR's
  reflectance ``R`` sees (``s`` the median ratio of the fitted ρ to R, refreshed every step),
  weighted by how rarely the LiDAR hit the vertex.

The alternating least squares that starts the fit (:func:`alternate`) solves its last ρ through
the surfaces' interpolation, as the renderer reads it, with the mesh's edges as a prior where
the samples are few (``FitOptions.rho_smooth``, :mod:`.vertex_rho`). It carries a smoothness
prior on the range response's knot values (``FitOptions.response_smooth``): where a drive sees
each surface from about one range, ρ and ``r(d)`` trade off freely. It also fits the per-laser
factors ``m_l`` (``FitOptions.laser_response``), each laser's knot values drawn to 1 and to
their neighbours' (``FitOptions.laser_shape_prior``); the gradient fit keeps them.

Scale: ``ρ`` and the sensor's gains trade off (``G·ρ``), so the gains are normalised to a
geometric mean of 1, ``r`` and every ``m_l`` to 1 at :data:`REFERENCE_M`, and at each knot the
``m_l`` to a geometric mean of 1 over the lasers; ρ is thus the intensity a surface
gives at normal incidence at that range with the average laser (KITTI's [0, 1] scale).
Without per-laser gains (``per_laser=False``) every ``G_l`` and ``m_l`` stays 1.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .observations import Samples
from .vertex_rho import harmonic_fill, interpolated_rho

__all__ = [
    "FitOptions",
    "SensorFit",
    "KNOTS_M",
    "REFERENCE_M",
    "fit_drive",
    "edges_of",
    "predict_returns",
    "alternate",
    "sensor_samples",
    "harmonic_fill",
    "detection_start",
    "laser_factor",
    "DROPOUTS",
]

#: Knots of the fitted range response, m; the response is 1 at REFERENCE_M.
KNOTS_M = (2.0, 4.0, 7.0, 10.0, 15.0, 20.0, 30.0, 45.0, 70.0, 120.0)
REFERENCE_M = 10.0
#: The largest fitted reflectance.
RHO_MAX = 4.0
#: The dropouts the ray-drop start tries (:func:`detection_start`), and the largest fitted.
DROPOUTS = (0.0, 0.01, 0.02, 0.03, 0.05, 0.07, 0.1, 0.15, 0.2, 0.3)
DROPOUT_MAX = 0.9
#: The bounds of a laser's own range factor m_l at a knot, during the alternation.
SHAPE_MIN, SHAPE_MAX = 0.25, 4.0
#: Rounds of the alternating least squares and the over-relaxation of its gains' step.
ALS_ROUNDS = 100
ALS_RELAX = 1.8


@dataclass(frozen=True)
class FitOptions:
    """Settings of the inversion (defaults used on the real drives)."""

    iterations: int = 40
    lr_rho: float = 0.001
    lr_sensor: float = 0.01
    lr_gains: float = 0.0002
    w_det: float = 0.02
    w_smooth: float = 0.2
    w_prior: float = 0.05
    per_laser: bool = True
    fit_response: bool = True
    fit_offset: bool = True
    fit_dropout: bool = True
    response_smooth: float = 1.0
    laser_response: bool = True
    laser_shape_prior: float = 0.1
    rho_smooth: float | None = 0.1


@dataclass
class SensorFit:
    """The recovered sensor and the fit's record.

    Attributes:
        gains: (R,) per-laser gains (geometric mean 1).
        knots_m, response: the range response r(d) at the knots.
        offset: the intensity offset b.
        threshold, noise: T and σ_n of detection.
        dropout: q, the share of returns lost whatever their intensity.
        history: per iteration the loss terms.
        laser_response: (R, K) each laser's factor m_l at the knots, or None (all 1).
    """

    gains: np.ndarray
    knots_m: tuple[float, ...]
    response: np.ndarray
    offset: float
    threshold: float
    noise: float
    dropout: float = 0.0
    history: list[dict] = field(default_factory=list)
    laser_response: np.ndarray | None = None

    def response_at(self, d, ring=None):
        """r(d), times ``m_l(d)`` of each return's laser ``ring`` where the fit has them
        (NumPy; ``d`` and ``ring`` of one shape)."""
        from ..lidar.return_model import range_response

        d = np.asarray(d, dtype=np.float64)
        out = range_response(d, self.knots_m, list(self.response))
        if ring is None or self.laser_response is None:
            return out
        rows = self.laser_response[np.asarray(ring, dtype=np.int64)]
        return out * range_response(d, self.knots_m, list(np.moveaxis(rows, -1, 0)))

    def reflectance_of(self, y, ring, d, cos) -> np.ndarray:
        """ρ that one detected return's intensity ``y`` says its surface has, in [0, RHO_MAX].

        The sensor reports ``max(E − b, 0)`` with ``E = G_l · ρ · cos θ · r(d)``, so ``E = y +
        b``; but a return read as 0 says only ``E <= b``, and a return was detected, so ``E``
        is taken no lower than twice the threshold ``T``: the expected scan detects it again
        from poses where ``cos θ · r(d)`` is down to half, and reads it as about 0 (``T`` is
        where the fit puts it, near 0, when ``b <= T``; above ``T`` the offset already holds
        ``E = b``). ``ρ = max(y + b, 2 T) / (G_l · r(d) · cos θ)`` (RHO_MAX where the
        denominator is 0). All (N,): ``y`` on the sensor's scale, ``ring`` its laser, ``d``
        range (m), ``cos`` = ``|cos θ|``."""
        ring = np.asarray(ring, dtype=np.int64)
        unit = self.gains[ring] * self.response_at(d, ring) * np.asarray(cos, np.float64)
        floor = 2.0 * self.threshold
        num = np.maximum(np.asarray(y, np.float64) + self.offset, floor)
        rho = np.where(unit > 0, num / np.where(unit > 0, unit, 1.0), RHO_MAX)
        return np.clip(rho, 0.0, RHO_MAX)


def edges_of(faces: np.ndarray) -> np.ndarray:
    """(E, 2) the unique undirected edges of (T, 3) triangles."""
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    e = np.sort(e, axis=1)
    return np.unique(e, axis=0)


def hit_reflectance(samples: Samples, rho):
    """ρ at each sample's hit: the barycentric interpolation of the per-vertex ``rho`` (Dr.Jit,
    differentiable in ``rho``), as the surfaces' ``mesh_attribute`` texture computes it."""
    import drjit as dr
    import mitsuba as mi

    return sum(w * dr.gather(mi.Float, rho, c) for w, c in zip(samples.weights, samples.corners))


def laser_factor(samples: Samples, shape: np.ndarray | None):
    """``m_l(d)`` of every sample (``mi.Float`` (S,)), from (R, K) per-laser knot values
    ``shape`` (None: 1)."""
    import mitsuba as mi

    from ..lidar.return_model import range_response

    if shape is None:
        return mi.Float(1.0)
    rows = np.asarray(shape, dtype=np.float64)[samples.ring.numpy().astype(np.int64)]
    m = range_response(samples.range_m.astype(np.float64), KNOTS_M, list(rows.T))
    return mi.Float(m.astype(np.float32))


def _expected(samples: Samples, rho, gains, response, sensor_rows=None, factor=1.0):
    """E of every sample (Dr.Jit), differentiable in ρ, the gains and the response;
    ``sensor_rows`` (``mi.Bool``, optional): only these samples carry the gradient to the gains
    and the response; ``factor``: each sample's fixed per-laser factor (:func:`laser_factor`)."""
    import drjit as dr
    import mitsuba as mi

    from ..lidar.return_model import expected_intensity, range_response

    d = samples.beams.path_m
    values = [dr.gather(mi.Float, response, i) for i in range(len(KNOTS_M))]
    sensor = dr.gather(mi.Float, gains, samples.ring) * range_response(d, KNOTS_M, values) * factor
    if sensor_rows is not None:
        sensor = dr.select(sensor_rows, sensor, dr.detach(sensor))
    rho_hit = hit_reflectance(samples, rho)
    return expected_intensity(sensor, rho_hit, d, samples.cos_t, 0.0, "compensated")


def predict_returns(samples: Samples, rho: np.ndarray, fitted: SensorFit) -> np.ndarray:
    """(S,) expected intensity E of the samples with per-vertex ``rho`` and the fitted sensor
    (NumPy)."""
    import drjit as dr
    import mitsuba as mi

    with dr.suspend_grad():
        e = _expected(
            samples,
            mi.Float(np.asarray(rho, dtype=np.float32)),
            mi.Float(fitted.gains.astype(np.float32)),
            mi.Float(fitted.response.astype(np.float32)),
            factor=laser_factor(samples, fitted.laser_response),
        )
        dr.eval(e)
    return e.numpy()


class _Problem:
    """The fit's data on the device: samples, edges, the prior."""

    def __init__(self, samples: Samples, edges: np.ndarray, prior, prior_weight, sensor_rows=None):
        import mitsuba as mi

        self.samples = samples
        self.factor = mi.Float(1.0)  # the per-laser factors, fixed in the gradient fit
        self.sensor_rows = None if sensor_rows is None else mi.Bool(np.asarray(sensor_rows))
        self.det = mi.Bool(samples.detected)
        self.y = mi.Float(samples.intensity)
        self.zero = mi.Bool(samples.intensity <= 0.005)
        self.n_det = max(int(samples.detected.sum()), 1)
        self.e0 = mi.UInt32(edges[:, 0].astype(np.uint32))
        self.e1 = mi.UInt32(edges[:, 1].astype(np.uint32))
        self.prior = None
        if prior is not None:
            seen = np.isfinite(prior)
            self.prior_idx = mi.UInt32(np.flatnonzero(seen).astype(np.uint32))
            self.prior = mi.Float(prior[seen].astype(np.float32))
            self.prior_w = mi.Float(np.asarray(prior_weight)[seen].astype(np.float32))
            self.prior_host = prior[seen]


def _sensor_values(opt, rings: int):
    """The normalised gains and response, offset, threshold, noise and dropout from the
    optimiser's variables (Dr.Jit)."""
    import drjit as dr
    import mitsuba as mi

    log_g = opt["log_g"]
    gains = dr.exp(log_g - dr.sum(log_g) / rings)
    log_r = opt["log_r"]
    ref = dr.gather(mi.Float, log_r, KNOTS_M.index(REFERENCE_M))
    response = dr.exp(log_r - ref)
    return gains, response, opt["b"], dr.exp(opt["log_t"]), dr.exp(opt["log_s"]), opt["q"]


def _loss(pb: _Problem, opt, sensor, options: FitOptions, rings: int):
    """The total loss and its terms (Dr.Jit scalars); ``sensor``: the variables of
    :func:`_sensor_values` (the optimiser's, or frozen values)."""
    import drjit as dr
    import mitsuba as mi

    from ..lidar.return_model import detection_probability

    gains, response, b, t, s, q = _sensor_values(sensor, rings)
    rho = opt["rho"]
    e = _expected(pb.samples, rho, gains, response, pb.sensor_rows, pb.factor)
    shown = dr.maximum(e - b, 0.0)
    resid = dr.select(pb.zero, shown, shown - pb.y)
    l_int = dr.sum(dr.select(pb.det, dr.square(resid), 0.0)) / pb.n_det
    p = dr.clip((1.0 - q) * detection_probability(e, t, s), 1e-4, 1.0 - 1e-4)
    l_det = -dr.mean(dr.select(pb.det, dr.log(p), dr.log(1.0 - p)))
    diff = dr.gather(mi.Float, rho, pb.e0) - dr.gather(mi.Float, rho, pb.e1)
    l_smooth = dr.mean(dr.square(diff))
    terms = {"intensity": l_int, "detection": l_det, "smooth": l_smooth}
    total = l_int + options.w_det * l_det + options.w_smooth * l_smooth
    if pb.prior is not None and options.w_prior > 0:
        rv = dr.gather(mi.Float, rho, pb.prior_idx)
        scale = float(np.median(rv.numpy() / np.maximum(pb.prior_host, 1e-3)))
        l_prior = dr.sum(pb.prior_w * dr.square(rv - scale * pb.prior)) / dr.sum(pb.prior_w)
        terms["prior"] = l_prior
        total = total + options.w_prior * l_prior
    return total, terms


def alternate(
    samples: Samples,
    vertices: int,
    rings: int,
    rounds: int = ALS_ROUNDS,
    per_laser=True,
    sensor_rows: np.ndarray | None = None,
    edges: np.ndarray | None = None,
    response_smooth: float = 0.0,
    laser_shape: float | None = None,
    rho_smooth: float | None = None,
):
    """Alternating least squares for ``E = G_l · ρ_v · cos θ · r(d) · m_l(d)`` (in the rounds
    each sample assigned to the corner of its triangle with the largest weight; the last ρ
    through the interpolation with ``rho_smooth``): ρ per vertex, then the
    gains, then the range response's knot values (a linear least-squares problem in them), then
    (``laser_shape`` given) each laser's knot values of ``m_l``, each the exact minimiser with
    the others fixed, normalised after each round (gains' geometric mean 1,
    ``r(REFERENCE_M) = 1``; the factors once, after the last round: ``m_l(REFERENCE_M) = 1``
    and each knot's ``m_l`` a geometric mean of 1 over the lasers). Levinson and Thrun's alternation between the beams' responses and
    the map's reflectance; it starts the gradient fit near the optimum.

    The gains' step is over-relaxed (``G ← G·(G*/G)^ALS_RELAX``, G* the exact minimiser): the
    slowest direction of the alternation is a common factor between groups of lasers that see
    different surfaces (the upper block the walls, the lower the road), which plain alternation
    approaches by a few tenths of a percent per round.

    Args:
        sensor_rows: (S,) bool, the samples the sensor (gains, range response) is fitted to
            (default: all); ρ alternates with the sensor on these, then every vertex's ρ is
            solved from all samples with the sensor fixed. :func:`sensor_samples` leaves out
            returns on a crease, where one vertex reflectance and one interpolated normal stand
            for two surfaces and bias the gains of the lasers that see one side.
        edges: (E, 2) the mesh's edges: a vertex no sample is assigned to takes the harmonic
            interpolation of its neighbours (:func:`harmonic_fill`; default: the median ρ).
        rho_smooth: with ``edges``, the last ρ (after the rounds) is solved through the
            surfaces' interpolation, every sample read at its barycentric weights as the
            renderer reads it, with this weight λ on the edges' prior
            (:func:`.vertex_rho.interpolated_rho`); None: each sample at its nearest corner.
        response_smooth: weight of the range response's smoothness prior: its step solves
            ``(MᵀM + w · tr(MᵀM)/K · DᵀD) r = Mᵀy`` with D the second differences of the K
            knot values (0: none). Where every surface is seen from about one range (a car
            that stops), ρ and r(d) trade off freely and r(d) swings by factors of 2-18
            between neighbouring knots; the prior takes the smoothest of the equally good.
        laser_shape: weight w of the per-laser factors' prior (None: no factors, all 1):
            laser l's step solves ``(FᵀF + w · tr(FᵀF)/K · (DᵀD + 1)) m = Fᵀy + w · tr(FᵀF)/K``,
            F its samples' design: toward 1 and smooth where its returns are few; the prior
            alone fixes how the factors share a common scale with ρ, the gains and r during
            the rounds, and each factor lies in [:data:`SHAPE_MIN`, :data:`SHAPE_MAX`]. They are
            normalised once, after the last round (the products unchanged at the knots; ρ is
            then solved with the normalised sensor).

    Returns:
        ``(rho (V,), gains (R,), response (K,), shape (R, K))`` NumPy float64 (``shape`` all
        1 without ``laser_shape`` or ``per_laser``).
    """
    y, v, ring, q, hat, fit = _als_samples(samples, sensor_rows)
    ys, vs, rs, qs, hs = y[fit], v[fit], ring[fit], q[fit], hat[fit]
    gains, resp = np.ones(rings), np.ones(len(KNOTS_M))
    shape = np.ones((rings, len(KNOTS_M)))
    ref = KNOTS_M.index(REFERENCE_M)
    d2 = np.diff(np.eye(len(KNOTS_M)), n=2, axis=0)  # second differences of the knot values
    fit_shape = per_laser and laser_shape is not None
    # a sample's range falls between two knots: its two hat values and their knots
    pair = _knot_pairs(hat)
    pairs = tuple(p[fit] for p in pair)

    for k in range(rounds):
        ms = _own(shape, pairs, rs)
        rho, _ = _solve_rho(vs, ys, gains[rs] * (hs @ resp) * ms * qs, vertices)
        if per_laser:
            a = rho[vs] * (hs @ resp) * ms * qs
            num, den = np.bincount(rs, ys * a, rings), np.bincount(rs, a * a, rings)
            best = np.where(den > 1e-9, num / np.maximum(den, 1e-9), gains)
            best = np.maximum(best, 1e-6)
            gains = best if k == 0 else gains * (best / gains) ** ALS_RELAX
        resp = _response_step((gains[rs] * rho[vs] * ms * qs)[:, None] * hs, ys, response_smooth)
        if fit_shape:
            c = gains[rs] * rho[vs] * (hs @ resp) * qs
            shape = _laser_shapes(c, pairs, ys, rs, rings, laser_shape, d2)
        g0 = float(np.exp(np.mean(np.log(np.maximum(gains, 1e-6)))))
        gains, resp = gains / g0, resp / resp[ref]
    if fit_shape:
        gains, resp, shape = _normalised_factors(gains, resp, shape)
    a = gains[ring] * (hat @ resp) * _own(shape, pair, ring) * q
    rho = _last_rho(samples, (y, v, a), vertices, edges, rho_smooth)
    return np.clip(rho, 0.0, RHO_MAX), gains, resp, shape


def _last_rho(samples: Samples, data, vertices: int, edges, smooth: float | None) -> np.ndarray:
    """(V,) ρ from every return with the sensor fixed (``data``: the alternation's ``(y, v,
    a)``, each (N,)): at each sample's nearest corner, the vertices without one filled from
    their neighbours (:func:`harmonic_fill`) or with the median; then, with ``edges`` and
    ``smooth``, through the interpolation (:func:`.vertex_rho.interpolated_rho`, started
    there)."""
    y, v, a = data
    rho, seen = _solve_rho(v, y, a, vertices)
    if edges is None:
        return np.where(seen, rho, np.median(rho[seen]) if seen.any() else 0.3)
    rho = harmonic_fill(rho, seen, edges)
    if smooth is None or len(y) == 0:
        return rho
    det = samples.detected
    corners = np.stack([c.numpy() for c in samples.corners], axis=1)[det]
    weights = np.stack([w.numpy() for w in samples.weights], axis=1)[det]
    return interpolated_rho(corners, weights, y, a, edges, vertices, smooth, start=rho)


def _als_samples(samples: Samples, sensor_rows):
    """The returns of ``samples`` as the alternation reads them, NumPy: ``(y, v, ring, cos,
    hat, fit)``, each (N,) but ``hat`` (N, K) (the hat functions of the knots at each range);
    ``v`` the corner of its triangle with the largest weight; ``fit`` the rows the sensor is
    fitted to (all where ``sensor_rows`` is None or selects none)."""
    from ..lidar.return_model import range_response

    det = samples.detected
    y = samples.intensity[det].astype(np.float64)
    corners = np.stack([c.numpy() for c in samples.corners], axis=1)[det]
    weights = np.stack([w.numpy() for w in samples.weights], axis=1)[det]
    v = corners[np.arange(len(corners)), weights.argmax(axis=1)].astype(np.int64)
    ring = samples.ring.numpy().astype(np.int64)[det]
    q = samples.cos[det].astype(np.float64)
    d = samples.range_m[det].astype(np.float64)
    eye = np.eye(len(KNOTS_M))
    hat = np.stack([range_response(d, KNOTS_M, list(eye[k])) for k in range(len(KNOTS_M))], 1)
    fit = np.ones(len(y), bool) if sensor_rows is None else np.asarray(sensor_rows)[det]
    if not fit.any():
        fit = np.ones(len(y), bool)
    return y, v, ring, q, hat, fit


def _solve_rho(v, y, a, vertices: int):
    """Per vertex the least-squares ρ of ``y = ρ_v · a`` over its samples (``v`` their
    vertices), and whether any sample has it."""
    num, den = np.bincount(v, y * a, vertices), np.bincount(v, a * a, vertices)
    return num / np.maximum(den, 1e-9), den > 1e-9


def _response_step(m: np.ndarray, y: np.ndarray, weight: float) -> np.ndarray:
    """The range response's knot values minimising ``|M r - y|² + w · tr(MᵀM)/K · |D r|²``
    (``m`` (S, K) the design, D the second differences), at least 1e-3."""
    k = m.shape[1]
    eye = np.eye(k)
    d2 = np.diff(eye, n=2, axis=0)
    mtm = m.T @ m
    smooth = weight * np.trace(mtm) / k * (d2.T @ d2)
    resp = np.linalg.solve(mtm + 1e-6 * eye + smooth, m.T @ y)
    return np.where(resp > 1e-3, resp, 1e-3)


def _own(shape: np.ndarray, pairs, ring) -> np.ndarray:
    """``m_l(d)`` of each sample from (R, K) knot values ``shape`` (:func:`_knot_pairs`
    ``pairs``; ``ring`` the samples' lasers)."""
    k0, k1, w0, w1 = pairs
    return w0 * shape[ring, k0] + w1 * shape[ring, k1]


def _normalised_factors(gains, resp, shape):
    """The products ``G_l · r(d) · m_l(d)`` with ``m_l(REFERENCE_M) = 1``, each knot's ``m_l``
    a geometric mean of 1 over the lasers, the gains a geometric mean of 1 and
    ``r(REFERENCE_M) = 1``: the same at the knots (up to the common factor ρ takes); between two
    knots whose means over the lasers differ, r and m_l, each linear there, multiply to a
    slightly different curve."""
    ref = KNOTS_M.index(REFERENCE_M)
    gains, shape = gains * shape[:, ref], shape / shape[:, ref : ref + 1]
    g_k = np.exp(np.mean(np.log(shape), axis=0))
    shape, resp = shape / g_k, resp * g_k
    g0 = float(np.exp(np.mean(np.log(gains))))
    return gains / g0, resp / resp[ref], shape


def _knot_pairs(hat: np.ndarray) -> tuple[np.ndarray, ...]:
    """``(k0, k1, w0, w1)``, each (S,): the two knots around each sample's range and their
    weights in the piecewise-linear interpolation (``hat`` (S, K) those weights for every knot;
    outside the knots ``k1 = k0`` and ``w1 = 0``)."""
    k = hat.shape[1]
    k0 = np.argmax(hat > 0, axis=1)
    k1 = np.minimum(k0 + 1, k - 1)
    rows = np.arange(len(hat))
    w0 = hat[rows, k0]
    w1 = np.where(k1 > k0, hat[rows, k1], 0.0)
    return k0, k1, w0, w1


def _laser_shapes(c, pairs, y, ring, rings: int, weight: float, d2) -> np.ndarray:
    """(R, K) each laser's knot values minimising ``|F_l m - y_l|² + λ_l (|D m|² + |m - 1|²)``,
    ``λ_l = weight · tr(F_lᵀF_l)/K``, F the samples' design (row: ``c`` times the hat weights
    of :func:`_knot_pairs` ``pairs``; ``ring`` (S,) their lasers); clipped to
    [:data:`SHAPE_MIN`, :data:`SHAPE_MAX`]."""
    k0, k1, w0, w1 = pairs
    k = d2.shape[1]
    base = ring * k
    ftf = np.zeros(rings * k * k)
    for a, b, w in ((k0, k0, w0 * w0), (k1, k1, w1 * w1), (k0, k1, w0 * w1), (k1, k0, w0 * w1)):
        ftf += np.bincount((base + a) * k + b, c * c * w, rings * k * k)
    fty = np.bincount(base + k0, c * w0 * y, rings * k) + np.bincount(
        base + k1, c * w1 * y, rings * k
    )
    ftf, fty = ftf.reshape(rings, k, k), fty.reshape(rings, k)
    lam = weight * np.trace(ftf, axis1=1, axis2=2) / k
    lam = np.maximum(lam, 1e-9)[:, None, None]
    lhs = ftf + lam * (d2.T @ d2 + np.eye(k))
    rhs = fty + lam[:, :, 0] * 1.0
    return np.clip(np.linalg.solve(lhs, rhs[..., None])[..., 0], SHAPE_MIN, SHAPE_MAX)


def sensor_samples(samples: Samples, crease: np.ndarray) -> np.ndarray:
    """(S,) bool: the samples whose triangle has no corner on a crease
    (:func:`.mesh.crease_vertices`; ``crease`` (V,) bool): those the sensor is fitted to."""
    return ~np.any(np.stack([crease[c.numpy()] for c in samples.corners]), axis=0)


def detection_start(
    expected: np.ndarray, detected: np.ndarray, low: float, dropouts=DROPOUTS
) -> tuple[float, float, float]:
    """``(T, σ_n, q)`` minimising the fit's ray-drop term (the mean binary cross-entropy of
    ``P_D = (1 - q) Φ((E - T)/σ_n)``, clipped to [1e-4, 1 - 1e-4] as in the loss) with ``E``
    fixed: the best of a log-spaced grid (T and σ_n from 10⁻⁴ to 1, on at most 200 000 samples
    drawn with a fixed seed) and of ``T = low``, ``σ_n = low/2``, each with every dropout q of
    ``dropouts``. The clipped term is flat where it saturates, so a grid, not a gradient, finds
    its minimum.

    Args:
        expected: (S,) E of the samples; detected: (S,) bool; low: a low intensity (> 0);
        dropouts: the dropouts tried, each in [0, 1) (``(0.0,)``: none).
    """
    from ..lidar.return_model import detection_probability

    e = np.asarray(expected, dtype=np.float64)
    hit = np.asarray(detected, bool)
    if len(e) > 200_000:
        keep = np.random.default_rng(0).choice(len(e), 200_000, replace=False)
        e, hit = e[keep], hit[keep]
    qs = np.asarray(dropouts, dtype=np.float64)
    if qs.size == 0 or (qs < 0).any() or (qs >= 1).any():
        raise ValueError("detection_start: dropouts must lie in [0, 1)")

    lo, hi = np.log(1e-4), np.log(1.0 - 1e-4)
    log_keep = np.log1p(-qs)
    floor = lo - log_keep.min()  # above it, log(1 - q) + log Φ is never clipped from below

    def losses(t, s):
        """(len(qs),) the term at (T, σ_n) for each dropout. A hit's clipped log P_D is
        ``log(1 - q) + log Φ``, clipped: one logarithm of Φ serves every q (clipped from
        above only where q < 1e-4, from below only where Φ is tiny)."""
        phi = detection_probability(e, t, s)
        with np.errstate(divide="ignore"):
            log_hit = np.log(phi[hit])
        small = log_hit < floor
        rest = log_hit[~small].sum()
        on = (~small).sum() * log_keep + rest
        on += np.maximum(log_keep[:, None] + log_hit[small][None, :], lo).sum(axis=1)
        for i in np.flatnonzero(log_keep > hi):  # q < 1e-4: the upper clip can bind
            on[i] = np.clip(log_keep[i] + log_hit, lo, hi).sum()
        p_miss = np.clip((1.0 - qs[:, None]) * phi[~hit][None, :], 1e-4, 1.0 - 1e-4)
        off = np.log(1.0 - p_miss).sum(axis=1)
        return -(on + off) / len(e)

    low = max(low, 1e-3)
    grid = np.logspace(-4, 0, 25)
    best = (np.inf, low, low / 2, 0.0)
    for t, s in [(low, low / 2)] + [(t, s) for t in grid for s in grid]:
        values = losses(t, s)
        k = int(np.argmin(values))
        if values[k] < best[0]:
            best = (float(values[k]), t, s, float(qs[k]))
    return best[1], best[2], best[3]


def _start(pb: _Problem, start, rings: int, options: FitOptions):
    """The optimiser at the alternating least squares' solution (``start``: ρ, gains,
    response, per-laser factors or None), the offset at 0 and the detection threshold, noise and dropout where the
    ray-drop term is lowest for that solution (:func:`detection_start`)."""
    import mitsuba as mi

    rho, gains, resp, shape = start
    e = pb.samples.intensity[pb.samples.detected]
    opt = mi.ad.Adam(lr=options.lr_sensor)
    opt["rho"] = mi.Float(rho.astype(np.float32))
    opt["log_g"] = mi.Float(np.log(np.maximum(gains, 1e-3)).astype(np.float32))
    opt["log_r"] = mi.Float(np.log(np.maximum(resp, 1e-3)).astype(np.float32))
    opt["b"] = mi.Float(np.zeros(1, np.float32))
    low = float(np.percentile(e[e > 0], 2)) if (e > 0).any() else 0.01
    fitted = SensorFit(gains, KNOTS_M, resp, 0.0, low, low / 2, laser_response=shape)
    expected = predict_returns(pb.samples, rho, fitted)
    dropouts = DROPOUTS if options.fit_dropout else (0.0,)
    t, s, q = detection_start(expected, pb.samples.detected, low, dropouts)
    opt["log_t"] = mi.Float(np.float32([np.log(t)]))
    opt["log_s"] = mi.Float(np.float32([np.log(s)]))
    opt["q"] = mi.Float(np.float32([q]))
    opt.set_learning_rate(rho=options.lr_rho, log_g=options.lr_gains, log_r=options.lr_gains)
    return opt


def _clamp(opt, options: FitOptions) -> None:
    """Keep the variables in their domain; freeze what is not fitted."""
    import drjit as dr
    import mitsuba as mi

    opt["rho"] = dr.clip(opt["rho"], 0.0, RHO_MAX)
    opt["b"] = dr.maximum(opt["b"], 0.0) if options.fit_offset else mi.Float(0.0)
    opt["q"] = dr.clip(opt["q"], 0.0, DROPOUT_MAX) if options.fit_dropout else mi.Float(0.0)
    if not options.per_laser:
        opt["log_g"] = dr.zeros(mi.Float, dr.width(opt["log_g"]))
    if not options.fit_response:
        opt["log_r"] = dr.zeros(mi.Float, dr.width(opt["log_r"]))


def fit_drive(samples: Samples, scene, edges: np.ndarray, rings: int, options: FitOptions, **kw):
    """Fit ρ and the sensor to the samples (module docstring): alternating least squares
    (:func:`alternate`) for ρ, the gains, the range response and each laser's own factor
    (``options.laser_response``; with ``fit_response`` only), then every variable but those
    factors jointly by Adam on the gradients of the full loss (offset, detection, smoothness,
    prior included).

    Args:
        samples: the training samples (cast into ``scene``).
        scene: the surfaces (:func:`.surfaces.surface_scene`); its ``vertex_rho`` (its
            ``mi.traverse`` parameter) is set to the fitted reflectance.
        edges: (E, 2) the mesh's edges (:func:`edges_of`).
        rings: lasers of the sensor.
        options: the settings.
        kw: ``prior`` (V,) NIDAR's R per vertex (NaN unseen), ``prior_weight`` (V,),
            ``sensor_rows`` (S,) bool: the samples the sensor is fitted to
            (:func:`sensor_samples`; default all), ``progress`` (bool).

    Returns:
        ``(rho, sensor)``: (V,) fitted reflectance and the :class:`SensorFit`.
    """
    import drjit as dr
    import mitsuba as mi

    from ..progress import progress_bar
    from .surfaces import RHO_KEY

    params = mi.traverse(scene)
    rows = kw.get("sensor_rows")
    pb = _Problem(samples, edges, kw.get("prior"), kw.get("prior_weight"), rows)
    vertices = dr.width(params[RHO_KEY])
    with_shape = options.per_laser and options.laser_response and options.fit_response
    rho0, gains0, resp0, shape = alternate(
        samples,
        vertices,
        rings,
        per_laser=options.per_laser,
        sensor_rows=rows,
        edges=edges,
        response_smooth=options.response_smooth,
        laser_shape=options.laser_shape_prior if with_shape else None,
        rho_smooth=options.rho_smooth,
    )
    shape = shape if with_shape else None
    pb.factor = laser_factor(samples, shape)
    opt = _start(pb, (rho0, gains0, resp0, shape), rings, options)
    _clamp(opt, options)
    history: list[dict] = []
    steps = progress_bar(range(options.iterations), show=kw.get("progress", False), desc="fit")
    for _ in steps:
        total, terms = _loss(pb, opt, opt, options, rings)
        dr.backward(total)
        opt.step()
        _clamp(opt, options)
        history.append({k: float(v.numpy()[0]) for k, v in terms.items()})
    rho = dr.detach(opt["rho"])
    params[RHO_KEY] = rho
    params.update()
    with dr.suspend_grad():
        g, r, b, t, s, q = _sensor_values(opt, rings)
    fitted = SensorFit(
        gains=g.numpy().astype(np.float64),
        knots_m=KNOTS_M,
        response=r.numpy().astype(np.float64),
        offset=float(b.numpy()[0]),
        threshold=float(t.numpy()[0]),
        noise=float(s.numpy()[0]),
        dropout=float(q.numpy()[0]),
        history=history,
        laser_response=shape,
    )
    return rho.numpy().astype(np.float64), fitted
