"""Private compiled loops of the exposure screen, :func:`photoquant.exposure.refine_by_pairs`.

Two kernels carry the whole screen once its pixels are drawn:

* :func:`pairs_of_values` — the pairs of neighbouring exposures: each drawn
  pixel's mean over the repeats, its clipping, ``g`` and its segment slope
  looked up, and each step's quota of valid pairs taken in the draw's
  random order (:func:`photoquant.exposure._neighbouring_pairs`' numpy
  twin, value by value: the same bits);
* :func:`screen_passes` — the passes: each end of a pair predicted from the
  other, the values used and their weights (:func:`pair_pass`), the steps'
  Huber locations and their sandwich covariance, the longest run of
  determined steps, the log times chained from it, and the noise line
  refitted to the residuals where there is one repeat
  (:func:`photoquant.exposure._pair_passes`' numpy twin, operation by
  operation, in the same order).

The screen's numpy twin forms the sandwich's ``ψᵀψ`` and the noise line's
normal equations by BLAS products, which add in another order than these
loops: the two paths agree to rounding (relative ``1e-12`` on the times,
``1e-9`` on their covariance, tested), not to the bit. What the compiled
screen costs, and what the alternatives did (1024×768×3, K = 4, N = 1,
4 000 pixels drawn, one thread, on the shared 2-core machine): its numpy
twin 8.5 ms against 2.85 ms for ``refine_by_pairs`` (2026-12-04); the passes
over the correction benchmark's 6 188 pairs 1.12 ms (min of 300,
2026-12-07) against 1.44 ms looping over every pair rather than the ones
used; looping over every pair, 1.45 ms against 1.61–1.64 ms with a zero test
before each division (min of 50, 2026-12-06).

The helpers (:func:`interp_near`, :func:`rounding_at`, :func:`table_index`,
:func:`lerp_at`, :func:`huber_iterations`) are compiled on their own and
called from the kernels; every name here is its plain-Python body when numba
is not installed (the callers then take their numpy twins). Every loop with
a division is compiled with numpy's error model (no zero test before each
division: none divides by zero — the search's interval, the levels' steps
and the totals are positive where they divide, and the rest is guarded).
The Huber iterations, the scale, the noise line and the sandwich loop over
the pairs used only (a pair left out has no weight and no residual: it adds
exact zeros), and a pair left out at its first end skips the second end's
arithmetic but its ``g''`` (what its next pass reads): the same bits as
looping over every pair.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from photoquant._interp import interval
from photoquant._numba import HAVE_NUMBA, compile_kernel
from photoquant._select import median_inplace

__all__ = [
    "huber_iterations",
    "interp_near",
    "lerp_at",
    "pair_pass",
    "pairs_of_values",
    "rounding_at",
    "screen_passes",
    "table_index",
]


def rounding_at(sigma: float, table: Any, n: int) -> float:  # pragma: no cover - numba
    """:func:`photoquant.exposure.rounding_variance` of one value (the table's linear
    interpolation)."""
    u = sigma * float(n)
    if np.isnan(sigma):
        return np.nan
    if not u <= n:
        return 0.0
    i = min(int(u), n - 1)
    return table[i] + (u - i) * (table[i + 1] - table[i])


def interp_near(x: float, xp: Any, fp: Any, hint: int) -> float:  # pragma: no cover - numba
    """``np.interp`` of one value (``xp`` non-decreasing), its interval searched from
    ``hint`` outwards: the interval ``xp[j] <= x < xp[j+1]`` is unique, so this is a
    binary search's answer, found in a step or two where ``x`` lies near the hint
    without a binary search's unpredictable branches."""
    n = xp.size
    if np.isnan(x):
        return x
    if x >= xp[n - 1]:
        return fp[n - 1]
    if x < xp[0]:
        return fp[0]
    lo = min(max(hint, 0), n - 2)
    while xp[lo] > x:
        lo -= 1
    while xp[lo + 1] <= x:
        lo += 1
    slope = (fp[lo + 1] - fp[lo]) / (xp[lo + 1] - xp[lo])
    return slope * (x - xp[lo]) + fp[lo]


def table_index(
    z: float, levels: Any, even: bool, inv_step: float
) -> tuple[int, float]:  # pragma: no cover - compiled by numba
    """The interval ``i`` of ``levels`` holding ``z`` (NaN: the first level; ends held) and
    the fraction of the way across it (:class:`photoquant.exposure._Tables`)."""
    n = levels.size
    lv0 = levels[0]
    zc = lv0 if np.isnan(z) else min(max(z, lv0), levels[n - 1])
    if even:
        i = min(int((zc - lv0) * inv_step), n - 2)
    else:
        # the last level at or below zc, at most n − 2: np.interp's bisection
        # (``np.searchsorted(levels, zc, "right") − 1`` clipped, the same interval; numba's
        # searchsorted cost ~0.3 s to compile)
        i = min(interval(zc, levels)[1], n - 2)
    return i, (zc - levels[i]) / (levels[i + 1] - levels[i])


def lerp_at(table: Any, i: int, frac: float) -> float:  # pragma: no cover - numba
    """``table`` a fraction ``frac`` of the way from entry ``i`` to ``i + 1`` (with
    :func:`table_index`: :meth:`photoquant.exposure._Tables.at`'s arithmetic)."""
    a = table[i]
    return a + frac * (table[i + 1] - a)


def pairs_of_values(
    values: Any, order: Any, sat_thr: Any, dark_thr: Any, tabs: Any, levels: Any,
    even: bool, inv_step: float, quota: Any, keep: Any, entries: Any, ends: Any,
) -> tuple[int, int]:  # fmt: skip  # pragma: no cover - compiled by numba
    """The pairs of :func:`photoquant.exposure._neighbouring_pairs` from the drawn values.

    ``values`` ``(N, K, P, C)`` integers; ``order`` the pixels' random order;
    a value is clipped where a repeat reaches ``sat_thr`` or lies at or below
    ``dark_thr`` (:meth:`photoquant.stack.ExposureStack.saturated`,
    :meth:`~photoquant.stack.ExposureStack.dark_clipped`); ``tabs`` ``(2, C·L)``
    holds ``g`` and its segments' slopes on ``levels``; ``quota`` ``(K − 1,)`` the pairs
    kept per step and channel at most. A value is valid where
    it is not clipped, ``g`` is finite there and its segment rises. Writes, as
    :func:`photoquant.exposure._selected_pairs` returns them, the rows kept
    (channel, position in ``order``) and the pairs (row, step, channel), and
    each pair's ``g`` and values at its two ends into ``ends`` ``(4, ·)``:
    ``y_lo, y_hi, z_lo, z_hi``.
    """
    n_rep, n_k, n_pix, n_ch = values.shape
    n_lv = levels.size
    count = np.zeros(max(n_k - 1, 1), dtype=np.int64)
    z = np.empty(n_k)
    y = np.empty(n_k)
    ok = np.empty(n_k, dtype=np.bool_)
    n_rows = 0
    n_pairs = 0
    for ch in range(n_ch):
        count[:] = 0
        for q in range(n_pix):
            p = order[q]
            for k in range(n_k):
                lo_v = values[0, k, p, ch]
                hi_v = lo_v
                total = np.int64(lo_v)
                for r in range(1, n_rep):
                    v = values[r, k, p, ch]
                    total += v
                    lo_v = min(lo_v, v)
                    hi_v = max(hi_v, v)
                z[k] = float(total) if n_rep == 1 else total / n_rep
                i, frac = table_index(z[k], levels, even, inv_step)
                base = ch * n_lv + i
                y[k] = lerp_at(tabs[0], base, frac)
                seg = lerp_at(tabs[1], base, frac)
                clipped = hi_v >= sat_thr[ch] or lo_v <= dark_thr[ch]
                ok[k] = (not clipped) and np.isfinite(y[k]) and seg > 0
            kept = False
            for j in range(n_k - 1):
                if ok[j] and ok[j + 1]:
                    count[j] += 1
                    if count[j] <= quota[j]:
                        if not kept:
                            keep[0, n_rows] = ch
                            keep[1, n_rows] = q
                            n_rows += 1
                            kept = True
                        entries[0, n_pairs] = n_rows - 1
                        entries[1, n_pairs] = j
                        entries[2, n_pairs] = ch
                        ends[0, n_pairs] = y[j]
                        ends[1, n_pairs] = y[j + 1]
                        ends[2, n_pairs] = z[j]
                        ends[3, n_pairs] = z[j + 1]
                        n_pairs += 1
    return n_rows, n_pairs


def pair_pass(
    y_lo: Any, y_hi: Any, z_lo: Any, z_hi: Any, s2_lo: Any, s2_hi: Any, chan: Any, step: Any,
    dx: Any, dx_nom: Any, line: Any, n_rep: int, levels: Any, even: bool, inv_step: float,
    d1: Any, d2: Any, g_mono: Any, bottom: Any, top: Any, margin: float, max_bend: float,
    code_step: float, rtable: Any, use: Any, w: Any, resid: Any, g2_lo: Any, g2_hi: Any,
) -> None:  # fmt: skip  # pragma: no cover - compiled by numba
    """One pass of :func:`photoquant.exposure.refine_by_pairs` (its numpy branch, value by
    value, the same operations in the same order): updates ``z_lo, z_hi, s2_lo, s2_hi``
    (the ends' levels and ``g''`` there), writes ``use, w, resid`` and, for the pairs
    used, ``g'²`` at both ends (a pair left out at its first end skips the rest of
    the second's arithmetic: its next pass needs only the levels and ``g''``)."""
    n_tab = rtable.size - 1
    for e in range(y_lo.size):
        c = chan[e]
        s = step[e]
        cy_lo = 0.0
        cy_hi = 0.0
        for end in range(2):
            zz = z_lo[e] if end == 0 else z_hi[e]
            v = max(line[c, 0] + line[c, 1] * zz, 1.0 / 12.0)
            if n_rep != 1:
                v = v / n_rep + rounding_at(np.sqrt(max(v - 1.0 / 12.0, 0.0)), rtable, n_tab)
            if end == 0:
                cy_lo = y_lo[e] - 0.5 * s2_lo[e] * v
            else:
                cy_hi = y_hi[e] - 0.5 * s2_hi[e] * v
        # each end's prediction lies near its value: the search starts at its interval
        zl = interp_near(
            cy_hi - dx[s], g_mono[c], levels, table_index(z_lo[e], levels, even, inv_step)[0]
        )
        zh = interp_near(
            cy_lo + dx[s], g_mono[c], levels, table_index(z_hi[e], levels, even, inv_step)[0]
        )
        z_lo[e] = zl
        z_hi[e] = zh
        ok = True
        var_sum = 0.0
        for end in range(2):
            zz = zl if end == 0 else zh
            i, frac = table_index(zz, levels, even, inv_step)
            s2 = lerp_at(d2[c], i, frac)
            if end == 0:
                s2_lo[e] = s2
            else:
                s2_hi[e] = s2
            if not ok:  # left out at its other end: g'' at the prediction is all it keeps
                continue
            s1 = lerp_at(d1[c], i, frac)
            v_one = max(line[c, 0] + line[c, 1] * zz, 1.0 / 12.0)
            r_one = rounding_at(np.sqrt(max(v_one - 1.0 / 12.0, 0.0)), rtable, n_tab)
            v_mean = v_one if n_rep == 1 else v_one / n_rep + r_one
            sigma = np.sqrt(v_one + r_one)
            bend = np.abs(s2) * max(sigma, code_step) / s1
            inside = zz >= bottom[c] + margin * sigma and zz <= top[c] - margin * sigma
            ok = inside and s1 > 0 and bend <= max_bend
            var_sum += s1 * s1 * v_mean
            if end == 0:
                cy_lo = y_lo[e] - 0.5 * s2 * v_mean
                g2_lo[e] = s1 * s1
            else:
                cy_hi = y_hi[e] - 0.5 * s2 * v_mean
                g2_hi[e] = s1 * s1
        weight = 1.0 / var_sum if ok else 0.0
        ok = ok and np.isfinite(weight) and weight > 0
        use[e] = ok
        w[e] = weight if ok else 0.0
        resid[e] = cy_hi - cy_lo - dx_nom[s] if ok else 0.0


def huber_iterations(
    resid: Any, w: Any, sqrt_w: Any, step: Any, used: Any, n_used: int, scale: float,
    huber_k: float, max_iterations: int, theta: Any, h: Any, u_last: Any,
) -> int:  # fmt: skip  # pragma: no cover - compiled by numba
    """:func:`photoquant.exposure._pair_offsets`' iterations (its numpy operations in
    order) over the pairs used, ``used[:n_used]`` (a pair left out has no weight and no
    residual: it adds exact zeros to the sums, and its ``h`` stays 1): updates
    ``theta`` in place, writes the last iteration's ``h`` and scaled residuals
    ``u_last`` of the pairs used, returns the iterations run."""
    n_steps = theta.size
    total = np.empty(n_steps)
    moment = np.empty(n_steps)
    iterations = 0
    for it in range(1, max_iterations + 1):
        iterations = it
        total[:] = 0.0
        moment[:] = 0.0
        for m in range(n_used):
            e = used[m]
            s = step[e]
            u = np.abs(resid[e] - theta[s]) * sqrt_w[e] / scale
            he = 1.0 if u <= huber_k else huber_k / max(u, 1e-300)
            u_last[e] = u
            h[e] = he
            wh = w[e] * he
            total[s] += wh
            moment[s] += wh * resid[e]
        change = 0.0
        for s in range(n_steps):
            new = moment[s] / (total[s] if total[s] > 0 else 1.0)
            change = max(change, np.abs(new - theta[s]))
            theta[s] = new
        if change < 1e-6:
            break
    return iterations


def _indices_of(flags: Any, out: Any) -> int:  # pragma: no cover - compiled by numba
    """The indices where ``flags`` holds, in order, into ``out``; returns how many (a
    kernel of its own: a count started at ``0`` in its caller is typed as the literal
    ``0`` first, and every kernel it is passed to compiles twice)."""
    n = 0
    for e in range(flags.size):
        if flags[e]:
            out[n] = e
            n += 1
    return n


def _longest_run(counts: Any, min_overlap: int) -> tuple[int, int]:  # pragma: no cover
    """:func:`photoquant.exposure._longest_run` of ``counts >= min_overlap``: the run of
    consecutive determined steps with the most values (the first of equals)."""
    best_start, best_stop, best_count = 0, 0, -1
    start = -1
    n = counts.size
    for j in range(n + 1):
        if j < n and counts[j] >= min_overlap:
            if start < 0:
                start = j
        elif start >= 0:
            total = 0
            for i in range(start, j):
                total += counts[i]
            if total > best_count:
                best_start, best_stop, best_count = start, j, total
            start = -1
    return best_start, best_stop


def _chain(
    x_nom: Any, theta: Any, start: int, stop: int, geometric_mean: bool, x: Any
) -> None:  # pragma: no cover - compiled by numba
    """:func:`photoquant.exposure._chain` into ``x``: the steps' offsets over the run
    ``start:stop`` chained to log times, the gauge kept."""
    for i in range(x.size):  # elementwise: a slice copy compiles numba's shape-error messages
        x[i] = x_nom[i]
    if stop <= start:
        return
    m = stop - start + 1
    rel = np.empty(m)
    rel[0] = 0.0
    acc = 0.0
    for j in range(start, stop):
        acc += (x_nom[j + 1] - x_nom[j]) + theta[j]
        rel[j - start + 1] = acc
    for i in range(m):
        rel[i] += x_nom[start]
    if geometric_mean:
        keep = np.mean(x_nom[start : stop + 1]) - np.mean(rel)
    else:
        keep = x_nom[stop] - rel[m - 1]
    for i in range(m):
        x[start + i] = rel[i] + keep


def _sandwich(
    resid: Any, w: Any, h: Any, u: Any, used: Any, n_used: int, theta: Any, row: Any,
    step: Any, huber_k: float, psi: Any, slope: Any, cov: Any,
) -> None:  # fmt: skip  # pragma: no cover - compiled by numba
    """:func:`photoquant.exposure._pair_offsets`' sandwich covariance of the steps' Huber
    locations into ``cov`` from the pairs used, ``used[:n_used]`` (a pair left out
    has ``ψ = 0`` and no slope; each (row, step) holds one pair); ``psi``
    ``(rows, steps)`` and ``slope`` are work space."""
    n_rows, n_steps = psi.shape
    psi[:] = 0.0
    slope[:] = 0.0
    for m in range(n_used):
        e = used[m]
        r = resid[e] - theta[step[e]]
        psi[row[e], step[e]] = w[e] * h[e] * r
        slope[step[e]] += w[e] * (u[e] <= huber_k)
    cov[:] = 0.0
    for r in range(n_rows):
        for i in range(n_steps):
            a = psi[r, i]
            if a != 0.0:
                for j in range(n_steps):
                    cov[i, j] += a * psi[r, j]
    for i in range(n_steps):
        for j in range(n_steps):
            si = slope[i] if slope[i] > 0 else np.inf
            sj = slope[j] if slope[j] > 0 else np.inf
            cov[i, j] = cov[i, j] / (si * sj)


def screen_passes(
    y_lo: Any, y_hi: Any, z_lo: Any, z_hi: Any, chan: Any, step: Any, row: Any, n_rows: int,
    x_nom: Any, line: Any, n_rep: int, levels: Any, even: bool, inv_step: float, d1: Any,
    d2: Any, g_mono: Any, bottom: Any, top: Any, margin: float, max_bend: float,
    code_step: float, rtable: Any, huber_k: float, max_iterations: int, min_overlap: int,
    geometric_mean: bool, passes: int, x: Any, cov: Any, counts: Any,
) -> tuple[int, int, float, int]:  # fmt: skip  # pragma: no cover - compiled by numba
    """The passes of :func:`photoquant.exposure._pair_passes`, all of them compiled.

    Writes the log times ``x``, the steps' covariance ``cov`` (the last pass's:
    the earlier passes need the locations only) and the pairs used per step
    ``counts``; refits ``line`` to the residuals between passes where
    ``n_rep == 1``; updates ``z_lo, z_hi`` to the last pass's predicted
    levels. Returns ``(run start, run stop, scale, iterations)``; an empty run
    (``stop <= start``) means no two neighbouring exposures share
    ``min_overlap`` values, and the caller raises.
    """
    n_pairs = y_lo.size
    n_steps = x_nom.size - 1
    n_ch = line.shape[0]
    s2_lo = np.empty(n_pairs)
    s2_hi = np.empty(n_pairs)
    for e in range(n_pairs):  # g'' at the observed values: the bias before any prediction
        for end in range(2):
            i, frac = table_index(z_lo[e] if end == 0 else z_hi[e], levels, even, inv_step)
            s2 = lerp_at(d2[chan[e]], i, frac)
            if end == 0:
                s2_lo[e] = s2
            else:
                s2_hi[e] = s2
    use = np.empty(n_pairs, dtype=np.bool_)
    w = np.empty(n_pairs)
    resid = np.empty(n_pairs)
    g2_lo = np.empty(n_pairs)
    g2_hi = np.empty(n_pairs)
    sqrt_w = np.empty(n_pairs)
    u = np.empty(n_pairs)
    u_last = np.empty(n_pairs)
    h = np.ones(n_pairs)
    used = np.empty(n_pairs, dtype=np.int64)
    theta = np.zeros(n_steps)
    total = np.empty(n_steps)
    moment = np.empty(n_steps)
    slope = np.empty(n_steps)
    dx = np.empty(n_steps)
    dx_nom = np.empty(n_steps)
    psi = np.empty((n_rows, n_steps))
    for j in range(n_steps):
        dx_nom[j] = x_nom[j + 1] - x_nom[j]
    for j in range(x.size):
        x[j] = x_nom[j]
    start, stop = 0, 0
    scale = 1.0
    iterations = 0
    n_passes = max(passes, 1)
    for pass_no in range(n_passes):
        last = pass_no == n_passes - 1
        for j in range(n_steps):
            dx[j] = x[j + 1] - x[j]
        pair_pass(
            y_lo, y_hi, z_lo, z_hi, s2_lo, s2_hi, chan, step, dx, dx_nom, line, n_rep,
            levels, even, inv_step, d1, d2, g_mono, bottom, top, margin, max_bend, code_step,
            rtable, use, w, resid, g2_lo, g2_hi,
        )  # fmt: skip
        # the pairs used (the others have no weight and no residual: exact zeros in
        # every sum below), the steps' weighted means, the scale (MAD), the Huber
        # iterations
        n_use = _indices_of(use, used)
        total[:] = 0.0
        moment[:] = 0.0
        for m in range(n_use):
            e = used[m]
            sqrt_w[e] = np.sqrt(w[e])
            total[step[e]] += w[e]
            moment[step[e]] += w[e] * resid[e]
        for j in range(n_steps):
            theta[j] = moment[j] / (total[j] if total[j] > 0 else 1.0)
        scale = 1.0
        if n_use:
            scaled = np.empty(n_use)
            for m in range(n_use):
                e = used[m]
                u[e] = np.abs(resid[e] - theta[step[e]]) * sqrt_w[e]
                scaled[m] = u[e]
            scale = median_inplace(scaled) / 0.6745
            if scale == 0.0:
                scale = 1.0
        h[:] = 1.0
        iterations = huber_iterations(
            resid, w, sqrt_w, step, used, n_use, scale, huber_k, max_iterations, theta, h,
            u_last,
        )  # fmt: skip
        if iterations:
            for m in range(n_use):
                u[used[m]] = u_last[used[m]]
        counts[:] = 0
        for m in range(n_use):
            counts[step[used[m]]] += 1
        start, stop = _longest_run(counts, min_overlap)
        if stop <= start:
            return start, stop, scale, iterations
        _chain(x_nom, theta, start, stop, geometric_mean, x)
        if last:  # the sandwich covariance: ψ per (row, step), its cross-products over rows
            _sandwich(resid, w, h, u, used, n_use, theta, row, step, huber_k, psi, slope, cov)
        elif n_rep == 1:  # the noise line from the residuals: E r² = Σ g'² v(z), both ends
            for ch in range(n_ch):
                n_in = 0
                m00 = m01 = m11 = r0 = r1 = 0.0
                for m in range(n_use):
                    e = used[m]
                    if h[e] >= 1.0 and chan[e] == ch:
                        n_in += 1
                        a = g2_lo[e] + g2_hi[e]
                        b = g2_lo[e] * z_lo[e] + g2_hi[e] * z_hi[e]
                        d = resid[e] - theta[step[e]]
                        r2 = d * d
                        m00 += a * a
                        m01 += a * b
                        m11 += b * b
                        r0 += a * r2
                        r1 += b * r2
                if n_in < 10:
                    continue
                det = m00 * m11 - m01 * m01
                if not (np.isfinite(det) and abs(det) > 1e-12 * abs(m00 * m11)):
                    continue
                c0 = (m11 * r0 - m01 * r1) / det
                c1 = (m00 * r1 - m01 * r0) / det
                if np.isfinite(c0) and np.isfinite(c1):
                    line[ch, 0] = c0
                    line[ch, 1] = c1
    return start, stop, scale, iterations


if HAVE_NUMBA:  # pragma: no cover - depends on the environment
    rounding_at = compile_kernel(rounding_at, error_model="numpy")
    interp_near = compile_kernel(interp_near, error_model="numpy")
    table_index = compile_kernel(table_index, error_model="numpy")
    lerp_at = compile_kernel(lerp_at, error_model="numpy")
    pairs_of_values = compile_kernel(pairs_of_values, error_model="numpy")
    pair_pass = compile_kernel(pair_pass, error_model="numpy")
    huber_iterations = compile_kernel(huber_iterations, error_model="numpy")
    _indices_of = compile_kernel(_indices_of)
    _longest_run = compile_kernel(_longest_run)
    _chain = compile_kernel(_chain, error_model="numpy")
    _sandwich = compile_kernel(_sandwich, error_model="numpy")
    screen_passes = compile_kernel(screen_passes, error_model="numpy")
