"""One error body for every failure: ``{"detail": {"code", "message", "field"?, "errors"?}}``."""

from __future__ import annotations

import logging
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from sqlalchemy.exc import OperationalError
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from ..errors import InputError
from ..jobs.artifacts import UploadTooLargeError
from ..jobs.service import OptionsError, QueueUnavailableError

RETRY_AFTER_S = "5"
log = logging.getLogger("tumblescan.api")


def error_response(status: int, code: str, message: str, **extra: Any) -> JSONResponse:
    headers = {"Retry-After": RETRY_AFTER_S} if status == 503 else None
    return JSONResponse({"detail": {"code": code, "message": message, **extra}}, status_code=status, headers=headers)


def first_field(errors: list[dict[str, Any]], prefix: str = "") -> str | None:
    """The dotted location of the first error (``options.seed``), the ``field`` of the body."""
    for e in errors:
        return ".".join(str(p) for p in (prefix, *e.get("loc", ())) if p != "") or None
    return None


def describe(errors: list[dict[str, Any]], prefix: str = "") -> str:
    parts = []
    for e in errors:
        loc = ".".join(str(p) for p in (prefix, *e.get("loc", ())) if p != "")
        unknown = "unknown option" if prefix == "options" else "unknown field"
        msg = unknown if e.get("type") == "extra_forbidden" else e.get("msg", "invalid")
        parts.append(f"{loc}: {msg}")
    return "; ".join(parts)


def install(app: FastAPI) -> None:
    @app.exception_handler(InputError)
    async def _input(_: Request, exc: InputError) -> JSONResponse:
        return error_response(exc.http_status, exc.code, str(exc), field=exc.field)

    @app.exception_handler(OptionsError)
    async def _options(_: Request, exc: OptionsError) -> JSONResponse:
        return error_response(
            422,
            "invalid_options",
            describe(exc.errors, "options"),
            field=first_field(exc.errors, "options"),
            errors=exc.errors,
        )

    @app.exception_handler(RequestValidationError)
    async def _request(_: Request, exc: RequestValidationError) -> JSONResponse:
        errs = [{k: v for k, v in e.items() if k in ("loc", "msg", "type")} for e in exc.errors()]
        return error_response(422, "invalid_request", describe(errs), field=first_field(errs), errors=errs)

    @app.exception_handler(UploadTooLargeError)
    async def _too_large(_: Request, exc: UploadTooLargeError) -> JSONResponse:
        return error_response(413, "upload_too_large", str(exc))

    @app.exception_handler(QueueUnavailableError)
    async def _queue(_: Request, exc: QueueUnavailableError) -> JSONResponse:
        return error_response(503, "queue_unavailable", f"the job queue is unavailable, retry later ({exc})")

    @app.exception_handler(OSError)
    async def _storage(_: Request, exc: OSError) -> JSONResponse:
        # The artifact directory is unwritable or full; nothing of the submission was kept.
        return error_response(507, "storage_unavailable", f"the service cannot store files: {exc.strerror or exc}")

    @app.exception_handler(OperationalError)
    async def _db(_: Request, exc: OperationalError) -> JSONResponse:
        return error_response(503, "store_unavailable", "the job store is unavailable, retry later")

    @app.exception_handler(StarletteHTTPException)
    async def _http(_: Request, exc: StarletteHTTPException) -> JSONResponse:
        codes = {400: "bad_request", 401: "unauthorized", 404: "not_found", 405: "method_not_allowed", 409: "conflict"}
        code = codes.get(exc.status_code, "http_error")
        resp = error_response(exc.status_code, code, str(exc.detail))
        for k, v in (exc.headers or {}).items():
            resp.headers[k] = v
        return resp


class InternalErrors:
    """An unexpected exception is logged with its traceback and answered as the error body
    every other failure has (500 ``internal_error``), never as Starlette's plain-text page.
    Nothing is re-raised, so the server keeps the client's keep-alive connection usable
    (re-raising made uvicorn close it under the client's next request)."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        started = False

        async def tracking_send(message: Message) -> None:
            nonlocal started
            started = started or message["type"] == "http.response.start"
            await send(message)

        try:
            await self.app(scope, receive, tracking_send)
        except Exception:
            log.exception("%s %s failed", scope.get("method"), scope.get("path"))
            if started:  # the answer is half sent: nothing better than cutting it off
                raise
            response = error_response(500, "internal_error", "the service failed on this request; it is logged")
            await response(scope, receive, send)
