"""Compiled scalar kernels of the model's maths (numba): Euler spirals and lognormal profiles, the
one implementation behind :mod:`tagbot.model.euler`'s array API, the sampler and the fitter's
loops.

Each function works on one segment or one argument, so the fitter can call it from compiled
loops of its own without numpy's per-call cost, and :mod:`~tagbot.model.euler` wraps it in a
loop over arrays. The maths is described there; the standard Fresnel integrals are scipy's own
(Cephes), called through the C interface that ``scipy.special.cython_special`` exports.

A segment's evaluation constants sit in one row of :data:`N_CONSTANTS` floats (see
:func:`segment_constants`), so arrays of segments are plain 2-D float arrays.
"""

from __future__ import annotations

import ctypes
import math
from collections.abc import Callable
from typing import Any, TypeVar

import numpy as np
import scipy.special.cython_special as _cython_special
from llvmlite import binding as llvm_binding
from llvmlite import ir
from numba import njit, types
from numba.core import cgutils
from numba.extending import get_cython_function_address, intrinsic

F = TypeVar("F", bound=Callable[..., Any])

SMALL_A = 1e-2
"""Below this ``|dkappa|·length²`` a segment is evaluated with the near-arc series."""
SMALL_A_MOMENTS = 4.0
"""Series threshold when I_1, I_2… are wanted: B&F's recurrence in k divides by ``a`` and
amplifies errors by ``|b|/|a|`` per step, harmless only once ``|a|`` is a few units."""
TAYLOR_B = 6.0
"""Up to this ``|b|``, near-arcs (``|a| < SMALL_A``) take the Taylor series of :func:`taylor`
(cheaper than the moments' series, within ~1e-14)."""
NEWTON_TOL = 1e-14
NEWTON_MAX_ITER = 20
# Initial-guess polynomial of Bertolazzi & Frego (2015), eq. for A(phi0, phi1).
_G0, _G1, _G2, _G3, _G4, _G5 = (
    2.989696028701907,
    0.716228953608281,
    -0.458969738821509,
    -0.502821153340377,
    0.261062141752652,
    -0.045854475238709,
)


def compiled(function: F) -> F:
    """Compile ``function`` with numba, cached on disk; float errors give inf/nan as in numpy.
    It runs without the GIL, so the command line's signal watchdog (:mod:`tagbot.signals`) can
    act while a long loop runs."""
    return njit(cache=True, error_model="numpy", nogil=True)(function)  # type: ignore[no-any-return]


def inlined(function: F) -> F:
    """:func:`compiled`, and inlined into its callers: for small functions that take arrays and
    are called in hot loops, where a call's reference counting would cost more than the work."""
    return njit(cache=True, error_model="numpy", nogil=True, inline="always")(function)  # type: ignore[no-any-return]


# Segment constants, one row per segment.
KIND, COS0, SIN0, KAPPA0, DKAPPA, S_CENTRE, INV_SCALE, GAMMA, ROT_COS, ROT_SIN, C0, S0 = range(12)
N_CONSTANTS = 12
ARC, NEAR_ARC, SPIRAL = 0, 1, 2
"""Segment kinds: arc or line (closed form), near-arc (series), spiral (Fresnel)."""


def _scipy_function(name: str, signature: bytes) -> int:
    """Address of the ``cython_special`` function ``name`` with the C ``signature``."""
    get_name = ctypes.pythonapi.PyCapsule_GetName
    get_name.restype = ctypes.c_char_p
    get_name.argtypes = [ctypes.py_object]
    for key, capsule in _cython_special.__pyx_capi__.items():
        if key.split("fuse_")[-1].lstrip("0123456789") == name and get_name(capsule) == signature:
            return get_cython_function_address("scipy.special.cython_special", key)
    raise ImportError(f"scipy.special.cython_special has no {name}{signature.decode()}")


# Registered by name, so that cached machine code links to them again in a new process.
_FRESNEL_SYMBOL = "tagbot_scipy_fresnel"
_NDTRI_SYMBOL = "tagbot_scipy_ndtri"
llvm_binding.add_symbol(
    _FRESNEL_SYMBOL, _scipy_function("fresnel", b"void (double, double *, double *)")
)
llvm_binding.add_symbol(
    _NDTRI_SYMBOL, _scipy_function("ndtri", b"double (double, int __pyx_skip_dispatch)")
)


@intrinsic
def fresnel(typingctx, x):  # type: ignore[no-untyped-def]
    """``(S(x), C(x))``, the standard Fresnel integrals (as ``scipy.special.fresnel``)."""
    signature = types.UniTuple(types.float64, 2)(types.float64)

    def codegen(context, builder, sig, args):  # type: ignore[no-untyped-def]
        double = ir.DoubleType()
        function_type = ir.FunctionType(
            ir.VoidType(), [double, double.as_pointer(), double.as_pointer()]
        )
        function = cgutils.get_or_insert_function(builder.module, function_type, _FRESNEL_SYMBOL)
        s, c = cgutils.alloca_once(builder, double), cgutils.alloca_once(builder, double)
        builder.call(function, [args[0], s, c])
        return context.make_tuple(builder, sig.return_type, [builder.load(s), builder.load(c)])

    return signature, codegen


@intrinsic
def ndtri(typingctx, p):  # type: ignore[no-untyped-def]
    """The standard normal quantile (as ``scipy.special.ndtri``)."""
    signature = types.float64(types.float64)

    def codegen(context, builder, sig, args):  # type: ignore[no-untyped-def]
        double = ir.DoubleType()
        function_type = ir.FunctionType(double, [double, ir.IntType(32)])
        function = cgutils.get_or_insert_function(builder.module, function_type, _NDTRI_SYMBOL)
        return builder.call(function, [args[0], ir.Constant(ir.IntType(32), 0)])

    return signature, codegen


_INV_SQRT_2PI = 1.0 / math.sqrt(2.0 * math.pi)
_INV_SQRT_2 = 1.0 / math.sqrt(2.0)
TINY = float(np.finfo(np.float64).tiny)
"""Elapsed times are clamped to at least this, so that logarithms stay finite."""


@compiled
def lognormal_at(t: float, onset: float, mu: float, sigma: float) -> tuple[float, float]:
    """A lognormal stroke's CDF ``W`` and density ``Λ`` at ``t``."""
    elapsed = max(t - onset, TINY)
    z = (math.log(elapsed) - mu) / sigma
    cdf = 0.5 * math.erfc(-z * _INV_SQRT_2)
    return cdf, math.exp(-0.5 * z * z) * _INV_SQRT_2PI / (sigma * elapsed)


@compiled
def stroke_window(onset: float, mu: float, sigma: float, budget: float) -> tuple[float, float]:
    """When a lognormal stroke is within ``budget`` (a fraction of it, capped at 1 %) of not
    started and of complete: its active window ``(t_on, t_off)``."""
    z = -ndtri(min(budget, 1e-2))
    return onset + math.exp(mu - sigma * z), onset + math.exp(mu + sigma * z)


@compiled
def wrap_angle(angle: float) -> float:
    """``angle`` wrapped into (−π, π]."""
    return math.pi - np.mod(math.pi - angle, 2.0 * math.pi)


@compiled
def sinc_half(b: float) -> complex:
    """M_0(b) = (e^{ib} − 1)/(ib), exact at and near b = 0."""
    h = 0.5 * b
    s = 1.0 if h == 0.0 else math.sin(h) / h
    return complex(math.cos(h), math.sin(h)) * s


@compiled
def moments_into(b: float, out: np.ndarray) -> None:
    """``out[n] = M_n(b) = ∫₀¹ τ^n e^{ibτ} dτ`` for ``n < len(out)``.

    Upward recurrence ``M_n = (e^{ib} − n M_{n−1}) / (ib)`` where stable (``n < |b|``);
    downward ``M_{n−1} = (e^{ib} − ib M_n) / n`` from a short series of ``M_top`` about τ = 1
    elsewhere.
    """
    n_max = len(out) - 1
    e = complex(math.cos(b), math.sin(b))
    ib = 1j * b
    out[0] = sinc_half(b)
    m = out[0]
    for n in range(1, n_max + 1):
        if n >= abs(b):
            break
        m = (e - n * m) / ib
        out[n] = m
    if n_max < abs(b):
        return
    top = n_max + 2 * math.ceil(abs(b)) + 2
    # M_top = e^{ib} Σ_j (−ib)^j top! / (top + j + 1)!: terms shrink by |b|/(top + j + 1) < ½.
    term = (1.0 / (top + 1)) + 0j
    series = term
    for j in range(1, 80):
        term = term * (-ib) * (1.0 / (top + j + 1))
        series += term
        if abs(term.real) + abs(term.imag) < 1e-17 * (abs(series.real) + abs(series.imag)):
            break
    m = e * series
    for n in range(top, 1, -1):
        m = (e - ib * m) * (1.0 / n)
        if n - 1 <= n_max and n - 1 >= abs(b):
            out[n - 1] = m


@compiled
def generalized_fresnel_into(a: float, b: float, accurate: bool, out: np.ndarray) -> None:
    """``out[k] = I_k(a, b) = ∫₀¹ τ^k exp(i(aτ²/2 + bτ)) dτ`` for ``k < len(out)``.

    ``accurate=False`` takes the fast recurrence for ``k ≥ 1`` down to ``|a| = SMALL_A``
    (enough for a Newton derivative).
    """
    k_max = len(out) - 1
    threshold = SMALL_A if (k_max == 0 or not accurate) else SMALL_A_MOMENTS
    if abs(a) < SMALL_A and abs(b) <= TAYLOR_B and k_max <= 2:
        i0, i1, i2 = taylor(a, b)
        out[0] = i0
        if k_max > 0:
            out[1] = i1
        if k_max > 1:
            out[2] = i2
    elif abs(a) < threshold:
        _series_into(a, b, out)
    else:
        _large_into(a, b, out)


@compiled
def taylor(a: float, b: float, tolerance: float = 1e-17) -> tuple[complex, complex, complex]:
    """``I_0, I_1, I_2`` by the integrand's Taylor series in τ, for small ``|a|`` and
    ``|b| ≤ TAYLOR_B``: ``e^{iψ(τ)} = Σ c_m τ^m`` with ``c_0 = 1``, ``c_1 = ib`` and
    ``(m + 1) c_{m+1} = i (b c_m + a c_{m−1})`` (from ``f' = iψ' f``), so
    ``I_k = Σ c_m / (m + k + 1)``. Its terms grow to at most ``e^{|b|}``-ish before they shrink,
    which costs at most two digits below ``TAYLOR_B``. The sum stops once two consecutive
    coefficients are below ``tolerance``."""
    pr, pi_, cr, ci = 0.0, 0.0, 1.0, 0.0  # c_{m−1}, c_m
    r1, r2, r3 = 1.0, 0.5, 1.0 / 3.0  # 1/(m + 1), 1/(m + 2), 1/(m + 3)
    i0r = i0i = i1r = i1i = i2r = i2i = 0.0
    m = 0
    while True:
        i0r += cr * r1
        i0i += ci * r1
        i1r += cr * r2
        i1i += ci * r2
        i2r += cr * r3
        i2i += ci * r3
        x, y = b * cr + a * pr, b * ci + a * pi_  # c_{m+1} = i (x + iy) / (m + 1)
        fr, fi = -y * r1, x * r1
        if m > abs(b) and abs(cr) + abs(ci) + abs(fr) + abs(fi) < tolerance:
            return complex(i0r, i0i), complex(i1r, i1i), complex(i2r, i2i)
        pr, pi_, cr, ci = cr, ci, fr, fi
        m += 1
        r1, r2, r3 = r2, r3, 1.0 / (m + 3)


@compiled
def _large_into(a: float, b: float, out: np.ndarray) -> None:
    """I_k for |a| >= SMALL_A: I_0 from standard Fresnel integrals, then B&F's recurrence."""
    negative = a < 0.0
    a_abs = abs(a)
    b_s = -b if negative else b  # I(a, b) = conj(I(−a, −b)): solve with a > 0
    scale = math.sqrt(math.pi / a_abs)
    s0, c0 = fresnel(b_s / (scale * a_abs))
    s1, c1 = fresnel((a_abs + b_s) / (scale * a_abs))
    phase = -0.5 * b_s * b_s / a_abs
    i0 = scale * complex(math.cos(phase), math.sin(phase)) * complex(c1 - c0, s1 - s0)
    out[0] = i0.conjugate() if negative else i0
    psi = 0.5 * a + b
    e1 = complex(math.cos(psi), math.sin(psi))
    for k in range(len(out) - 1):
        # a I_{k+1} + b I_k = −i (e^{iψ(1)} − [k = 0]) + i k I_{k−1}
        rhs = -1j * (e1 - (1.0 if k == 0 else 0.0)) - b * out[k]
        if k > 0:
            rhs += 1j * k * out[k - 1]
        out[k + 1] = rhs / a


@compiled
def _series_into(a: float, b: float, out: np.ndarray) -> None:
    """I_k for small |a|: Σ_n (ia/2)^n / n! · M_{k+2n}(b), truncated below double precision."""
    h = 0.5 * abs(a)
    n_terms = 0
    bound = 1.0
    while h > 0.0 and bound > 1e-18:  # next term ≤ h^{n+1}/(n+1)! (|M| ≤ 1)
        n_terms += 1
        bound *= h / n_terms
    k_max = len(out) - 1
    m = np.empty(k_max + 2 * n_terms + 1, dtype=np.complex128)
    moments_into(b, m)
    for k in range(k_max + 1):
        total = m[k]
        coeff = 1.0 + 0j
        for n in range(1, n_terms + 1):
            coeff = coeff * (0.5j * a) / n
            total += coeff * m[k + 2 * n]
        out[k] = total


@compiled
def solve_g1(phi0: float, phi1: float) -> float:
    """Root ``A`` of B&F's ``Y_0(2A, φ1 − φ0 − A, φ0) = 0`` (chord-relative angles in (−π, π])."""
    x, y = phi0 / math.pi, phi1 / math.pi
    xy, x2, y2 = x * y, x * x, y * y
    a = (phi0 + phi1) * (
        _G0 + xy * (_G1 + xy * _G2) + (_G3 + xy * _G4) * (x2 + y2) + _G5 * (x2 * x2 + y2 * y2)
    )
    delta = phi1 - phi0
    rot = complex(math.cos(phi0), math.sin(phi0))
    moments = np.empty(3, dtype=np.complex128)
    for _ in range(NEWTON_MAX_ITER):
        generalized_fresnel_into(2.0 * a, delta - a, False, moments)
        g = (rot * moments[0]).imag
        dg = (rot * moments[2]).real - (rot * moments[1]).real
        a -= g / dg
        if abs(g) <= NEWTON_TOL:
            break
    return a


@compiled
def fit_unit_chord(phi0: float, phi1: float) -> tuple[float, float, float, float]:
    """The G1 clothoid from (0, 0) to (1, 0) with chord-relative tangents ``phi0``, ``phi1``
    (wrapped into (−π, π]): ``(theta0, kappa0, dkappa, length)``."""
    phi0, phi1 = wrap_angle(phi0), wrap_angle(phi1)
    a = solve_g1(phi0, phi1)
    delta = phi1 - phi0
    i0 = np.empty(1, dtype=np.complex128)
    generalized_fresnel_into(2.0 * a, delta - a, True, i0)
    length = 1.0 / (complex(math.cos(phi0), math.sin(phi0)) * i0[0]).real
    return phi0, (delta - a) / length, 2.0 * a / (length * length), length


@compiled
def is_arc(phi1: float, phi2: float) -> bool:
    """A ΣΛ* stroke: ``phi1 == -phi2`` with ``|phi2| < π`` (a circular arc)."""
    return phi1 == -phi2 and abs(phi2) < math.pi


@compiled
def unit_stroke(phi1: float, phi2: float) -> tuple[float, float, float, float]:
    """A stroke's shape on the unit chord: ``(theta0, kappa0, dkappa, length)``; arcs in
    closed form (exact where the spiral fit's root would be ~1e-17 rather than 0)."""
    if is_arc(phi1, phi2):
        length = 1.0 if phi2 == 0.0 else phi2 / math.sin(phi2)
        return -phi2, 2.0 * phi2 / length, 0.0, length
    return fit_unit_chord(phi1, phi2)


@compiled
def segment_constants(
    theta0: float, kappa0: float, dkappa: float, length: float, out: np.ndarray
) -> None:
    """Fill ``out`` (:data:`N_CONSTANTS` floats) with a segment's evaluation constants."""
    a = abs(dkappa) * length * length
    kind = ARC if dkappa == 0.0 else (NEAR_ARC if a < SMALL_A else SPIRAL)
    dk = dkappa if kind == SPIRAL else 1.0
    scale = math.sqrt(math.pi / abs(dk))
    s_centre = -kappa0 / dk
    theta_c = theta0 - 0.5 * kappa0 * kappa0 / dk
    fs0, fc0 = fresnel(-s_centre / scale)
    out[KIND] = kind
    out[COS0], out[SIN0] = math.cos(theta0), math.sin(theta0)
    out[KAPPA0], out[DKAPPA] = kappa0, dkappa
    out[S_CENTRE], out[INV_SCALE] = s_centre, 1.0 / scale
    out[GAMMA] = 1.0 if dk > 0.0 else -1.0
    out[ROT_COS], out[ROT_SIN] = scale * math.cos(theta_c), scale * math.sin(theta_c)
    out[C0], out[S0] = fc0, fs0


@inlined
def segment_point(c: np.ndarray, s: float) -> tuple[float, float, float, float]:
    """Displacement ``(dx, dy)`` from the start and unit tangent ``(tx, ty)`` at arc length
    ``s`` of the segment with constants ``c``."""
    kind = int(c[KIND])
    cos0, sin0 = c[COS0], c[SIN0]
    if kind == ARC:
        # The chord to s turns by half the tangent's turn κ0·s and is s·sin(x)/x long.
        x = 0.5 * c[KAPPA0] * s
        cx, sx = math.cos(x), math.sin(x)
        chord = s if x == 0.0 else s * sx / x
        hx, hy = cos0 * cx - sin0 * sx, sin0 * cx + cos0 * sx  # direction θ0 + x
        return chord * hx, chord * hy, hx * cx - hy * sx, hy * cx + hx * sx
    k0, dk = c[KAPPA0], c[DKAPPA]
    turn = s * (k0 + 0.5 * dk * s)
    ct, st = math.cos(turn), math.sin(turn)
    tx, ty = cos0 * ct - sin0 * st, sin0 * ct + cos0 * st
    if kind == NEAR_ARC:
        a, b = dk * s * s, k0 * s
        if abs(b) <= TAYLOR_B:
            i0 = taylor(a, b)[0]
        else:
            out = np.empty(1, dtype=np.complex128)
            _series_into(a, b, out)
            i0 = out[0]
        off = s * complex(cos0, sin0) * i0
        return off.real, off.imag, tx, ty
    # Spiral: ρ e^{iθc} [F(u) − F(u0)], u = (s − s_c)/ρ, F = C + iγS.
    fs, fc = fresnel((s - c[S_CENTRE]) * c[INV_SCALE])
    fc -= c[C0]
    fs = (fs - c[S0]) * c[GAMMA]
    rc, rs = c[ROT_COS], c[ROT_SIN]
    return rc * fc - rs * fs, rs * fc + rc * fs, tx, ty


# --- loops over arrays, for the numpy API -----------------------------------------------------


@compiled
def moments_array(n_max: int, b: np.ndarray) -> np.ndarray:
    out = np.empty((b.size, n_max + 1), dtype=np.complex128)
    for i in range(b.size):
        moments_into(b[i], out[i])
    return out


@compiled
def generalized_fresnel_array(
    k_max: int, a: np.ndarray, b: np.ndarray, accurate: bool
) -> np.ndarray:
    out = np.empty((a.size, k_max + 1), dtype=np.complex128)
    for i in range(a.size):
        generalized_fresnel_into(a[i], b[i], accurate, out[i])
    return out


@compiled
def solve_g1_array(phi0: np.ndarray, phi1: np.ndarray) -> np.ndarray:
    out = np.empty(phi0.size)
    for i in range(phi0.size):
        out[i] = solve_g1(phi0[i], phi1[i])
    return out


@compiled
def unit_strokes_array(phi1: np.ndarray, phi2: np.ndarray) -> np.ndarray:
    """Per stroke ``(theta0, kappa0, dkappa, length)`` of :func:`unit_stroke`, shape (n, 4)."""
    out = np.empty((phi1.size, 4))
    for i in range(phi1.size):
        out[i, 0], out[i, 1], out[i, 2], out[i, 3] = unit_stroke(phi1[i], phi2[i])
    return out


@compiled
def windows_array(
    onsets: np.ndarray, mu: np.ndarray, sigma: np.ndarray, budget: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    t_on, t_off = np.empty(onsets.size), np.empty(onsets.size)
    for i in range(onsets.size):
        t_on[i], t_off[i] = stroke_window(onsets[i], mu[i], sigma[i], budget[i])
    return t_on, t_off


@compiled
def arcs_array(phi1: np.ndarray, phi2: np.ndarray) -> np.ndarray:
    out = np.empty(phi1.size, dtype=np.bool_)
    for i in range(phi1.size):
        out[i] = is_arc(phi1[i], phi2[i])
    return out


@compiled
def constants_array(
    theta0: np.ndarray, kappa0: np.ndarray, dkappa: np.ndarray, length: np.ndarray
) -> np.ndarray:
    out = np.empty((theta0.size, N_CONSTANTS))
    for i in range(theta0.size):
        segment_constants(theta0[i], kappa0[i], dkappa[i], length[i], out[i])
    return out


@compiled
def evaluate_runs(
    constants: np.ndarray, segments: np.ndarray, counts: np.ndarray, s: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`segment_point` at ``s``, which holds ``counts[i]`` values for ``segments[i]``."""
    dx, dy, tx, ty = np.empty(s.size), np.empty(s.size), np.empty(s.size), np.empty(s.size)
    row = 0
    for i in range(segments.size):
        c = constants[segments[i]]
        for _ in range(counts[i]):
            dx[row], dy[row], tx[row], ty[row] = segment_point(c, s[row])
            row += 1
    return dx, dy, tx, ty


@compiled
def plan_grids(
    t_off: np.ndarray, first_stroke: np.ndarray, starts: np.ndarray, step: float
) -> tuple[np.ndarray, np.ndarray]:
    """Each plan's sampling times, every ``step`` from its start (``starts[k]``) to its end (the
    latest ``t_off`` of its strokes ``first_stroke[k]:first_stroke[k + 1]``; the last sample at
    or just past it), one plan after the other (plan ``k``'s rows ``first[k]:first[k + 1]``)."""
    plans = starts.size
    first = np.zeros(plans + 1, np.intp)
    for k in range(plans):
        end = t_off[first_stroke[k] : first_stroke[k + 1]].max()
        first[k + 1] = first[k] + math.ceil((end - starts[k]) / step - 1e-9) + 1
    t = np.empty(first[plans])
    for k in range(plans):
        for i in range(first[k + 1] - first[k]):
            t[first[k] + i] = starts[k] + i * step
    return t, first


@compiled
def evaluate_plans_into(
    t: np.ndarray,
    first_row: np.ndarray,
    first_stroke: np.ndarray,
    start: np.ndarray,
    chords: np.ndarray,
    t_on: np.ndarray,
    t_off: np.ndarray,
    onsets: np.ndarray,
    mu: np.ndarray,
    sigma: np.ndarray,
    length: np.ndarray,
    constants: np.ndarray,
    xy: np.ndarray,
    v: np.ndarray,
) -> int:
    """Positions ``xy`` and velocities ``v`` (N, 2, ``v`` zeroed) of plans at their sorted
    times: plan ``k`` owns rows ``first_row[k]:first_row[k + 1]`` of ``t`` and strokes
    ``first_stroke[k]:first_stroke[k + 1]``, starts at ``start[k]``; each stroke is evaluated
    inside its window ``[t_on, t_off]`` (its curve at ``D·W(t)``, velocity ``D·Λ(t)`` along
    the tangent there), contributes nothing before it and its whole chord after it. Returns the
    (sample, stroke) pairs evaluated."""
    begin = np.empty(onsets.size, np.intp)
    stop = np.empty(onsets.size, np.intp)
    for k in range(first_row.size - 1):
        lo, hi = first_row[k], first_row[k + 1]
        rows = t[lo:hi]
        # The chords of the strokes complete before each row: differences, then their sums.
        xy[lo:hi] = 0.0
        for i in range(first_stroke[k], first_stroke[k + 1]):
            begin[i] = lo + np.searchsorted(rows, t_on[i], side="left")
            stop[i] = lo + np.searchsorted(rows, t_off[i], side="right")
            if stop[i] < hi:
                xy[stop[i], 0] += chords[i, 0]
                xy[stop[i], 1] += chords[i, 1]
        x, y = start[k, 0], start[k, 1]
        for r in range(lo, hi):
            x += xy[r, 0]
            y += xy[r, 1]
            xy[r, 0], xy[r, 1] = x, y
    pairs = 0
    for i in range(onsets.size):
        c = constants[i]
        for r in range(begin[i], stop[i]):
            cdf, density = lognormal_at(t[r], onsets[i], mu[i], sigma[i])
            dx, dy, tx, ty = segment_point(c, length[i] * cdf)
            speed = length[i] * density
            xy[r, 0] += dx
            xy[r, 1] += dy
            v[r, 0] += speed * tx
            v[r, 1] += speed * ty
        pairs += stop[i] - begin[i]
    return pairs
