#!/usr/bin/env bash
# Makes the video fixtures of `fewview_video`'s tests with FFmpeg (an independent
# encoder/decoder), into crates/video/tests/fixtures/video/.
#
# Rerun:   bash tools/make-video-fixtures.sh        (needs ffmpeg: bash scripts/setup.sh)
# Made with: ffmpeg 5.1.9-0+deb12u1 (Debian 12), libx264, libx265.
#
#   testsrc_x264.mp4            10 frames of lavfi testsrc, 160x90 (not a multiple of 16, so the
#                               SPS crops), 10 fps, libx264 High profile with B-frames (decode
#                               order differs from display order), VUI colour matrix unspecified
#   testsrc_x264.yuv            FFmpeg's decode of it, raw I420, frames in display order
#   testsrc_x264_rgb.png        FFmpeg's decode converted to RGB (swscale defaults), the 10
#                               frames stacked vertically (160x900)
#   testsrc_hevc.mp4            2 frames of H.265 (hev1), which our reader must refuse clearly
#   testsrc_ffmpeg.gif          FFmpeg's animated GIF (palettegen/paletteuse; FFmpeg writes
#                               partial frames with transparency, exercising disposal)
#   testsrc_ffmpeg_gif_rgb.png  FFmpeg's decode of that GIF, frames stacked vertically
set -euo pipefail
cd "$(dirname "$0")/.."
out=crates/video/tests/fixtures/video
mkdir -p "$out"
ff=(ffmpeg -hide_banner -loglevel error -y)

"${ff[@]}" -f lavfi -i testsrc=size=160x90:rate=10:duration=1 \
  -c:v libx264 -preset medium -profile:v high -bf 2 -crf 20 -pix_fmt yuv420p \
  -map_metadata -1 -fflags +bitexact -flags:v +bitexact -movflags +faststart "$out/testsrc_x264.mp4"
"${ff[@]}" -i "$out/testsrc_x264.mp4" -f rawvideo -pix_fmt yuv420p "$out/testsrc_x264.yuv"
"${ff[@]}" -i "$out/testsrc_x264.mp4" -vf "format=rgb24,tile=1x10" -frames:v 1 "$out/testsrc_x264_rgb.png"

"${ff[@]}" -f lavfi -i testsrc=size=64x64:rate=10:duration=0.2 \
  -c:v libx265 -x265-params log-level=error -pix_fmt yuv420p -tag:v hev1 \
  -map_metadata -1 -fflags +bitexact "$out/testsrc_hevc.mp4"

"${ff[@]}" -f lavfi -i testsrc=size=64x48:rate=10:duration=0.5 \
  -vf "split[a][b];[a]palettegen[p];[b][p]paletteuse" -fflags +bitexact "$out/testsrc_ffmpeg.gif"
"${ff[@]}" -i "$out/testsrc_ffmpeg.gif" -vf "format=rgb24,tile=1x5" -frames:v 1 "$out/testsrc_ffmpeg_gif_rgb.png"

ls -l "$out"
