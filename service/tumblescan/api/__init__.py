"""HTTP API (FastAPI) over the job service."""
