# The service image: Python 3.11 slim, only the `serve` extra (onnxruntime; no torch, no
# training or test tools), the shipped models/ baked in, a non-root user.
#
#   docker build -t motion-style .
#   make image      # the same, on a base built from Debian's packages where no registry answers
#   docker run -p 8000:8000 -e MOTION_WORKERS=2 -e MOTION_INTRA_OP_THREADS=1 motion-style
#   docker run -p 8000:8000 -v "$PWD/keys:/keys:ro" -e MOTION_API_KEYS_FILE=/keys/api-keys \
#     motion-style      # API keys (docs/api-keys.md): mount the folder, not the file
#   docker build --build-arg EXTRAS="serve fbx" -t motion-style:fbx .   # FBX (make image-fbx)
#
# Settings are MOTION_* variables (README); keep workers x intra-op threads <= the CPUs you
# give the container. With several workers, `python -m service` points
# PROMETHEUS_MULTIPROC_DIR at a fresh folder under /tmp so /metrics counts every worker.

ARG PYTHON_IMAGE=python:3.11-slim-bookworm
# pyproject.toml's extras installed: "serve fbx" adds Blender as a Python module (FBX in and
# out, about 0.9 GB more; docs/deploy.md), the image tagged motion-style:fbx
ARG EXTRAS=serve

FROM ${PYTHON_IMAGE} AS build
ARG EXTRAS
ENV PIP_NO_CACHE_DIR=1 PIP_DISABLE_PIP_VERSION_CHECK=1
RUN python -m venv /opt/venv
COPY pyproject.toml deploy/serve_requirements.py /tmp/build/
RUN python /tmp/build/serve_requirements.py /tmp/build/pyproject.toml $EXTRAS > /tmp/build/requirements.txt \
 && /opt/venv/bin/pip install --require-virtualenv -r /tmp/build/requirements.txt \
 && /opt/venv/bin/python -c "import fastapi, onnxruntime, soundfile, soxr, uvicorn" \
 && if /opt/venv/bin/python -c "import torch" 2>/dev/null; then echo "torch in the image" >&2; exit 1; fi
# What serving never runs: pip and setuptools, and the packages' own test suites (numpy,
# scipy, numba: 66 MB). See docs/deploy.md for the image's size.
RUN /opt/venv/bin/python -m pip uninstall -y -q pip setuptools \
 && find /opt/venv/lib -type d -name tests -prune -exec rm -rf {} + \
 && /opt/venv/bin/python -c "import fastapi, numba, onnxruntime, scipy.ndimage, scipy.signal, soundfile"

FROM ${PYTHON_IMAGE} AS runtime
ARG EXTRAS
# bpy links X11 and OpenGL client libraries, but its workers never open a display or a GL
# context: libGL and libGLX are unpacked without the Mesa drivers their package pulls in
# (LLVM and all, 200 MB). Versions are the base's Debian release's (DL3008): the base is
# made per release, and an exact pin would break at its next point release.
WORKDIR /tmp
# hadolint ignore=DL3008
RUN case " $EXTRAS " in *" fbx "*) \
      apt-get update -qq \
      && apt-get install -y -qq --no-install-recommends libx11-6 libxrender1 libxxf86vm1 \
           libxfixes3 libxi6 libxkbcommon0 libsm6 libgomp1 libglvnd0 >/dev/null \
      && apt-get download -qq libgl1 libglx0 \
      && for deb in ./*.deb; do dpkg-deb -x "$deb" /; done && rm ./*.deb \
      && rm -rf /var/lib/apt/lists/* /var/cache/apt/*.bin /var/log/apt /var/log/dpkg.log ;; \
    esac
# The motion core's loops are compiled when the service starts (a few seconds) and kept in
# NUMBA_CACHE_DIR, under /tmp: writable under a read-only root (deploy/k8s mounts one there).
ENV PATH=/opt/venv/bin:$PATH \
    PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    MOTION_WORKERS=1 \
    MOTION_LOG_FORMAT=json \
    MOTION_MODELS_DIR=/app/models \
    MOTION_STYLES_DIR=/var/lib/motion-style/styles \
    NUMBA_CACHE_DIR=/tmp/numba-cache
# Registered styles (POST /v1/styles) live in MOTION_STYLES_DIR: mount a volume there that
# every replica shares (docker-compose.yml, deploy/k8s/styles-pvc.yaml), or they are lost
# with the container. The folder is made here so a fresh named volume copies its owner.
RUN groupadd --system --gid 10001 motion \
 && useradd --system --uid 10001 --gid motion --no-create-home --home-dir /nonexistent \
      --shell /usr/sbin/nologin motion \
 && mkdir -p /var/lib/motion-style/styles \
 && chown -R 10001:10001 /var/lib/motion-style
COPY --from=build /opt/venv /opt/venv
WORKDIR /app
COPY motion/ motion/
COPY service/ service/
COPY models/ models/
# Fail the build, not the first request, if the app cannot be built from what was copied.
RUN python -c "import service.main; service.main.create_app()" \
 && case " $EXTRAS " in *" fbx "*) python -c "import bpy, io_scene_fbx.export_fbx_bin" ;; esac
USER 10001:10001
EXPOSE 8000
HEALTHCHECK --interval=15s --timeout=5s --start-period=60s --retries=3 \
  CMD ["python", "-c", "import sys, urllib.request; sys.exit(0 if urllib.request.urlopen('http://127.0.0.1:8000/healthz', timeout=4).status == 200 else 1)"]
CMD ["python", "-m", "service", "--host", "0.0.0.0", "--port", "8000"]
