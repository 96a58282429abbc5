"""One typed result model per job kind; :func:`result_model` picks it by the job's kind."""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict

from .bearings import BearingsResult
from .linescan import MotionResult
from .marker_pose import MarkerPoseResult
from .panel_axis import PanelAxisResult
from .spin_rate import SpinResult

# Kind name -> result model (one line per kind, as in the service's registry).
RESULT_MODELS: dict[str, type[BaseModel]] = {
    "linescan-motion": MotionResult,
    "panel-axis": PanelAxisResult,
    "bearings": BearingsResult,
    "marker-pose-graph": MarkerPoseResult,
    "spin-from-images": SpinResult,
}


class UnknownResult(BaseModel):
    """The result of a kind this client does not know yet: every field kept as is."""

    model_config = ConfigDict(extra="allow")


def result_model(kind: str) -> type[BaseModel]:
    return RESULT_MODELS.get(kind, UnknownResult)


__all__ = [
    "RESULT_MODELS",
    "BearingsResult",
    "MarkerPoseResult",
    "MotionResult",
    "PanelAxisResult",
    "SpinResult",
    "UnknownResult",
    "result_model",
]
