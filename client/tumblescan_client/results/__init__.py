"""One typed result model per job kind; :func:`result_model` picks it by the job's kind."""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict

from .linescan import MotionResult
from .marker_pose import MarkerPoseResult

# Kind name -> result model (one line per kind, as in the service's registry).
RESULT_MODELS: dict[str, type[BaseModel]] = {
    "linescan-motion": MotionResult,
    "marker-pose-graph": MarkerPoseResult,
}


class UnknownResult(BaseModel):
    """The result of a kind this client does not know yet: every field kept as is."""

    model_config = ConfigDict(extra="allow")


def result_model(kind: str) -> type[BaseModel]:
    return RESULT_MODELS.get(kind, UnknownResult)


__all__ = ["RESULT_MODELS", "MarkerPoseResult", "MotionResult", "UnknownResult", "result_model"]
