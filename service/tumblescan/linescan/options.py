"""Options of the line-scan estimators, one model per input form.

Tracks and frames share the model choice, the reference time, the sensor noise, the seed and
the validation settings; the search over starts (strategy, objective, swarm) belongs to
tracks, the frame period and the dense fit to frames. An option given to the form it does
not apply to is refused (the models forbid extra names), never ignored. ``EstimateOptions``
carries every option, for library users who call either estimator.
"""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field

from ..errors import InvalidOptionError
from .choices import ModelChoice, Objective, Strategy
from .sensor import SensorNoise
from .swarm import SwarmConfig
from .tracks import MIN_FRAMES


class DenseConfig(BaseModel):
    """Sampling and iteration settings of the dense refinement (lengths in metres)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    surfel_m: float | None = Field(None, gt=0, description="surfel size; default (estimate_from_frames): extent / 100")
    partners: int = Field(2, ge=1, le=100, description="other frames each surfel is matched in (second stage)")
    fine_partners: int = Field(
        14, ge=1, le=100, description="other frames each surfel is matched in (last stage; all of them if fewer)"
    )
    near_window: int = Field(2, ge=1, le=100, description="frames either side matched in the first stage")
    max_iterations: int = Field(15, ge=1, le=1000, description="Gauss-Newton steps in each of the first two stages")
    fine_iterations: int = Field(6, ge=1, le=1000, description="Gauss-Newton steps in the last stage")
    tolerance: float = Field(
        0.1, gt=0, le=1, description="stop a stage when no parameter moves more than this many standard deviations"
    )
    beams: bool = Field(
        True, description="fit thin members (booms, truss wires) as lines too, from the second stage on"
    )
    grazing: bool = Field(
        True,
        description="in the last stage, match the hits seen at grazing incidence that no planar surfel holds "
        "against the other frames' planar surfels",
    )


class CommonOptions(BaseModel):
    """What both estimators take."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    model: ModelChoice = Field("auto", description="auto chooses spin-only vs spin-precession by an F-test")
    reference_time_s: float | None = Field(None, allow_inf_nan=False, description="default: first observation")
    seed: int = Field(0, ge=0, le=2**63 - 1)
    sensor: SensorNoise | None = Field(None, description="overrides the noise declared with the input")
    validation_frames: int | None = Field(None, ge=MIN_FRAMES, description="frames in the second solve")
    significance: float = Field(1e-3, gt=0, lt=0.5, description="level of the model and similarity tests")

    def reference_time(self, t_first_s: float, t_last_s: float) -> float:
        """The time T the motion is stated at: the option, or the first observation's time.

        T may lie outside the observations by at most their span (at least 1 s): the phase
        ω·(t - T) of a far T loses the digits the fit needs, and the estimate would fail its
        own validation after a full run instead of being refused here.
        """
        if self.reference_time_s is None:
            return t_first_s
        check_reference_time(
            self.reference_time_s, t_first_s, t_last_s, named="options.reference_time_s =",
            whose="the observations", field="options.reference_time_s",
        )  # fmt: skip
        return self.reference_time_s


def check_reference_time(T_s: float, t_first_s: float, t_last_s: float, *, named: str, whose: str, field: str) -> None:
    """A reference time ``T_s`` within the times' span (at least 1 s) of ``t_first_s`` ..
    ``t_last_s``, or ``InvalidOptionError`` saying so (``named``: how the message names it,
    ``whose``: the times): the phase of a far T loses the digits a fit or a rectified point needs."""
    reach_s = max(t_last_s - t_first_s, 1.0)
    if not t_first_s - reach_s <= T_s <= t_last_s + reach_s:
        raise InvalidOptionError(
            f"{named} {T_s:g} s lies too far from {whose} ({t_first_s:g} to {t_last_s:g} s): "
            f"keep it within {reach_s:g} s of them",
            field=field,
        )


class TracksOptions(CommonOptions):
    """Options of :func:`estimate_motion` (feature tracks)."""

    strategy: Strategy = Field("auto", description="auto: initializer if it validates, else swarm; then LM")
    objective: Objective = Field("ml", description="ml (maximum likelihood) or pairwise (paper eq. 10)")
    swarm: SwarmConfig = SwarmConfig()
    max_attempts: int = Field(3, ge=1, le=20)
    reject_outliers: bool = True


class FramesOptions(CommonOptions):
    """Options of :func:`estimate_from_frames` (dense frames)."""

    frame_period_s: float | None = Field(
        None, gt=0, allow_inf_nan=False, description="frames input without frame indices: the scanner's frame period"
    )
    dense: DenseConfig = Field(DenseConfig(), description="sampling and iterations of the dense fit")


class EstimateOptions(TracksOptions, FramesOptions):
    """Every option of both estimators (library use; the service takes one form's options)."""
