#!/usr/bin/env bash
# Reference LPIPS weights the tests compare against (not needed at run time: fewview embeds the
# ST-LPIPS AlexNet). Downloads the PyPI wheels lpips 0.1.4 and stlpips-pytorch 0.0.2 (both
# BSD-2-Clause) with pip and unpacks their weight files into .cache/lpips-weights/ (git-ignored):
#   lpips/{alex,vgg,squeeze}.pth      the lpips v0.1 linear heads
#   stlpips/{alex,vgg}_shift_tolerant.pth   the full ST-LPIPS networks
# Idempotent: does nothing when the files are there.
set -euo pipefail
cd "$(dirname "$0")/.."
dest=.cache/lpips-weights
want=("$dest/lpips/alex.pth" "$dest/lpips/vgg.pth" "$dest/lpips/squeeze.pth"
      "$dest/stlpips/alex_shift_tolerant.pth" "$dest/stlpips/vgg_shift_tolerant.pth")
missing=0
for f in "${want[@]}"; do [ -s "$f" ] || missing=1; done
[ "$missing" = 0 ] && exit 0

if ! python3 -m pip --version >/dev/null 2>&1; then
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq && apt-get install -y -qq python3-pip >/dev/null
fi
wheels=$(mktemp -d)
trap 'rm -rf "$wheels"' EXIT
python3 -m pip download -q --no-deps --only-binary=:all: -d "$wheels" lpips==0.1.4 stlpips-pytorch==0.0.2
mkdir -p "$dest/lpips" "$dest/stlpips"
python3 - "$wheels" "$dest" <<'PY'
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
for f in "${want[@]}"; do [ -s "$f" ] || { echo "setup-lpips: $f missing after download" >&2; exit 1; }; done
echo "setup-lpips: weights in $dest"
