"""The named choices of the line-scan options, apart from the options themselves so that the
CLI can declare its flags without loading NumPy."""

from __future__ import annotations

from typing import Literal

Strategy = Literal["auto", "lm", "swarm"]
Objective = Literal["ml", "pairwise"]
ModelChoice = Literal["auto", "spin-precession", "spin-only"]
ShapeName = Literal["box", "telescope", "dish-boom", "long-array", "octagon-truss"]
