#!/usr/bin/env bash
# Headless-Chromium test of the viewer page (docs/VIEWER.md), and of the exported
# follower.glb: Khronos glTF validator + a three.js glTF viewer. Called by .ci/run.
#
#   tests/browser/run.sh                       # install what is missing, build the fixture page, test it
#   VIEWER_SHOT=docs/viewer.png tests/browser/run.sh   # also write the README screenshot
#   CHROMIUM=/path/to/chromium tests/browser/run.sh    # another Chromium binary
#
# Installs Debian's chromium (apt) when $CHROMIUM (default /usr/bin/chromium) is
# absent, and playwright-core, three and gltf-validator from the committed
# package-lock.json (npm ci; no browser download). Exits non-zero on any failure.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../.." && pwd)"
start=$(date +%s)
say() { echo "[browser $(( $(date +%s) - start ))s] $*"; }

export CHROMIUM="${CHROMIUM:-/usr/bin/chromium}"
sudo_() { if [ "$(id -u)" -eq 0 ]; then "$@"; else sudo "$@"; fi; }
apt_install() {
  say "apt-get install -y $*"
  sudo_ apt-get update -qq
  DEBIAN_FRONTEND=noninteractive sudo_ apt-get install -y -qq "$@" >/dev/null
}
if [ ! -x "$CHROMIUM" ]; then
  [ "$CHROMIUM" = /usr/bin/chromium ] || { echo "CHROMIUM=$CHROMIUM is not executable" >&2; exit 1; }
  apt_install chromium
fi
command -v node >/dev/null && command -v npm >/dev/null || apt_install nodejs npm
say "$("$CHROMIUM" --version 2>/dev/null | head -n1), node $(node --version)"

# playwright-core only (drives an existing Chromium; never downloads a browser).
export PLAYWRIGHT_SKIP_BROWSER_DOWNLOAD=1
if ! cmp -s "$here/package-lock.json" "$here/node_modules/.package-lock.json.ci" 2>/dev/null \
   || [ ! -d "$here/node_modules/playwright-core" ]; then
  say "npm ci"
  (cd "$here" && npm ci --no-audit --no-fund --loglevel=error)
  cp "$here/package-lock.json" "$here/node_modules/.package-lock.json.ci"
fi

tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
frames=300
# The workspace in the test profile (into target/debug), as `cargo test
# --workspace` builds it: after that (.ci/run) nothing is rebuilt.
say "building duolando and the fixture page"
(cd "$root" && cargo build -q --profile test --workspace --bins --examples)
bin="${CARGO_TARGET_DIR:-$root/target}/debug"
(cd "$root" && "$bin/examples/viewer_fixture" "$tmp/page" --frames "$frames")

say "testing $tmp/page/index.html in headless Chromium"
shot=()
if [ -n "${VIEWER_SHOT:-}" ]; then
  case "$VIEWER_SHOT" in /*) ;; *) VIEWER_SHOT="$root/$VIEWER_SHOT" ;; esac
  shot=(--shot "$VIEWER_SHOT")
fi
node "$here/viewer_test.mjs" --page "$tmp/page/index.html" --frames "$frames" --audio "${shot[@]}"

# The exported follower.glb (bundled demo model; the tiny fixture without assets/).
dance=(); [ -f "$root/assets/demo.duo" ] || dance=(--model tests/fixtures/tiny/model.duo \
  --leader tests/fixtures/rollout_tiny_long/leader_pos3d.npy --music tests/fixtures/rollout_tiny_long/music.npy)
say "duolando dance ${dance[*]} (follower.glb): gltf-validator, then a three.js viewer in headless Chromium"
(cd "$root" && "$bin/duolando" dance "${dance[@]}" --out "$tmp/dance" 2>"$tmp/dance.log") || { cat "$tmp/dance.log" >&2; exit 1; }
node "$here/validate_glb.mjs" "$tmp/dance/follower.glb"
node "$here/glb_test.mjs" --glb "$tmp/dance/follower.glb"
# The bare demo also wrote the bundled solo dancer into solo/, the pages linked both ways.
if [ -d "$tmp/dance/solo" ]; then
  say "the bare demo's solo dancer: gltf-validator on solo/dancer.glb, both pages in headless Chromium"
  node "$here/validate_glb.mjs" "$tmp/dance/solo/dancer.glb"
  node "$here/demo_pages_test.mjs" --dir "$tmp/dance"
elif [ -f "$root/assets/bailando_demo.duo" ]; then
  echo "the bare demo wrote no solo/ although assets/bailando_demo.duo exists" >&2; cat "$tmp/dance.log" >&2; exit 1
fi
say "done"

# The live page of `duolando live` (docs/VIEWER.md, "The live page"): the server streams the demo at 30 fps.
say "testing the live page in headless Chromium"
node "$here/live_test.mjs" --bin "$bin/duolando"
say "done (live)"
