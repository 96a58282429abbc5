"""``/v1/jobs``: create, upload, read, list, artifacts, report, cancel."""

from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from fastapi import APIRouter, HTTPException, Query, Request, Response, status
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import FileResponse
from starlette.background import BackgroundTask
from starlette.datastructures import FormData

from ...errors import MalformedInputError
from ...io.json_text import parse_json
from ...io.ply import read_ply
from ...jobs.artifacts import safe_name
from ...jobs.registry import get_kind
from ...jobs.service import REPORT_FILE, ArtifactMissingError, JobService, Upload
from ...jobs.tables import FINAL, Job
from ..deps import CallerDep, ServiceDep
from ..errors import WrongContentTypeError
from ..schemas import (
    DEFAULT_KIND,
    REPORT_TEXT,
    ArtifactPublic,
    ErrorBody,
    JobCreate,
    JobList,
    JobPublic,
    Status,
    upload_schema,
)

router = APIRouter(prefix="/v1/jobs", tags=["jobs"])
ERRORS: dict[int | str, dict[str, Any]] = {code: {"model": ErrorBody} for code in (400, 401, 404, 413, 422, 503, 507)}
# A succeeded job's files: 409 before it has succeeded, 410 when a file has gone from the store.
FILE_ERRORS: dict[int | str, dict[str, Any]] = {
    **ERRORS,
    409: {"model": ErrorBody, "description": "the job has not succeeded"},
    410: {"model": ErrorBody, "description": "the file is no longer in the artifact store (artifact_missing)"},
}
# An image sequence may come as many files; the body limit still bounds the total size.
MAX_FILES, MAX_FIELDS = 5000, 100
FORM_TYPES = ("multipart/form-data", "application/x-www-form-urlencoded")


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
    """Queue a job from JSON input (the kinds whose forms take JSON; ``{"tracks": ...}`` for
    linescan-motion)."""
    job = service.submit_json(body.kind, body.input, body.options, caller.key_id)
    return accepted(job, request, response)


UPLOAD_BODY = upload_schema()


@router.post(
    "/upload",
    status_code=status.HTTP_202_ACCEPTED,
    responses=ERRORS,
    openapi_extra={"requestBody": {"required": True, "content": {"multipart/form-data": {"schema": UPLOAD_BODY}}}},
)
async def upload_job(request: Request, response: Response, service: ServiceDep, caller: CallerDep) -> JobPublic:
    """Queue a job from uploaded files: ``kind``, ``options`` (JSON) and the kind's parts
    (``GET /v1/kinds/{name}`` lists them). Files are streamed to disk, never held in memory."""
    media = request.headers.get("content-type", "").partition(";")[0].strip()
    if media.lower() not in FORM_TYPES:  # JSON or else would be read as a form without a file
        given = media or "a body without a Content-Type"
        raise WrongContentTypeError(
            f"body: POST /v1/jobs/upload takes multipart/form-data, not {given}; JSON input goes to POST /v1/jobs",
            field="body",
        )
    form = await request.form(max_files=MAX_FILES, max_fields=MAX_FIELDS)
    try:
        kind, options, files = _parse_upload(form)
        job = await run_in_threadpool(service.submit_upload, kind, files, options, caller.key_id)
    finally:
        await form.close()
    return accepted(job, request, response)


def _parse_upload(form: FormData) -> tuple[str, dict[str, Any], dict[str, list[Upload]]]:
    """The kind, the options and the files by field; text where a file belongs is an error."""
    for single in ("kind", "options"):
        if (n := len(form.getlist(single))) > 1:
            raise MalformedInputError(f"{single} is given {n} times; give it once", field=single)
    kind = form.get("kind", DEFAULT_KIND)
    raw = form.get("options", "{}")
    if not isinstance(kind, str):
        raise MalformedInputError("kind must be a text field, not a file", field="kind")
    if not isinstance(raw, str):
        raise MalformedInputError("options must be a text field holding a JSON object", field="options")
    options = parse_json(raw, "options", error=MalformedInputError)
    if not isinstance(options, dict):
        raise MalformedInputError("options must be a JSON object", field="options")
    files: dict[str, list[Upload]] = {}
    for field, value in form.multi_items():
        if field in ("kind", "options"):
            continue
        if isinstance(value, str):
            raise MalformedInputError(f"'{field}' must be a file, not a text field", field=field)
        if value.size == 0:  # said before a reader sniffs it and calls it some other format
            name = safe_name(value.filename) or "the file"
            raise MalformedInputError(f"'{field}': {name} is empty (0 bytes)", field=field)
        files.setdefault(field, []).append((value.filename, value.file))
    if not files:
        raise MalformedInputError(f"the upload has no file; GET /v1/kinds/{kind} lists its parts", field="file")
    return kind, options, files


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


WAIT_TEXT = "long poll: hold up to this many seconds for a change (a finite number, 0 to 30)"


@router.get("/{job_id}", responses=ERRORS)
async def get_job(
    job_id: str,
    request: Request,
    service: ServiceDep,
    caller: CallerDep,
    wait: Annotated[float, Query(ge=0, le=30, allow_inf_nan=False, description=WAIT_TEXT)] = 0,
) -> JobPublic:
    """A job's status, progress, result and artifact links. With ``wait`` the answer comes as
    soon as the job's status, stage or progress changes, or when ``wait`` runs out."""
    # Waiting happens on the event loop (one shared watcher), so waiting clients hold no threads.
    job = _found(await run_in_threadpool(service.get, job_id, caller.scope), job_id)
    if wait > 0 and job.status not in FINAL:
        await request.app.state.watcher.wait_for_change(job_id, (job.status, job.stage, job.progress), wait)
        job = _found(await run_in_threadpool(service.get, job_id, caller.scope), job_id)
    return public(job, request)


@router.get("/{job_id}/artifacts", responses=FILE_ERRORS)
def list_artifacts(job_id: str, request: Request, service: ServiceDep, caller: CallerDep) -> list[ArtifactPublic]:
    """The files a succeeded job has: its kind's artifacts and its HTML report, each with the
    file name its download is saved as."""
    job = _succeeded(service.get(job_id, caller.scope), job_id, "its artifacts exist")
    kind = get_kind(job.kind)
    specs = {a.name: a for a in kind.artifacts}
    base = f"{base_url(request)}/v1/jobs/{job_id}/artifacts"
    items = [
        ArtifactPublic(name=name, media_type=specs[name].media_type, description=specs[name].description,
                       url=f"{base}/{name}", filename=_filename(name, job.artifacts[name]))
        for name in job.artifacts
        if name in specs
    ]  # fmt: skip
    report = ArtifactPublic(
        name="report", media_type="text/html", description=REPORT_TEXT, url=f"{base}/report", filename=REPORT_FILE
    )
    return [*items, report]


@router.get(
    "/{job_id}/artifacts/{name}",
    responses={**FILE_ERRORS, 200: {"content": {"application/octet-stream": {}}}},
    response_class=FileResponse,
)
def get_artifact(
    job_id: str,
    name: str,
    service: ServiceDep,
    caller: CallerDep,
    format: Annotated[Literal["ply", "npz"] | None, Query(description="PLY artifacts: ply (default) or npz")] = None,
) -> FileResponse:
    """One artifact of a succeeded job (``report`` is its HTML report), saved as the name
    ``/artifacts`` lists (``cloud.ply``; ``cloud.npz`` with ``format=npz``)."""
    if name == "report":
        if format == "npz":
            raise MalformedInputError("format=npz applies to PLY artifacts; report is text/html", field="format")
        return get_job_report(job_id, service, caller)
    job = _succeeded(service.get(job_id, caller.scope), job_id, f"its {name} exists")
    spec = next((a for a in get_kind(job.kind).artifacts if a.name == name), None)
    if spec is None or name not in job.artifacts:
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"job {job_id} has no artifact {name!r}")
    if format == "npz" and Path(job.artifacts[name]).suffix != ".ply":
        raise MalformedInputError(f"format=npz applies to PLY artifacts; {name} is {spec.media_type}", field="format")
    return _download(service, job, name, spec.media_type, npz=format == "npz")


@router.get(
    "/{job_id}/cloud",
    responses={**FILE_ERRORS, 200: {"content": {"application/octet-stream": {}}, "description": "binary PLY or NPZ"}},
    response_class=FileResponse,
)
def get_job_cloud(
    job_id: str, service: ServiceDep, caller: CallerDep, format: Annotated[Literal["ply", "npz"], Query()] = "ply"
) -> FileResponse:
    """Alias of ``/artifacts/cloud``: the rectified cloud, binary PLY (default) or NPZ
    (``xyz_m``, ``t_s`` and every other field), saved as ``cloud.ply`` (``cloud.npz``)."""
    job = _succeeded(service.get(job_id, caller.scope), job_id, "the cloud exists")
    if "cloud" not in job.artifacts:
        linescan = job.kind == DEFAULT_KIND
        why = "submit one with the tracks to get it rectified" if linescan else f"{job.kind} writes none"
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"job {job_id} has no cloud ({why})")
    return _download(service, job, "cloud", "application/octet-stream", npz=format == "npz")


@router.get(
    "/{job_id}/report",
    responses={**FILE_ERRORS, 200: {"content": {"text/html": {}}, "description": "self-contained HTML"}},
    response_class=FileResponse,
)
def get_job_report(job_id: str, service: ServiceDep, caller: CallerDep) -> FileResponse:
    """The job's report: one self-contained HTML file that works offline (alias of
    ``/artifacts/report``), shown inline and saved as ``report.html``."""
    job = _succeeded(service.get(job_id, caller.scope), job_id, "its report exists")
    path = service.report_path(job)
    return FileResponse(path, media_type="text/html", filename=REPORT_FILE, content_disposition_type="inline")


@router.delete("/{job_id}", responses=ERRORS)
def cancel_job(job_id: str, request: Request, service: ServiceDep, caller: CallerDep) -> JobPublic:
    """Cancel a queued or running job: a queued one is ``cancelled`` at once; a running one
    answers ``cancel_requested: true`` while still ``running`` and stops at its next check,
    within seconds. Its files are deleted once it has stopped. Finished jobs are returned
    unchanged."""
    return public(_found(service.cancel(job_id, caller.scope), job_id), request)


def _succeeded(job: Job | None, job_id: str, what: str) -> Job:
    job = _found(job, job_id)
    if job.status != "succeeded" or job.artifacts_deleted:
        raise HTTPException(status.HTTP_409_CONFLICT, f"job {job_id} is {job.status}; {what} once it has succeeded")
    return job


def _filename(name: str, stored: str) -> str:
    """What artifact ``name`` is saved as, the listing's ``filename`` and the download's
    Content-Disposition alike: the name with the stored file's extension (``cloud.ply``)."""
    return name + Path(stored).suffix


def _download(service: JobService, job: Job, name: str, media_type: str, *, npz: bool) -> FileResponse:
    """Artifact ``name`` as stored, or a PLY one as NPZ; 410 when its file has gone."""
    stored = job.artifacts[name]
    path = service.artifacts.path(job.id, stored)
    if not path.is_file():
        gone = f"job {job.id}'s {name} ({_filename(name, stored)})"
        raise ArtifactMissingError(f"{gone} is no longer in the artifact store; submit the job again to make it")
    if npz:
        return _as_npz(path, f"{name}.npz")
    return FileResponse(path, media_type=media_type, filename=_filename(name, stored))


def _as_npz(path: Path, filename: str) -> FileResponse:
    """A PLY artifact as NPZ: ``xyz_m``, ``t_s`` and every other per-point field."""
    cloud = read_ply(path)
    tmp = tempfile.NamedTemporaryFile(suffix=".npz", delete=False)  # noqa: SIM115 (removed after sending)
    with tmp:
        arrays: dict[str, Any] = {"xyz_m": cloud.xyz_m, "t_s": cloud.t_s, **cloud.fields}
        np.savez(tmp, **arrays)
    return FileResponse(
        tmp.name, media_type="application/octet-stream", filename=filename, background=BackgroundTask(_unlink, tmp.name)
    )


def _found(job: Job | None, job_id: str) -> Job:
    if job is None:
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"job {job_id} not found")
    return job


def _unlink(path: str) -> None:
    import os

    os.unlink(path)
