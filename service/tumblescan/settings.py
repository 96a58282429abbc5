"""Service settings: one pydantic-settings object, environment prefix ``TUMBLESCAN_``."""

from __future__ import annotations

import os
from functools import lru_cache
from pathlib import Path
from typing import Annotated

from pydantic import Field, SecretStr, field_validator
from pydantic_settings import BaseSettings, NoDecode, SettingsConfigDict


class Settings(BaseSettings):
    """Every setting can be given as ``TUMBLESCAN_<NAME>`` (for example ``TUMBLESCAN_DATA_DIR``)."""

    model_config = SettingsConfigDict(env_prefix="TUMBLESCAN_", extra="ignore")

    data_dir: Path = Field(Path("tumblescan-data"), description="job database, queue and artifacts (embedded mode)")
    artifact_dir: Path | None = Field(
        None, description="uploads and results; default <data_dir>/artifacts; shared path for many machines"
    )
    database_url: str | None = Field(None, description="SQLAlchemy URL; default sqlite:///<data_dir>/jobs.db")
    redis_url: str | None = Field(None, description="use RedisHuey at this URL instead of the embedded SQLite queue")
    queue_name: str = Field(
        "tumblescan", pattern=r"^[A-Za-z0-9_.-]+$", description="queue name (deployments sharing a Redis)"
    )
    host: str = "127.0.0.1"
    port: int = Field(8000, ge=0, le=65535)
    workers: int = Field(
        default_factory=lambda: os.cpu_count() or 1, ge=1, le=256, description="worker processes of 'serve'"
    )
    api_keys: Annotated[list[SecretStr], NoDecode] = Field(
        default_factory=list, description="accepted Bearer keys (comma-separated in the environment)"
    )
    admin_keys: Annotated[list[SecretStr], NoDecode] = Field(
        default_factory=list, description="keys that may also list and cancel every job (comma-separated)"
    )
    allow_unauthenticated: bool = Field(False, description="serve beyond localhost without API keys (not recommended)")
    job_timeout_s: float = Field(600.0, gt=0, description="a job running longer fails with code 'timeout'")
    max_observations: int = Field(1_000_000, gt=0, description="largest tracks input accepted")
    max_cloud_points: int = Field(50_000_000, gt=0, description="largest cloud accepted")
    limits: dict[str, dict[str, int | float]] = Field(
        default_factory=dict,
        description='per-kind limits over their defaults, as JSON: {"linescan-motion": {"max_cloud_points": 1e7}}',
    )
    public_url: str | None = Field(None, description="base URL used in links; default from the request")
    heartbeat_s: float = Field(2.0, gt=0, description="how often a running job proves its worker alive")
    lease_s: float = Field(20.0, gt=0, description="a running job silent for this long has lost its worker")
    max_attempts: int = Field(2, ge=1, le=10, description="runs of a job whose worker was lost, in all")
    reaper_interval_s: float = Field(5.0, gt=0)
    max_upload_bytes: int = Field(1 << 30, gt=0)
    poll_initial_delay_s: float = Field(0.01, gt=0)
    poll_max_delay_s: float = Field(0.1, gt=0)

    @field_validator("api_keys", "admin_keys", mode="before")
    @classmethod
    def _split_keys(cls, v: object) -> object:
        if isinstance(v, str):
            return [k.strip() for k in v.split(",") if k.strip()]
        return v

    def open_access_problem(self) -> str | None:
        """Why serving with these settings would expose an open service, or None."""
        if self.api_keys or self.admin_keys or self.allow_unauthenticated:
            return None
        if self.host in ("127.0.0.1", "localhost", "::1"):
            return None
        return (
            f"refusing to serve on {self.host} without API keys: set TUMBLESCAN_API_KEYS, or "
            "TUMBLESCAN_ALLOW_UNAUTHENTICATED=true to accept that anyone who can reach it may use it"
        )

    @property
    def artifacts(self) -> Path:
        return self.artifact_dir or self.data_dir / "artifacts"

    @property
    def db_url(self) -> str:
        return self.database_url or f"sqlite:///{(self.data_dir / 'jobs.db').resolve()}"


@lru_cache
def get_settings() -> Settings:
    return Settings()
