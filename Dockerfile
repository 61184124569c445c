# simbridge: a rosbridge v2 server with a built-in robot simulation, as a container.
#
#   docker build -t simbridge .
#   docker run --rm -p 9090:9090 simbridge           # ws://HOST:9090/ (page on http://HOST:9090/)
#
# Multi-arch (a Raspberry Pi 4B/5 with a 64-bit OS, and an x86-64 class server):
#   docker buildx build --platform linux/amd64,linux/arm64 -t REGISTRY/simbridge:TAG --push .
# or, without buildx (Debian's docker.io), the arm64 image alone on an x86-64 machine whose kernel
# runs arm64 programs (qemu-user-static registered with binfmt_misc; docs/deploy.md):
#   docker build --platform linux/arm64 -t simbridge:arm64 .
# The tests build and run it that way (tests/deploy/test_arm64.py, `make test-arm64`).
# 32-bit ARM (armv7, 32-bit Raspberry Pi OS) is NOT supported: numpy and PyYAML publish no
# armv7 wheels, so pip would compile them (hours under emulation). Use a 64-bit OS on the Pi.
#
# Every dependency installs from a binary wheel (no compiler in the image; the one exception, the
# DDS binding on arm64, is compiled in a stage of its own, below). Any Debian bookworm based image
# with Python >= 3.11 and its venv module works as the base (the tests build from a local one):
#   docker build --build-arg BASE_IMAGE=my-debian-python .
ARG BASE_IMAGE=python:3.12-slim-bookworm

# The Cyclone DDS binding for the dds extra where PyPI has no wheel of it: aarch64 (the Pi). Built
# from its sdist against Debian's Cyclone DDS C library (cyclonedds-dev 0.10.2, so the binding
# 0.10.2: pyproject.toml's pin for aarch64), here, so that the compiler stays out of the image;
# the image gets the wheel and Debian's runtime library (libddsc0debian). About 3 minutes under
# qemu emulation, cached in this stage's layer. Anywhere else, or without dds, it makes nothing.
FROM ${BASE_IMAGE} AS dds-binding
ARG SIMBRIDGE_EXTRAS=""
ARG CYCLONEDDS_AARCH64=cyclonedds==0.10.2
RUN mkdir /wheels \
    && case ",${SIMBRIDGE_EXTRAS},$(uname -m)" in *,dds,*aarch64) ;; *) exit 0 ;; esac \
    && apt-get update \
    && apt-get install -y --no-install-recommends gcc libc6-dev cyclonedds-dev \
    && { python3 -c "import os, sysconfig; raise SystemExit(not os.path.exists(os.path.join(sysconfig.get_paths()['include'], 'Python.h')))" \
         || apt-get install -y --no-install-recommends python3-dev; } \
    && home=/tmp/cyclonedds && mkdir -p "$home/lib" "$home/bin" \
    && ln -s /usr/include "$home/include" \
    && ln -s "/usr/lib/$(gcc -dumpmachine)/libddsc.so" "$home/lib/" \
    && python3 -m venv /tmp/venv \
    && CYCLONEDDS_HOME="$home" /tmp/venv/bin/pip wheel --no-cache-dir --no-deps \
        --no-binary cyclonedds -w /wheels "${CYCLONEDDS_AARCH64}"

FROM ${BASE_IMAGE}

ENV PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1 \
    PIP_NO_CACHE_DIR=1 \
    PATH=/opt/simbridge/bin:$PATH

# A virtual environment keeps the install off the base image's Python (Debian's is "externally
# managed", PEP 668) and works the same on python:*-slim.
RUN python3 -m venv /opt/simbridge

# Optional extras, comma-separated: SIMBRIDGE_EXTRAS=zenoh adds ROS 2 over Zenoh (--zenoh, zenohd;
# docker-compose.classroom.yml builds it so), SIMBRIDGE_EXTRAS=foxglove the Foxglove WebSocket
# protocol (--foxglove-port), SIMBRIDGE_EXTRAS=dds ROS 2 over DDS (--dds; on arm64 with the
# binding built above and Debian's Cyclone DDS 0.10.2 library, docs/dds.md).
ARG SIMBRIDGE_EXTRAS=""

# The DDS binding built above (none on amd64 or without dds) and the C library it links.
COPY --from=dds-binding /wheels /tmp/wheels
RUN if [ -n "$(ls /tmp/wheels)" ]; then \
        apt-get update \
        && apt-get install -y --no-install-recommends libddsc0debian \
        && apt-get clean && rm -rf /var/lib/apt/lists/*; \
    fi

# Dependencies first, from pyproject.toml alone: this layer stays cached while the code changes.
COPY pyproject.toml /tmp/simbridge/
RUN python3 -c "import os, tomllib; p = tomllib.load(open('/tmp/simbridge/pyproject.toml', 'rb'))['project']; extras = [e for e in os.environ.get('SIMBRIDGE_EXTRAS', '').split(',') if e]; print('\n'.join(p['dependencies'] + [d for e in extras for d in p['optional-dependencies'][e]]))" \
        > /tmp/requirements.txt \
    && pip install --no-cache-dir --only-binary=:all: --find-links /tmp/wheels \
        -r /tmp/requirements.txt \
    && rm -rf /tmp/requirements.txt /tmp/wheels

# The package itself: the code, its page and its default configuration (bundled in the wheel).
COPY README.md /tmp/simbridge/
COPY simbridge /tmp/simbridge/simbridge
COPY static /tmp/simbridge/static
COPY config /tmp/simbridge/config
RUN pip install --no-cache-dir --only-binary=:all: --no-deps /tmp/simbridge \
    && rm -rf /tmp/simbridge \
    && simbridge check-config

# Run unprivileged. The process needs no files of its own: settings come from the image, from
# SIMBRIDGE_* variables, or from a read-only mount (docker-compose.yml mounts config/).
RUN useradd --uid 10001 --user-group --no-create-home --home-dir /nonexistent \
        --shell /usr/sbin/nologin simbridge
USER simbridge:simbridge
WORKDIR /tmp

# 9090: rosbridge WebSocket (it also answers /healthz and serves the page); 8080: page + /healthz.
EXPOSE 9090 8080

# No curl in slim images: the server's own probe (GET /healthz on $SIMBRIDGE_PORT, exit 0 or 1).
HEALTHCHECK --interval=10s --timeout=5s --start-period=30s --retries=3 \
    CMD ["simbridge", "healthcheck"]

# Exec form: simbridge is PID 1 and receives docker stop's SIGTERM (clean shutdown, no 10 s wait).
CMD ["simbridge", "--host", "0.0.0.0"]
