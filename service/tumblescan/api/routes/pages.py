"""HTML pages: the job list at ``/`` and each job's report at ``/jobs/{id}``."""

from __future__ import annotations

import html
from typing import Annotated

from fastapi import APIRouter, HTTPException, Query, Request
from fastapi.responses import FileResponse, HTMLResponse, Response

from ...jobs.service import ArtifactMissingError
from ...jobs.tables import FINAL, Job
from ..deps import KEY_COOKIE, ServiceDep, get_caller, presented_key

router = APIRouter(tags=["pages"], include_in_schema=False)
PAGE_SIZE = 100

STYLE = """body{font-family:system-ui,sans-serif;margin:1.5em auto;max-width:1000px;color:#222}
table{border-collapse:collapse}th,td{border:1px solid #ccc;padding:.25em .6em;text-align:left}
th{background:#f3f3f3}.succeeded{color:#070}.failed{color:#b00}.cancelled{color:#777}.running{color:#05a}"""


def page(title: str, body: str, *, status_code: int = 200, refresh_s: int | None = None) -> HTMLResponse:
    meta = f'<meta http-equiv="refresh" content="{refresh_s}">' if refresh_s else ""
    head = f"<meta charset='utf-8'>{meta}<title>{html.escape(title)}</title><style>{STYLE}</style>"
    doc = f"<!DOCTYPE html><html lang='en'><head>{head}</head><body>{body}</body></html>"
    return HTMLResponse(doc, status_code=status_code)


def _owner(request: Request) -> str | HTMLResponse | None:
    """The caller's job scope, or a 401 page saying whether the key is missing or not valid."""
    try:
        return get_caller(request).scope
    except HTTPException:
        how = "Open this page with <code>?api_key=&lt;your key&gt;</code> once; the key is then kept in a cookie."
        if presented_key(request):
            body = f"<h1>Invalid API key</h1><p>The key given is not valid here. {how}</p>"
            return page("Invalid API key", body, status_code=401)
        return page("API key required", f"<h1>API key required</h1><p>{how}</p>", status_code=401)


def _remember_key(request: Request, response: Response) -> Response:
    key = request.query_params.get("api_key")
    if key:
        response.set_cookie(KEY_COOKIE, key, httponly=True, samesite="strict")
    return response


@router.get("/", response_class=HTMLResponse)
def job_list(
    request: Request, service: ServiceDep, cursor: Annotated[str | None, Query(max_length=200)] = None
) -> Response:
    owner = _owner(request)
    if isinstance(owner, HTMLResponse):
        return owner
    try:
        jobs, nxt = service.list(status=None, owner=owner, limit=PAGE_SIZE, cursor=cursor)
    except ValueError:
        return page("Bad cursor", "<h1>Bad cursor</h1><p><a href='/'>Back to the newest jobs</a></p>", status_code=422)
    rows = "".join(_row(j) for j in jobs) or "<tr><td colspan='5'>no jobs yet</td></tr>"
    more = f"<p><a href='/?cursor={html.escape(nxt)}'>older jobs</a></p>" if nxt else ""
    active = any(j.status not in FINAL for j in jobs)
    body = f"""<h1>Tumblescan jobs</h1>
<table id="jobs"><tr><th>job</th><th>status</th><th>kind</th><th>created (UTC)</th><th>duration</th></tr>
{rows}</table>{more}
<p>{"Refreshing every 2 s while jobs run." if active else ""}</p>"""
    return _remember_key(request, page("Tumblescan jobs", body, refresh_s=2 if active else None))


def _row(j: Job) -> str:
    from datetime import UTC, datetime

    created = datetime.fromtimestamp(j.created_at, UTC).strftime("%Y-%m-%d %H:%M:%S")
    duration = f"{j.finished_at - j.started_at:.2f} s" if j.finished_at and j.started_at else ""
    status = f"{j.status} ({100 * j.progress:.0f} %, {html.escape(j.stage)})" if j.status == "running" else j.status
    return (
        f"<tr data-job='{j.id}'><td><a href='/jobs/{j.id}'>{j.id}</a></td><td class='{j.status}'>{status}</td>"
        f"<td>{html.escape(j.kind)}</td><td>{created}</td><td>{duration}</td></tr>"
    )


@router.get("/jobs/{job_id}", response_class=HTMLResponse)
def job_page(job_id: str, request: Request, service: ServiceDep) -> Response:
    owner = _owner(request)
    if isinstance(owner, HTMLResponse):
        return owner
    job = service.get(job_id, owner)
    if job is None:
        body = f"<h1>Job not found</h1><p>No job <code>{html.escape(job_id)}</code> here. <a href='/'>All jobs</a></p>"
        return page("Job not found", body, status_code=404)
    if job.status == "succeeded" and not job.artifacts_deleted:
        try:
            return _remember_key(request, FileResponse(service.report_path(job), media_type="text/html"))
        except ArtifactMissingError as exc:
            body = f"<h1>Report unavailable</h1><p>{html.escape(str(exc))}.</p><p><a href='/'>All jobs</a></p>"
            return page("Report unavailable", body, status_code=410)
    error = (
        f"<p class='failed'>{html.escape(job.error_code or '')}: {html.escape(job.error_message or '')}</p>"
        if job.error_code
        else ""
    )
    body = f"""<h1>Job {job.id}</h1><p>Status: <span class='{job.status}'>{job.status}</span>,
stage {html.escape(job.stage)}, {100 * job.progress:.0f} %</p>{error}<p><a href='/'>All jobs</a></p>"""
    return _remember_key(request, page(f"Job {job.id}", body, refresh_s=None if job.status in FINAL else 1))
