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
