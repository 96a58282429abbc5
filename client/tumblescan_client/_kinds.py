"""``client.kinds`` and ``async_client.kinds``: the job kinds the service runs, sync and async twins."""

from __future__ import annotations

from typing import TYPE_CHECKING

from .models import Kind, KindSummary

if TYPE_CHECKING:
    from ._client import AsyncClient, Client


class Kinds:
    """``client.kinds``: the job kinds the service runs, with their input forms and schemas."""

    def __init__(self, client: Client) -> None:
        self._c = client

    def list(self) -> list[KindSummary]:
        return [KindSummary.model_validate(k) for k in self._c._request("GET", "/v1/kinds").json()]

    def get(self, name: str) -> Kind:
        return Kind.model_validate(self._c._request("GET", f"/v1/kinds/{name}").json())


class AsyncKinds:
    """``async_client.kinds``: the same as :class:`Kinds`, awaitable."""

    def __init__(self, client: AsyncClient) -> None:
        self._c = client

    async def list(self) -> list[KindSummary]:
        return [KindSummary.model_validate(k) for k in (await self._c._request("GET", "/v1/kinds")).json()]

    async def get(self, name: str) -> Kind:
        return Kind.model_validate((await self._c._request("GET", f"/v1/kinds/{name}")).json())
