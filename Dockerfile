# Tumblescan service: API plus embedded workers by default (see compose.yaml for scale-out).
#   docker run -p 8000:8000 -e TUMBLESCAN_API_KEYS=<key> -v tumblescan:/data tumblescan
# It listens on 0.0.0.0 inside the container, so it refuses to start without API keys.
FROM python:3.11-slim

# libusb-1.0-0: Open3D does not import without it. curl: the health check.
RUN apt-get update \
 && apt-get install -y --no-install-recommends libusb-1.0-0 curl \
 && rm -rf /var/lib/apt/lists/*

ENV PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    PIP_NO_CACHE_DIR=1 \
    TUMBLESCAN_DATA_DIR=/data \
    TUMBLESCAN_HOST=0.0.0.0 \
    TUMBLESCAN_PORT=8000

WORKDIR /app
COPY pyproject.toml README.md ./
COPY service ./service
COPY client ./client
RUN pip install ./client . && useradd --create-home --uid 10001 tumblescan \
 && mkdir -p /data /artifacts && chown tumblescan:tumblescan /data /artifacts

USER tumblescan
VOLUME ["/data"]
EXPOSE 8000
HEALTHCHECK --interval=15s --timeout=3s --start-period=20s --retries=3 \
  CMD curl -fsS "http://127.0.0.1:${TUMBLESCAN_PORT}/healthz" || exit 1

ENTRYPOINT ["tumblescan"]
CMD ["serve"]
