"""Options of an estimate (the job's options model).

Options arrive as JSON, where pydantic's lax mode took ``"return_tracks": "yes"`` (or 1) for
true: the flag is strict. ``method`` is one of two strings, which lax mode never coerced. Strict
per field rather than for the model: pydantic's mypy plugin types a strict model's constructor
strictly, and callers pass a ``str`` checked elsewhere. No NaN or Infinity for any number an
option may take (``allow_inf_nan=False``; pydantic says "finite number")."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, Strict


class EstimateOptions(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)

    method: Literal["ours", "paper"] = Field(
        "ours", description="ours (rigid-body fit) or the paper's (mean end points, sine fit)"
    )
    return_tracks: Annotated[bool, Strict()] | None = Field(
        None, description="add per-track observations, a JSON bool (default: meta.json's options)"
    )
