#!/usr/bin/env bash
# Headless browser for the user-study end-to-end test: Debian's `chromium` (apt) and
# `playwright-core` (npm, no browser download of its own) in the git-ignored .cache/browser/.
# Idempotent and quick when both are present.
set -euo pipefail
cd "$(dirname "$0")/.."
export DEBIAN_FRONTEND=noninteractive
need_apt=()
command -v chromium >/dev/null 2>&1 || need_apt+=(chromium)
command -v node >/dev/null 2>&1 || need_apt+=(nodejs)
command -v npm >/dev/null 2>&1 || need_apt+=(npm)
if [ ${#need_apt[@]} -gt 0 ]; then
  apt-get update -qq
  apt-get install -y -qq --no-install-recommends "${need_apt[@]}" fonts-dejavu-core >/dev/null
fi
dest=.cache/browser
version=1.65.1
if [ ! -f "$dest/node_modules/playwright-core/package.json" ] ||
   ! grep -q "\"version\": \"$version\"" "$dest/node_modules/playwright-core/package.json"; then
  mkdir -p "$dest"
  [ -f "$dest/package.json" ] || echo '{"name":"fewview-browser-tests","private":true}' > "$dest/package.json"
  PLAYWRIGHT_SKIP_BROWSER_DOWNLOAD=1 npm install --prefix "$dest" --no-audit --no-fund --silent "playwright-core@$version"
fi
