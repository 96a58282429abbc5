"""Dependencies: the job service and the caller's identity."""

from __future__ import annotations

import hashlib
import hmac
from dataclasses import dataclass
from typing import Annotated

from fastapi import Depends, HTTPException, Request, status

from ..jobs.service import JobService


def get_service(request: Request) -> JobService:
    service: JobService = request.app.state.service
    return service


def key_id(key: str) -> str:
    """What a job records of the key that created it: a hash, never the key."""
    return hashlib.sha256(key.encode()).hexdigest()[:32]


KEY_COOKIE = "tumblescan_key"


def presented_key(request: Request) -> str:
    """``Authorization: Bearer <key>``; for pages opened in a browser also ``?api_key=`` or the
    cookie it leaves, in that order: a key given in the URL is the one meant (a stale cookie
    neither hides it nor answers for it)."""
    scheme, _, key = request.headers.get("authorization", "").partition(" ")
    if scheme.lower() == "bearer" and key.strip():
        return key.strip()
    return request.query_params.get("api_key") or request.cookies.get(KEY_COOKIE) or ""


@dataclass(frozen=True)
class Caller:
    """Who is asking: the key id new jobs are recorded under, and whether it sees every job."""

    key_id: str | None
    admin: bool

    @property
    def scope(self) -> str | None:
        """The owner filter for reads and cancellations (None: all jobs)."""
        return None if self.admin else self.key_id


def get_caller(request: Request) -> Caller:
    """The caller when keys are configured (401 without a valid one); open access otherwise."""
    users: list[str] = request.app.state.key_hashes
    admins: list[str] = request.app.state.admin_hashes
    if not users and not admins:
        return Caller(None, admin=True)
    key = presented_key(request)
    if not key:
        raise HTTPException(
            status.HTTP_401_UNAUTHORIZED,
            "missing API key (Authorization: Bearer <key>)",
            headers={"WWW-Authenticate": "Bearer"},
        )
    kid = key_id(key)
    if any(hmac.compare_digest(kid, h) for h in admins):
        return Caller(kid, admin=True)
    if any(hmac.compare_digest(kid, h) for h in users):
        return Caller(kid, admin=False)
    raise HTTPException(status.HTTP_401_UNAUTHORIZED, "invalid API key", headers={"WWW-Authenticate": "Bearer"})


ServiceDep = Annotated[JobService, Depends(get_service)]
CallerDep = Annotated[Caller, Depends(get_caller)]
