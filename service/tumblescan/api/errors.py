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

from ..errors import InputError, MalformedInputError
from ..io.json_text import parse_json
from ..jobs.artifacts import UploadTooLargeError
from ..jobs.service import ArtifactMissingError, OptionsError, QueueUnavailableError

RETRY_AFTER_S = "5"
# FastAPI's answer when reading a JSON body raised something other than a JSONDecodeError
# (nesting past the parser's limit, an integer past Python's digit limit, bytes that are not
# UTF-8); the body is re-read here to say which.
UNREADABLE_BODY = "There was an error parsing the body"
log = logging.getLogger("tumblescan.api")


class WrongContentTypeError(InputError):
    """A body of another type than the endpoint takes (JSON to the upload, a form to the JSON)."""

    code = "wrong_content_type"


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


def is_json(content_type: str) -> bool:
    media = content_type.partition(";")[0].strip().lower()
    return media == "application/json" or (media.startswith("application/") and media.endswith("+json"))


async def unreadable_body(request: Request) -> JSONResponse:
    """The 422 for a JSON body the parser could not read, from the same parser (and words) as
    an uploaded part's JSON: ``body: the JSON nests too deeply to read``. (FastAPI has read the
    body already; ``request.body()`` returns it again.)"""
    try:
        parse_json(await request.body(), "body", error=MalformedInputError)
        message = "body: the JSON could not be read"
    except InputError as exc:
        return error_response(422, exc.code, str(exc), field=exc.field)
    except ValueError as exc:  # an integer past Python's digit limit (sys.int_max_str_digits)
        message = f"body: a number in the JSON is too long to read ({str(exc).partition(';')[0]})"
    return error_response(422, MalformedInputError.code, message, field="body")


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
    async def _request(request: Request, exc: RequestValidationError) -> JSONResponse:
        errs = [{k: v for k, v in e.items() if k in ("loc", "msg", "type")} for e in exc.errors()]
        ctype = request.headers.get("content-type", "")
        if ctype and not is_json(ctype) and any(tuple(e.get("loc", ())) == ("body",) for e in errs):
            # A JSON body sent as something else reaches validation as bytes ("a valid dictionary").
            message = (
                f"body: {request.method} {request.url.path} takes application/json, not {ctype.partition(';')[0]}"
                "; files go to POST /v1/jobs/upload as multipart/form-data"
            )
            return error_response(422, WrongContentTypeError.code, message, field="body")
        return error_response(422, "invalid_request", describe(errs), field=first_field(errs), errors=errs)

    @app.exception_handler(ArtifactMissingError)
    async def _missing(_: Request, exc: ArtifactMissingError) -> JSONResponse:
        return error_response(410, "artifact_missing", str(exc))

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
    async def _http(request: Request, exc: StarletteHTTPException) -> JSONResponse:
        if exc.detail == UNREADABLE_BODY and isinstance(exc.__cause__, RecursionError | ValueError):
            return await unreadable_body(request)
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
