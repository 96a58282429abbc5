"""``/v1/kinds``: what this service runs, with each kind's input forms, option and result
schemas, artifacts and limits (all read from the registry)."""

from __future__ import annotations

from fastapi import APIRouter, HTTPException, Request, status

from ...jobs.registry import kinds
from ..deps import CallerDep, ServiceDep
from ..schemas import ErrorBody, KindPublic, KindSummary
from .jobs import base_url

router = APIRouter(prefix="/v1/kinds", tags=["kinds"])


@router.get("", responses={401: {"model": ErrorBody}})
def list_kinds(request: Request, caller: CallerDep) -> list[KindSummary]:
    """Every job kind, by name."""
    base = base_url(request)
    return [KindSummary(name=k.name, title=k.title, url=f"{base}/v1/kinds/{k.name}") for k in kinds().values()]


@router.get("/{name}", responses={401: {"model": ErrorBody}, 404: {"model": ErrorBody}})
def get_kind_details(name: str, service: ServiceDep, caller: CallerDep) -> KindPublic:
    """One kind: its input forms (upload parts, JSON input) with their options' JSON schema,
    its result's JSON schema, its artifacts and this deployment's limits."""
    kind = kinds().get(name)
    if kind is None:
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"no job kind {name!r}; GET /v1/kinds lists them")
    return KindPublic.from_kind(kind, service.limits(kind))
