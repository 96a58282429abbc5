"""Liveness, readiness and Prometheus metrics."""

from __future__ import annotations

from fastapi import APIRouter, Response
from fastapi.responses import JSONResponse, PlainTextResponse

from ..deps import ServiceDep
from ..errors import RETRY_AFTER_S

router = APIRouter(tags=["health"])
DURATION_BUCKETS_S = (0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0, 30.0, 60.0, 300.0, 600.0)
# A worker process that has not beaten for this long is not counted as present.
WORKER_FRESH_S = 15.0


@router.get("/healthz")
async def healthz() -> dict[str, str]:
    """The process is alive (answered on the event loop: never queued behind busy threads)."""
    return {"status": "ok"}


@router.get("/readyz", responses={503: {"description": "not ready (with Retry-After)"}})
def readyz(service: ServiceDep) -> JSONResponse:
    """Store and queue reachable and at least one worker process alive; a 503 carries
    ``Retry-After``, as every 503 does."""
    checks: dict[str, str] = {}
    try:
        service.store.ping()
        checks["store"] = "ok"
    except Exception as exc:
        checks["store"] = f"unreachable: {type(exc).__name__}"
    try:
        service.queue_depth()
        checks["queue"] = "ok"
    except Exception as exc:
        checks["queue"] = f"unreachable: {type(exc).__name__}"
    try:
        n = service.store.live_worker_processes(WORKER_FRESH_S) if checks["store"] == "ok" else 0
        checks["workers"] = f"{n} process(es)" if n else "none"
    except Exception as exc:
        checks["workers"] = f"unknown: {type(exc).__name__}"
    ready = (
        checks["store"] == "ok"
        and checks["queue"] == "ok"
        and checks["workers"] not in ("none",)
        and not checks["workers"].startswith("unknown")
    )
    body = {"status": "ready" if ready else "not ready", "checks": checks}
    if ready:
        return JSONResponse(body)
    return JSONResponse(body, status_code=503, headers={"Retry-After": RETRY_AFTER_S})


@router.get("/metrics", response_class=PlainTextResponse)
def metrics(service: ServiceDep) -> Response:
    """Prometheus text format: jobs by status, job duration histogram, queue depth."""
    lines = ["# HELP tumblescan_jobs Jobs by status.", "# TYPE tumblescan_jobs gauge"]
    for status, n in service.store.counts().items():
        lines.append(f'tumblescan_jobs{{status="{status}"}} {n}')
    durations = service.store.durations()
    lines += [
        "# HELP tumblescan_job_duration_seconds Run time of finished jobs.",
        "# TYPE tumblescan_job_duration_seconds histogram",
    ]
    for b in DURATION_BUCKETS_S:
        lines.append(f'tumblescan_job_duration_seconds_bucket{{le="{b}"}} {sum(d <= b for d in durations)}')
    lines.append(f'tumblescan_job_duration_seconds_bucket{{le="+Inf"}} {len(durations)}')
    lines.append(f"tumblescan_job_duration_seconds_sum {sum(durations):.6f}")
    lines.append(f"tumblescan_job_duration_seconds_count {len(durations)}")
    lines += ["# HELP tumblescan_queue_depth Tasks waiting in the queue.", "# TYPE tumblescan_queue_depth gauge"]
    lines.append(f"tumblescan_queue_depth {service.queue_depth()}")
    return PlainTextResponse("\n".join(lines) + "\n", media_type="text/plain; version=0.0.4")
