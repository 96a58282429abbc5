"""Each surfel's misfit: how far its anchor sits off the surface its partners in other frames see.

A planar surfel's anchor is where its plane meets the surface under its centroid. On a surface
that is not a plane at the cell's scale (a small part, a dish's rim, a bend between two facets)
it lies off that surface by an amount no noise model of the points predicts, and the same in
every residual the surfel takes part in: as the source of ``r_k = n . (a_s - a_t)`` and, with the
sign turned, as a target. Its mean over them,

    delta_s = sum_k sgn_k r_k / var_k / sum_k 1 / var_k        (sgn_k = +1 as source, -1 as target)

is the anchor's own error plus the average of its partners' errors, with variance

    v_s = var_s / N_s + 1 / sum_k 1 / var_k

when the model holds (``var_s / N_s`` the anchor's noise along its normal, ``var_k`` the
residuals' model variances of :func:`.matching.linearize`). The misfit is what is left over,

    tau_s^2 = max(0, delta_s^2 / s^2 - v_s)

in the model's units (``s`` the residuals' common scale), and adds to the variance of every
residual the surfel takes part in. A residual weighs a misfitting surfel down by the Cauchy
loss only once it lies several sigmas out; a surfel whose offset is one or two sigmas in every
one of its 14 partner frames pulls the fit by as much in every one, and that pull is a bias.
With it its residuals weigh what the data say they are worth.

An experiment, measured and reverted (docs/linescan.md, 2026-11-29, seventh round): one Newton
step from the truth with the misfit read *at the truth* promised much (RMS error over the bound
on Hubble 2.31 -> 1.52, the telescope 2.04 -> 1.47, the box 1.35 -> 1.09), but the whole fit
scored 104 of 120 against main's 107, and with the misfit read at the optimum of the linearised
cost (:func:`at_optimum`) 105; read there, the step from the truth gains on Hubble alone.
"""

from __future__ import annotations

import numpy as np

from ..._typing import BoolArray, FloatArray
from .matching import Linearized, Matches, cauchyweights, robust_sigma
from .surfels import Surfels

# Reweighted solves of the linearised cost before the misfit is read (:func:`at_optimum`).
OPTIMUM_SOLVES = 5


def surfel_misfit(surf: Surfels, matches: Matches, lin: Linearized) -> FloatArray:
    """``tau_s^2`` of the module docstring for every surfel ``(m,)``, in units of the residuals'
    model variance (zero for a surfel without residuals); arguments as :func:`surfel_offsets`."""
    offset2, expected, seen = surfel_offsets(surf, matches, lin)
    return np.where(seen, np.maximum(offset2 - expected, 0.0), 0.0)


def surfel_offsets(surf: Surfels, matches: Matches, lin: Linearized) -> tuple[FloatArray, FloatArray, BoolArray]:
    """Each surfel's ``delta_s^2 / s^2`` and ``v_s`` of the module docstring ``(m,)`` (model
    units), and whether it has residuals, read at the optimum of the linearised cost
    (:func:`at_optimum`).

    surf: the surfels the residuals were formed from. matches: their correspondences; the first
    ``len(matches.src)`` rows of ``lin`` are theirs (any thin members' rows follow; they take
    part in the optimum only). lin: the residuals ``r`` (m), their derivatives and model
    variances ``var`` (m^2); their common scale ``s`` is the robust sigma of ``r / sqrt(var)``,
    as in :func:`.matching.weights`."""
    m = len(surf.line)
    k = len(matches.src)
    r, w = at_optimum(lin)[:k], 1.0 / lin.var[:k]
    scale = max(robust_sigma(r * np.sqrt(w)), 1e-12)
    pull = np.bincount(matches.src, w * r, minlength=m) - np.bincount(matches.dst, w * r, minlength=m)
    weight = np.bincount(matches.src, w, minlength=m) + np.bincount(matches.dst, w, minlength=m)
    seen = weight > 0
    delta = np.divide(pull, weight, out=np.zeros(m), where=seen)
    expected = surf.var_m2 / np.maximum(surf.count, 1) + np.divide(1.0, weight, out=np.zeros(m), where=seen)
    return delta**2 / scale**2, expected, seen


def at_optimum(lin: Linearized, *, solves: int = OPTIMUM_SOLVES) -> FloatArray:
    """The residuals ``(n,)`` (m) at the optimum of the Cauchy cost of the linearised residuals
    ``r + J dx``, by ``solves`` reweighted least-squares solves from ``dx = 0``.

    Read away from the optimum, a surfel's mean residual holds what the motion has yet to fit:
    the frames' offsets from one another, the same over a patch of the target. Taken as misfit
    it weighs down the very residuals that would correct the motion; measured at the start of
    the last stage (the second stage's motion, some bounds off) it made the whole fit worse
    than without it (docs/linescan.md, seventh round)."""
    r = lin.r
    for _ in range(solves):
        w = cauchyweights(r / np.sqrt(lin.var), robust_sigma(r / np.sqrt(lin.var))) / lin.var
        Jw = lin.J * w[:, None]
        dx = np.linalg.lstsq(Jw.T @ lin.J, -(Jw.T @ lin.r), rcond=None)[0]
        r = lin.r + lin.J @ dx
    return np.asarray(r)
