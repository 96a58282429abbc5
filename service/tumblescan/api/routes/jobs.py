"""``/v1/jobs``: create, upload, read, list, download the cloud, cancel."""

from __future__ import annotations

import json
import tempfile
from typing import Annotated, Any, Literal

import numpy as np
from fastapi import APIRouter, File, Form, HTTPException, Query, Request, Response, UploadFile, status
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import FileResponse
from starlette.background import BackgroundTask

from ...cloud_io import read_ply
from ...errors import MalformedInputError
from ...jobs.store import FINAL, Job
from ..deps import CallerDep, ServiceDep
from ..schemas import ErrorBody, JobCreate, JobList, JobPublic, Status

router = APIRouter(prefix="/v1/jobs", tags=["jobs"])
ERRORS: dict[int | str, dict[str, Any]] = {code: {"model": ErrorBody} for code in (400, 401, 404, 413, 422, 503, 507)}


def base_url(request: Request) -> str:
    configured = request.app.state.settings.public_url
    return (configured or str(request.base_url)).rstrip("/")


def public(job: Job, request: Request) -> JobPublic:
    return JobPublic.from_job(job, base_url(request))


def accepted(job: Job, request: Request, response: Response) -> JobPublic:
    response.headers["Location"] = f"{base_url(request)}/v1/jobs/{job.id}"
    return public(job, request)


@router.post("", status_code=status.HTTP_202_ACCEPTED, responses=ERRORS)
def create_job(
    body: JobCreate, request: Request, response: Response, service: ServiceDep, caller: CallerDep
) -> JobPublic:
    """Queue a job from JSON input (``{"tracks": ...}`` for linescan-motion)."""
    job = service.submit_json(body.kind, body.input, body.options, caller.key_id)
    return accepted(job, request, response)


@router.post("/upload", status_code=status.HTTP_202_ACCEPTED, responses=ERRORS)
def upload_job(
    request: Request,
    response: Response,
    service: ServiceDep,
    caller: CallerDep,
    file: Annotated[UploadFile, File(description="tracks (JSON or CSV)")],
    cloud: Annotated[UploadFile | None, File(description="optional PLY with per-point times to rectify")] = None,
    truth: Annotated[
        UploadFile | None, File(description="optional truth.json of a simulation, shown in the report")
    ] = None,
    options: Annotated[str, Form(description="the kind's options as a JSON object")] = "{}",
    kind: Annotated[str, Form()] = "linescan-motion",
) -> JobPublic:
    """Queue a job from uploaded files; they are streamed to disk, never held in memory."""
    try:
        opts = json.loads(options)
    except json.JSONDecodeError as exc:
        raise MalformedInputError(f"options is not valid JSON: {exc.msg}", field="options") from None
    if not isinstance(opts, dict):
        raise MalformedInputError("options must be a JSON object", field="options")
    files = {"file": file.file} | {name: f.file for name, f in (("cloud", cloud), ("truth", truth)) if f is not None}
    job = service.submit_upload(kind, files, opts, caller.key_id)
    return accepted(job, request, response)


@router.get("", responses=ERRORS)
def list_jobs(
    request: Request,
    service: ServiceDep,
    caller: CallerDep,
    status_: Annotated[Status | None, Query(alias="status")] = None,
    limit: Annotated[int, Query(ge=1, le=500)] = 50,
    cursor: Annotated[str | None, Query(max_length=200)] = None,
) -> JobList:
    """Jobs newest first, optionally by status; follow ``next_cursor`` for more."""
    try:
        jobs, nxt = service.list(status=status_, owner=caller.scope, limit=limit, cursor=cursor)
    except ValueError as exc:
        raise MalformedInputError(str(exc), field="cursor") from None
    return JobList(items=[public(j, request) for j in jobs], next_cursor=nxt)


@router.get("/{job_id}", responses=ERRORS)
async def get_job(
    job_id: str,
    request: Request,
    service: ServiceDep,
    caller: CallerDep,
    wait: Annotated[float, Query(ge=0, le=30, description="long poll: hold up to this many seconds for a change")] = 0,
) -> JobPublic:
    """A job's status, progress, result and artifact links. With ``wait`` the answer comes as
    soon as the job's status, stage or progress changes, or when ``wait`` runs out."""
    # Waiting happens on the event loop (one shared watcher), so waiting clients hold no threads.
    job = _found(await run_in_threadpool(service.get, job_id, caller.scope), job_id)
    if wait > 0 and job.status not in FINAL:
        await request.app.state.watcher.wait_for_change(job_id, (job.status, job.stage, job.progress), wait)
        job = _found(await run_in_threadpool(service.get, job_id, caller.scope), job_id)
    return public(job, request)


@router.get(
    "/{job_id}/cloud",
    responses={
        **ERRORS,
        200: {"content": {"application/octet-stream": {}}, "description": "binary PLY or NPZ"},
        409: {"model": ErrorBody},
    },
    response_class=FileResponse,
)
def get_job_cloud(
    job_id: str, service: ServiceDep, caller: CallerDep, format: Annotated[Literal["ply", "npz"], Query()] = "ply"
) -> FileResponse:
    """The rectified cloud: binary PLY (default) or NPZ (``xyz_m``, ``t_s`` and every other field)."""
    job = _found(service.get(job_id, caller.scope), job_id)
    if job.status != "succeeded":
        raise HTTPException(
            status.HTTP_409_CONFLICT, f"job {job_id} is {job.status}; the cloud exists once it has succeeded"
        )
    if "cloud" not in job.artifacts or job.artifacts_deleted:
        raise HTTPException(
            status.HTTP_404_NOT_FOUND, f"job {job_id} has no cloud (submit one with the tracks to get it rectified)"
        )
    path = service.artifacts.path(job_id, job.artifacts["cloud"])
    if format == "ply":
        return FileResponse(path, media_type="application/octet-stream", filename=f"{job_id}-rectified.ply")
    cloud = read_ply(path)
    tmp = tempfile.NamedTemporaryFile(suffix=".npz", delete=False)  # noqa: SIM115 (removed after sending)
    with tmp:
        arrays: dict[str, Any] = {"xyz_m": cloud.xyz_m, "t_s": cloud.t_s, **cloud.fields}
        np.savez(tmp, **arrays)
    return FileResponse(
        tmp.name,
        media_type="application/octet-stream",
        filename=f"{job_id}-rectified.npz",
        background=BackgroundTask(_unlink, tmp.name),
    )


@router.get(
    "/{job_id}/report",
    responses={
        **ERRORS,
        200: {"content": {"text/html": {}}, "description": "self-contained HTML"},
        409: {"model": ErrorBody},
    },
    response_class=FileResponse,
)
def get_job_report(job_id: str, service: ServiceDep, caller: CallerDep) -> FileResponse:
    """The job's report: one self-contained HTML file that works offline."""
    job = _found(service.get(job_id, caller.scope), job_id)
    if job.status != "succeeded" or job.artifacts_deleted:
        raise HTTPException(
            status.HTTP_409_CONFLICT, f"job {job_id} is {job.status}; its report exists once it has succeeded"
        )
    return FileResponse(service.report_path(job), media_type="text/html")


@router.delete("/{job_id}", responses=ERRORS)
def cancel_job(job_id: str, request: Request, service: ServiceDep, caller: CallerDep) -> JobPublic:
    """Cancel a queued or running job (a running one stops at its next check, within seconds);
    its files are deleted once it has stopped. Finished jobs are returned unchanged."""
    return public(_found(service.cancel(job_id, caller.scope), job_id), request)


def _found(job: Job | None, job_id: str) -> Job:
    if job is None:
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"job {job_id} not found")
    return job


def _unlink(path: str) -> None:
    import os

    os.unlink(path)
