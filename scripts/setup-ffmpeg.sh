#!/usr/bin/env bash
# Installs Debian's ffmpeg (ffmpeg + ffprobe), the independent reference reader/writer that the
# video tests of `fewview_scene::video` compare against. Idempotent: does nothing when `ffprobe`
# is already on PATH. Needs root (CI and developer machines run as root).
set -euo pipefail

if command -v ffprobe >/dev/null 2>&1 && command -v ffmpeg >/dev/null 2>&1; then
  exit 0
fi

export DEBIAN_FRONTEND=noninteractive
apt-get update -qq
apt-get install -y -qq --no-install-recommends ffmpeg >/dev/null
command -v ffprobe >/dev/null
