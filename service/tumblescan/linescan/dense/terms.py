"""What the dense fit's residuals are made of: the surfel pairs (:mod:`.matching`), the thin
members (:mod:`.beams`) and the grazing hits' groups (:mod:`.grazing`), in that order, in the
cost, its steps and the covariance (:mod:`.refine`)."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..._typing import FloatArray
from ..sensor import SensorNoise
from .beams import Beams, beam_rows
from .data import DenseData
from .grazing import Grazing, find_grazing, grazing_rows
from .mapping import LineMapping
from .matching import Linearized, Matches, linearize, residuals, robust_sigma
from .surfels import Surfels


@dataclass(frozen=True)
class Terms:
    """What the residuals are made of: the surfels, their correspondences, the thin members and
    the grazing hits' groups; ``grazing_scale2`` the groups' variances' factor (:meth:`linearize`)."""

    surf: Surfels
    matches: Matches
    beams: Beams
    grazing: Grazing = field(default_factory=Grazing.none)
    grazing_scale2: float = 1.0

    def linearize(self, data: DenseData, noise: SensorNoise, mapping: LineMapping) -> Linearized:
        """The surfels' residuals (:func:`.matching.linearize`), then the members'
        (:func:`.beams.beam_rows`), then the grazing groups' (:func:`.grazing.grazing_rows`)."""
        lin = linearize(data, mapping, self.surf, self.matches, noise)
        rows, Js, var = [lin.r], [lin.J], [lin.var]
        if self.beams.members:
            r, J, _ = beam_rows(self.beams, data, mapping)
            assert J is not None
            rows.append(r)
            Js.append(J)
            var.append(self.beams.row_var_m2)
        if self.grazing.groups:
            r, J, v = grazing_rows(self.grazing, self.surf, mapping, noise)
            assert J is not None
            rows.append(r)
            Js.append(J)
            var.append(v * self.grazing_scale2)
        if len(rows) == 1:
            return lin
        return Linearized(np.concatenate(rows), np.vstack(Js), np.concatenate(var))

    def residuals(self, data: DenseData, noise: SensorNoise, mapping: LineMapping) -> FloatArray:
        """The residuals alone, in the order of :meth:`linearize`."""
        rows = [residuals(mapping, self.surf, self.matches)[0]]
        if self.beams.members:
            rows.append(beam_rows(self.beams, data, mapping, jacobian=False)[0])
        if self.grazing.groups:
            rows.append(grazing_rows(self.grazing, self.surf, mapping, noise, jacobian=False)[0])
        return rows[0] if len(rows) == 1 else np.concatenate(rows)

    def positions(self, data: DenseData, mapping: LineMapping) -> FloatArray:
        """Where each residual's source lies at ``T`` (its patch, for the covariance)."""
        m, surf = self.matches, self.surf
        where = [mapping.apply(surf.anchor_obs[m.src], surf.line[m.src])]
        if self.beams.members:
            hits = mapping.apply(data.xyz_m[self.beams.point], data.line[self.beams.point])
            where += [hits, hits]  # a row across, then one along the sight, per hit
        if self.grazing.groups:
            where.append(mapping.apply(self.grazing.xyz_obs, self.grazing.line))
        return where[0] if len(where) == 1 else np.vstack(where)

    def with_grazing(self, data: DenseData, noise: SensorNoise, mapping: LineMapping) -> Terms:
        """These terms with the grazing groups found at ``mapping`` (:func:`.grazing.find_grazing`),
        off the members' hits, their variances scaled so that their robust scale is the surfel
        pairs' (each kind of residual has its own misfit; one scale would weigh one by the other's)."""
        return self.with_groups(
            find_grazing(data, mapping, self.surf, noise, exclude=self.beams.point), data, noise, mapping
        )

    def with_groups(self, groups: Grazing, data: DenseData, noise: SensorNoise, mapping: LineMapping) -> Terms:
        """These terms with ``groups``, scaled at ``mapping`` as :meth:`with_grazing` scales its own."""
        if groups.groups == 0:
            return replace(self, grazing=groups, grazing_scale2=1.0)
        pairs = linearize(data, mapping, self.surf, self.matches, noise)
        r_g, _, var_g = grazing_rows(groups, self.surf, mapping, noise, jacobian=False)
        s_p = robust_sigma(pairs.r / np.sqrt(pairs.var))
        s_g = robust_sigma(r_g / np.sqrt(var_g))
        return replace(self, grazing=groups, grazing_scale2=(s_g / s_p) ** 2 if s_p > 0 and s_g > 0 else 1.0)
