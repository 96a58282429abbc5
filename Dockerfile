# Tumblescan service: API plus embedded workers by default (see compose.yaml for scale-out).
#   docker build -t tumblescan:local .        (or scripts/build-image: podman or docker, proxies, no registry)
#   docker run -p 8000:8000 -e TUMBLESCAN_API_KEYS=<key> -v tumblescan:/data tumblescan:local
# It listens on 0.0.0.0 inside the container, so it refuses to start without API keys.
# Python packages are pinned by constraints.txt (scripts/lock-deps regenerates it); the build context
# is limited by .dockerignore; scripts/container-smoke builds this image and runs a job of every kind.
# docs/deploy.md describes the image, its volumes, settings and health checks.

# --- build: a virtualenv with the pinned dependencies, then the two packages (no pip cache, no sources) ---
FROM python:3.11-slim AS build
ENV PIP_NO_CACHE_DIR=1 PIP_DISABLE_PIP_VERSION_CHECK=1 PYTHONDONTWRITEBYTECODE=1
RUN python -m venv /opt/venv
ENV PATH=/opt/venv/bin:$PATH
WORKDIR /src
# Dependencies first, from the two pyproject files only, so that a source change reuses this layer.
COPY constraints.txt pyproject.toml ./
COPY client/pyproject.toml client/
# A host behind a TLS-inspecting proxy hands its CA bundle in as the build secret pip_cert
# (scripts/build-image does); without it pip uses its own certificates. setuptools (pinned too) is the
# build backend of the two packages below, and dash (Open3D's) needs it at run time.
RUN --mount=type=secret,id=pip_cert \
    if [ -s /run/secrets/pip_cert ]; then export PIP_CERT=/run/secrets/pip_cert; fi \
 && python -c "import tomllib; \
print('\n'.join(d for f in ('pyproject.toml', 'client/pyproject.toml') \
for d in tomllib.load(open(f, 'rb'))['project']['dependencies']))" > requirements.txt \
 && pip install -c constraints.txt -r requirements.txt setuptools
COPY README.md ./
COPY service service
COPY client client
RUN pip install --no-deps --no-build-isolation ./client . \
 && pip check \
 && pip uninstall -y -q pip

# --- gl: the vendor-neutral EGL/GL loaders (libglvnd) that Open3D's library links against. Debian's
# libegl1/libgl1 packages also pull in Mesa's drivers and LLVM (about 210 MB) that nothing here calls:
# Open3D's raycasting runs on the CPU, it only needs these four libraries to load. ---
FROM python:3.11-slim AS gl
RUN apt-get update \
 && apt-get install -y --no-install-recommends libegl1 libgl1 \
 && mkdir /glvnd \
 && dpkg -L libegl1 libgl1 libglx0 libglvnd0 | grep -E '/lib(EGL[.]so[.]1|GL[.]so[.]1|GLX[.]so[.]0|GLdispatch[.]so[.]0)$' \
  | xargs cp -L -t /glvnd/ \
 && test "$(ls /glvnd | wc -l)" = 4

# --- run: slim base, the run-time system libraries, the virtualenv, a non-root user ---
FROM python:3.11-slim
# libusb-1.0-0: Open3D does not import without it; libx11-6: the GLX loader's one dependency;
# libgomp1: OpenMP of Open3D, OpenCV and GTSAM. The Python wheels bundle every other library they load
# (scripts/container-smoke checks with ldd that nothing under /opt/venv lacks a library).
COPY --from=gl /glvnd/ /usr/local/lib/
RUN apt-get update \
 && apt-get install -y --no-install-recommends libusb-1.0-0 libx11-6 libgomp1 \
 && rm -rf /var/lib/apt/lists/* \
 && ldconfig \
 && useradd --create-home --uid 10001 --user-group tumblescan \
 && mkdir -p /data /artifacts && chown tumblescan:tumblescan /data /artifacts
COPY --from=build /opt/venv /opt/venv

ENV PATH=/opt/venv/bin:$PATH \
    PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    TUMBLESCAN_DATA_DIR=/data \
    TUMBLESCAN_HOST=0.0.0.0 \
    TUMBLESCAN_PORT=8000

USER tumblescan
WORKDIR /home/tumblescan
VOLUME ["/data"]
EXPOSE 8000
# Liveness only (the process answers); /readyz says whether store, queue and workers are there.
# Workers (`tumblescan worker`) serve no HTTP: compose.yaml turns this check off for them.
HEALTHCHECK --interval=15s --timeout=5s --start-period=30s --retries=3 \
  CMD ["python", "-c", "import os, urllib.request; urllib.request.urlopen('http://127.0.0.1:%s/healthz' % os.environ.get('TUMBLESCAN_PORT', '8000'), timeout=4)"]

ENTRYPOINT ["tumblescan"]
CMD ["serve"]
