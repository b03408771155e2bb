//! Round trips through our own reader, and cross-checks against FFmpeg (an independent
//! encoder, decoder and prober): `ffprobe`/`ffmpeg` at test time (installed by
//! `scripts/setup.sh`) and FFmpeg-made fixtures (`tools/make-video-fixtures.sh`).

use std::path::{Path, PathBuf};
use std::process::Command;

use super::color::{Matrix, YuvFormat};
use super::*;

/// Peak signal-to-noise ratio in dB of two equal-size images with values in `[0, 1]`.
fn psnr(a: &Image, b: &Image) -> f64 {
    assert_eq!(
        (a.width, a.height, a.channels),
        (b.width, b.height, b.channels)
    );
    let mse = a
        .data
        .iter()
        .zip(&b.data)
        .map(|(x, y)| ((*x as f64) - (*y as f64)).powi(2))
        .sum::<f64>()
        / a.data.len() as f64;
    if mse == 0.0 {
        f64::INFINITY
    } else {
        -10.0 * mse.log10()
    }
}

/// The top-left `w × h` window of `img`.
fn window(img: &Image, w: usize, h: usize) -> Image {
    let mut out = Image::new(w, h, img.channels);
    for y in 0..h {
        for x in 0..w {
            for c in 0..img.channels {
                out.set(x, y, c, img.get(x, y, c));
            }
        }
    }
    out
}

/// A smooth animation: drifting colour gradients and a soft-edged disk (a 4-pixel smoothstep
/// rim, like a defocused or anti-aliased render) moving on a circle.
fn animation(width: usize, height: usize, frames: usize) -> Vec<Image> {
    (0..frames)
        .map(|t| {
            let phase = t as f32 / frames as f32 * std::f32::consts::TAU;
            let (cx, cy) = (
                width as f32 * (0.5 + 0.25 * phase.cos()),
                height as f32 * (0.5 + 0.25 * phase.sin()),
            );
            let radius = 0.18 * width.min(height) as f32;
            let mut img = Image::new(width, height, 3);
            for y in 0..height {
                for x in 0..width {
                    let (u, v) = (x as f32 / width as f32, y as f32 / height as f32);
                    let bg = [
                        0.15 + 0.7 * u,
                        0.2 + 0.6 * v,
                        0.5 + 0.3 * (std::f32::consts::PI * (u + v) + phase).sin(),
                    ];
                    let d = ((x as f32 + 0.5 - cx).powi(2) + (y as f32 + 0.5 - cy).powi(2)).sqrt();
                    let s = ((radius - d) / 4.0 + 0.5).clamp(0.0, 1.0);
                    let cover = s * s * (3.0 - 2.0 * s);
                    let disk = [0.95, 0.85, 0.1];
                    for c in 0..3 {
                        img.set(x, y, c, bg[c] * (1.0 - cover) + disk[c] * cover);
                    }
                }
            }
            img
        })
        .collect()
}

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/video")
        .join(name)
}

/// An FFmpeg tool, or a panic that says how to install it.
fn ffmpeg_tool(name: &str) -> Command {
    let found = Command::new(name)
        .arg("-version")
        .output()
        .is_ok_and(|o| o.status.success());
    assert!(
        found,
        "`{name}` not found: run `bash scripts/setup.sh` (scripts/test.sh does)"
    );
    let mut cmd = Command::new(name);
    cmd.args(["-hide_banner", "-v", "error"]);
    cmd
}

fn run_ok(cmd: &mut Command) -> Vec<u8> {
    let out = cmd.output().expect("spawn ffmpeg tool");
    assert!(
        out.status.success(),
        "{cmd:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    out.stdout
}

/// 8-bit interleaved RGB as an `Image`.
fn rgb8_image(width: usize, height: usize, bytes: &[u8]) -> Image {
    assert_eq!(bytes.len(), width * height * 3);
    Image::from_vec(
        width,
        height,
        3,
        bytes.iter().map(|&b| b as f32 / 255.0).collect(),
    )
}

#[test]
fn mp4_round_trip_keeps_quality_count_and_rate() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("orbit.mp4");
    let frames = animation(128, 96, 24);
    write_video(&path, &frames, 24.0, &VideoOptions::default()).unwrap();
    let (back, fps) = read_video(&path).unwrap();
    assert_eq!(back.len(), frames.len());
    assert_eq!(fps, 24.0);
    let worst = frames
        .iter()
        .zip(&back)
        .map(|(a, b)| psnr(a, b))
        .fold(f64::INFINITY, f64::min);
    assert!(worst >= 35.0, "worst frame PSNR {worst:.2} dB");
    // Identical input gives identical bytes (single-threaded encoder, fixed timestamps).
    let again = dir.path().join("again.mp4");
    write_video(&again, &frames, 24.0, &VideoOptions::default()).unwrap();
    assert_eq!(
        std::fs::read(&path).unwrap(),
        std::fs::read(&again).unwrap()
    );
    // The fastest rate the 32-bit timescale holds is recorded as given; a faster one is
    // refused rather than saved wrong (the timescale used to saturate), and nothing is written.
    let fastest = dir.path().join("fastest.mp4");
    write_video(
        &fastest,
        &frames[..2],
        MAX_MP4_FPS,
        &VideoOptions::default(),
    )
    .unwrap();
    assert_eq!(read_video(&fastest).unwrap().1, MAX_MP4_FPS);
    let too_fast = dir.path().join("too_fast.mp4");
    let err = write_video(&too_fast, &frames[..2], 1e7, &VideoOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("too_fast.mp4") && err.contains("timescale"),
        "{err}"
    );
    assert!(!too_fast.exists());
}

#[test]
fn mp4_quality_options_trade_size_for_fidelity() {
    let dir = tempfile::tempdir().unwrap();
    let frames = animation(96, 64, 12);
    let mut results = Vec::new();
    for quality in [H264Quality::ConstantQp(12), H264Quality::ConstantQp(36)] {
        let path = dir
            .path()
            .join(format!("{quality:?}.mp4").replace(['(', ')', ' '], ""));
        let opts = VideoOptions {
            quality,
            ..VideoOptions::default()
        };
        write_video(&path, &frames, 30.0, &opts).unwrap();
        let (back, _) = read_video(&path).unwrap();
        let mean = frames
            .iter()
            .zip(&back)
            .map(|(a, b)| psnr(a, b))
            .sum::<f64>()
            / 12.0;
        results.push((std::fs::metadata(&path).unwrap().len(), mean));
    }
    let ((fine_size, fine_psnr), (coarse_size, coarse_psnr)) = (results[0], results[1]);
    assert!(fine_size > 2 * coarse_size, "{results:?}");
    assert!(fine_psnr > coarse_psnr + 6.0, "{results:?}");
    assert!(fine_psnr > 40.0, "{results:?}");

    // Bitrate mode: a generous budget still decodes to every frame at good quality.
    let path = dir.path().join("bitrate.mp4");
    let opts = VideoOptions {
        quality: H264Quality::Bitrate {
            bits_per_second: 2_000_000,
        },
        ..VideoOptions::default()
    };
    write_video(&path, &frames, 30.0, &opts).unwrap();
    let (back, fps) = read_video(&path).unwrap();
    assert_eq!((back.len(), fps), (12, 30.0));
    let worst = frames
        .iter()
        .zip(&back)
        .map(|(a, b)| psnr(a, b))
        .fold(f64::INFINITY, f64::min);
    assert!(worst > 35.0, "bitrate mode worst PSNR {worst:.2}");
}

#[test]
fn mp4_odd_sizes_are_padded_or_cropped() {
    let dir = tempfile::tempdir().unwrap();
    let frames = animation(97, 65, 4);
    for (policy, size) in [
        (OddSizePolicy::PadEdge, (98, 66)),
        (OddSizePolicy::Crop, (96, 64)),
    ] {
        let path = dir.path().join(format!("{policy:?}.mp4"));
        let opts = VideoOptions {
            odd_size: policy,
            ..VideoOptions::default()
        };
        write_video(&path, &frames, 10.0, &opts).unwrap();
        let (back, _) = read_video(&path).unwrap();
        assert_eq!((back[0].width, back[0].height), size);
        for (a, b) in frames.iter().zip(&back) {
            let p = psnr(&window(a, 96, 64), &window(b, 96, 64));
            assert!(p >= 35.0, "{policy:?}: {p:.2} dB");
        }
        if policy == OddSizePolicy::PadEdge {
            // The added column and row repeat the last real ones.
            for y in [10, 40] {
                let (l, r) = (back[0].pixel(96, y), back[0].pixel(97, y));
                assert!(
                    l.iter().zip(r).all(|(a, b)| (a - b).abs() < 0.03),
                    "{l:?} vs {r:?}"
                );
            }
            let (t, b) = (back[0].pixel(50, 64), back[0].pixel(50, 65));
            assert!(
                t.iter().zip(b).all(|(x, y)| (x - y).abs() < 0.03),
                "{t:?} vs {b:?}"
            );
        }
    }
}

#[test]
fn mp4_flat_colours_come_back_as_written() {
    let dir = tempfile::tempdir().unwrap();
    let colours = [
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, 0.0, 1.0],
        [0.5, 0.5, 0.5],
        [0.9, 0.6, 0.2],
    ];
    let frames: Vec<Image> = colours.iter().map(|c| Image::filled(64, 48, c)).collect();
    let path = dir.path().join("flat.mp4");
    let opts = VideoOptions {
        quality: H264Quality::ConstantQp(10),
        ..VideoOptions::default()
    };
    write_video(&path, &frames, 5.0, &opts).unwrap();
    let (back, _) = read_video(&path).unwrap();
    for (colour, frame) in colours.iter().zip(&back) {
        let p = frame.pixel(32, 24);
        for c in 0..3 {
            assert!(
                (p[c] - colour[c]).abs() < 0.02,
                "{colour:?} came back as {p:?}"
            );
        }
    }
}

/// FFmpeg's prober and decoder read our MP4 as what we meant to write.
#[test]
fn ffmpeg_reads_our_mp4() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("orbit.mp4");
    let frames = animation(128, 96, 30);
    write_video(&path, &frames, 30.0, &VideoOptions::default()).unwrap();

    let json = run_ok(ffmpeg_tool("ffprobe").args([
        "-count_frames",
        "-select_streams",
        "v:0",
        "-show_entries",
        "stream=codec_name,profile,level,pix_fmt,width,height,nb_read_frames,r_frame_rate,avg_frame_rate,color_space,color_range",
        "-of",
        "json",
    ]).arg(&path));
    let probe: serde_json::Value = serde_json::from_slice(&json).unwrap();
    let stream = &probe["streams"][0];
    assert_eq!(stream["codec_name"], "h264", "{probe}");
    assert_eq!(stream["pix_fmt"], "yuv420p", "{probe}");
    assert_eq!(stream["profile"], "Constrained Baseline", "{probe}");
    assert_eq!(stream["level"], 30, "{probe}");
    assert_eq!(
        (stream["width"].as_u64(), stream["height"].as_u64()),
        (Some(128), Some(96))
    );
    assert_eq!(stream["nb_read_frames"], "30", "{probe}");
    assert_eq!(stream["r_frame_rate"], "30/1", "{probe}");
    assert_eq!(stream["avg_frame_rate"], "30/1", "{probe}");
    assert_eq!(stream["color_space"], "bt709", "{probe}");
    assert_eq!(stream["color_range"], "tv", "{probe}");

    // FFmpeg's H.264 decode equals ours bit for bit.
    let raw = run_ok(
        ffmpeg_tool("ffmpeg")
            .arg("-i")
            .arg(&path)
            .args(["-f", "rawvideo", "-pix_fmt", "yuv420p", "-"]),
    );
    let (ours, _, _) = mp4_h264::decode_mp4_yuv(&path).unwrap();
    let frame_bytes = 128 * 96 * 3 / 2;
    assert_eq!(raw.len(), 30 * frame_bytes);
    for (i, (a, b)) in ours.iter().zip(raw.chunks_exact(frame_bytes)).enumerate() {
        assert!(
            a.to_i420() == b,
            "frame {i}: our decode differs from FFmpeg's"
        );
    }

    // Frame 17, decoded and converted to RGB by FFmpeg (honouring our BT.709 signalling).
    let raw = run_ok(ffmpeg_tool("ffmpeg").arg("-i").arg(&path).args([
        "-vf",
        r"select=eq(n\,17)",
        "-frames:v",
        "1",
        "-f",
        "rawvideo",
        "-pix_fmt",
        "rgb24",
        "-",
    ]));
    let theirs = rgb8_image(128, 96, &raw);
    let p = psnr(&theirs, &frames[17]);
    assert!(p >= 35.0, "FFmpeg's decode of frame 17: {p:.2} dB");
}

/// Our reader decodes FFmpeg's libx264 output (High profile, B-frames, cropped 160x90)
/// bit-exactly in Y'CbCr and close to FFmpeg's own RGB conversion.
#[test]
fn we_read_ffmpegs_mp4() {
    let path = fixture("testsrc_x264.mp4");
    let (pictures, format, fps) = mp4_h264::decode_mp4_yuv(&path).unwrap();
    assert_eq!(fps, 10.0);
    assert_eq!(
        format,
        YuvFormat {
            matrix: Matrix::Bt601,
            full_range: false
        }
    );
    let reference = std::fs::read(fixture("testsrc_x264.yuv")).unwrap();
    let (w, h) = (160, 90);
    let frame_bytes = w * h * 3 / 2;
    assert_eq!(pictures.len(), reference.len() / frame_bytes);
    for (i, (picture, expected)) in pictures
        .iter()
        .zip(reference.chunks_exact(frame_bytes))
        .enumerate()
    {
        assert_eq!((picture.width, picture.height), (w, h));
        assert!(
            picture.to_i420() == expected,
            "frame {i} differs from FFmpeg's decode"
        );
    }

    // FFmpeg's RGB (swscale defaults) replicates each chroma sample over 2×2 pixels, we
    // interpolate bilinearly: the two differ where chroma jumps (testsrc's hard colour edges),
    // and agree where it is locally flat. Compare there, where only the matrix, the range and
    // rounding can differ.
    let (frames, fps) = read_video(&path).unwrap();
    assert_eq!((frames.len(), fps), (10, 10.0));
    let stacked = Image::load(&fixture("testsrc_x264_rgb.png")).unwrap();
    let (cw, ch) = (w / 2, h / 2);
    for (i, (frame, picture)) in frames.iter().zip(&pictures).enumerate() {
        let flat_chroma = |x: usize, y: usize| {
            let (cx, cy) = (x / 2, y / 2);
            let at = |plane: &[u8], dx: isize, dy: isize| {
                let xx = (cx as isize + dx).clamp(0, cw as isize - 1) as usize;
                let yy = (cy as isize + dy).clamp(0, ch as isize - 1) as usize;
                plane[yy * cw + xx] as i32
            };
            (-1..=1).all(|dy| {
                (-1..=1).all(|dx| {
                    (at(&picture.u, dx, dy) - at(&picture.u, 0, 0)).abs() <= 2
                        && (at(&picture.v, dx, dy) - at(&picture.v, 0, 0)).abs() <= 2
                })
            })
        };
        let (mut sum, mut count, mut all) = (0.0f64, 0usize, 0.0f64);
        for y in 0..h {
            for x in 0..w {
                for c in 0..3 {
                    let theirs = stacked.get(x, i * h + y, c) as f64;
                    let d = (frame.get(x, y, c) as f64 - theirs).powi(2);
                    all += d;
                    if flat_chroma(x, y) {
                        sum += d;
                        count += 1;
                    }
                }
            }
        }
        let flat_psnr = -10.0 * (sum / count as f64).log10();
        let all_psnr = -10.0 * (all / (w * h * 3) as f64).log10();
        let share = count as f64 / (w * h * 3) as f64;
        assert!(
            share > 0.4,
            "frame {i}: only {:.0} % of pixels have flat chroma",
            share * 100.0
        );
        // Measured: ~50.6 dB on 53 % of the values, 22.3 dB everywhere.
        assert!(
            flat_psnr >= 45.0,
            "frame {i}: {flat_psnr:.2} dB against FFmpeg's RGB on flat chroma"
        );
        // Everywhere, hard chroma edges included: bounded by the interpolation difference.
        assert!(
            all_psnr >= 20.0,
            "frame {i}: {all_psnr:.2} dB against FFmpeg's RGB"
        );
    }
}

#[test]
fn gif_round_trip_bounds_palette_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("orbit.gif");
    let frames = animation(96, 64, 10);
    write_video(&path, &frames, 25.0, &VideoOptions::default()).unwrap();
    let (back, fps) = read_video(&path).unwrap();
    assert_eq!((back.len(), fps), (10, 25.0));
    for (i, (a, b)) in frames.iter().zip(&back).enumerate() {
        // Palette error: PSNR, mean and 99th-percentile absolute error per channel value.
        let p = psnr(a, b);
        let mut errors: Vec<f32> = a
            .data
            .iter()
            .zip(&b.data)
            .map(|(x, y)| (x - y).abs())
            .collect();
        errors.sort_by(f32::total_cmp);
        let mean = errors.iter().sum::<f32>() / errors.len() as f32;
        let p99 = errors[errors.len() * 99 / 100];
        let max = *errors.last().unwrap();
        // Measured with NeuQuant at speed 3: ~31 dB, mean 0.020, p99 0.085, max 0.19.
        assert!(p >= 30.0, "GIF frame {i}: PSNR {p:.2} dB");
        assert!(mean <= 0.025, "GIF frame {i}: mean error {mean}");
        assert!(p99 <= 0.1, "GIF frame {i}: 99th-percentile error {p99}");
        assert!(max <= 0.25, "GIF frame {i}: max error {max}");
    }
    // Centisecond timing: 30 fps is stored as 3 cs.
    let path30 = dir.path().join("thirty.gif");
    write_video(&path30, &frames[..2], 30.0, &VideoOptions::default()).unwrap();
    let (_, fps30) = read_video(&path30).unwrap();
    assert!((fps30 - 100.0 / 3.0).abs() < 1e-3, "{fps30}");
    let err = write_video(
        &dir.path().join("fast.gif"),
        &frames,
        60.0,
        &VideoOptions::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("fast.gif") && err.contains("50 fps"), "{err}");
}

/// FFmpeg's GIF (partial frames over transparency) decodes to exactly FFmpeg's own frames.
#[test]
fn we_read_ffmpegs_gif() {
    let (frames, fps) = read_video(&fixture("testsrc_ffmpeg.gif")).unwrap();
    assert_eq!((frames.len(), fps), (5, 10.0));
    let stacked = Image::load(&fixture("testsrc_ffmpeg_gif_rgb.png")).unwrap();
    let (w, h) = (64, 48);
    for (i, frame) in frames.iter().enumerate() {
        assert_eq!((frame.width, frame.height), (w, h));
        let offset = i * w * h * 3;
        assert!(
            frame.to_u8() == stacked.to_u8()[offset..offset + w * h * 3],
            "GIF frame {i} differs from FFmpeg's decode"
        );
    }
}

#[test]
fn frame_folder_round_trip_is_exact_at_8_bits() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("frames");
    // Values on the 8-bit grid survive PNG exactly; odd sizes stay as they are.
    let frames: Vec<Image> = animation(37, 23, 12)
        .into_iter()
        .map(|f| {
            let data = f.to_u8().into_iter().map(|b| b as f32 / 255.0).collect();
            Image::from_vec(37, 23, 3, data)
        })
        .collect();
    write_video(&path, &frames, 12.5, &VideoOptions::default()).unwrap();
    assert!(path.join("frame_00011.png").is_file());
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let mode = std::fs::metadata(&path).unwrap().permissions().mode();
        assert_eq!(mode & 0o777, 0o755, "frame folder mode {mode:o}");
    }
    let (back, fps) = read_video(&path).unwrap();
    assert_eq!((back.len(), fps), (12, 12.5));
    for (a, b) in frames.iter().zip(&back) {
        assert_eq!(a.to_u8(), b.to_u8());
    }
    // Rewriting with fewer frames replaces the folder: no stale frame 11 survives.
    let trailing_slash = PathBuf::from(format!("{}/", path.display()));
    write_video(
        &trailing_slash,
        &frames[..3],
        12.5,
        &VideoOptions::default(),
    )
    .unwrap();
    assert_eq!(read_video(&path).unwrap().0.len(), 3);
    assert!(!path.join("frame_00011.png").exists());
    // A frame deleted by hand no longer matches video.json: an error, not a wrong timing.
    std::fs::remove_file(path.join("frame_00002.png")).unwrap();
    let err = read_video(&path).map(|_| ()).unwrap_err().to_string();
    assert!(
        err.contains("video.json") && err.contains("records 3 frames"),
        "{err}"
    );
    // A folder holding other files is never replaced.
    std::fs::write(path.join("notes.txt"), b"mine").unwrap();
    let err = write_video(&path, &frames, 12.5, &VideoOptions::default())
        .unwrap_err()
        .to_string();
    assert!(err.contains("notes.txt") && err.contains("frames"), "{err}");
}

#[test]
fn foreign_frame_folders_sort_naturally_and_composite_alpha() {
    let dir = tempfile::tempdir().unwrap();
    let folder = dir.path().join("theirs");
    std::fs::create_dir(&folder).unwrap();
    // Values 0, 1, 2, ..., 10 written under names that sort wrongly as plain strings.
    for k in 0..=10usize {
        let v = k as f32 / 255.0;
        let img = if k == 10 {
            Image::filled(4, 2, &[v, v, v, 0.0]) // fully transparent: becomes the background
        } else {
            Image::filled(4, 2, &[v, v, v])
        };
        img.save_png(&folder.join(format!("img{k}.png"))).unwrap();
    }
    std::fs::write(folder.join("readme.txt"), b"not a frame").unwrap();
    image::RgbImage::from_pixel(4, 2, image::Rgb([200, 100, 50]))
        .save(folder.join("img10b.JPG"))
        .unwrap();
    let (frames, fps) = read_video(&folder).unwrap();
    assert_eq!((frames.len(), fps), (12, DEFAULT_FOLDER_FPS));
    let jpeg = frames[11].to_u8();
    for (got, want) in jpeg[..3].iter().zip([200u8, 100, 50]) {
        assert!(got.abs_diff(want) <= 3, "JPEG frame {:?}", &jpeg[..3]);
    }
    for (k, f) in frames.iter().take(10).enumerate() {
        assert_eq!(f.to_u8()[0] as usize, k);
    }
    assert_eq!(frames[10].pixel(0, 0), &[1.0, 1.0, 1.0]);
    let black = ReadOptions {
        background: [0.0, 0.0, 0.0],
    };
    assert_eq!(
        read_video_with(&folder, &black).unwrap().0[10].pixel(0, 0),
        &[0.0, 0.0, 0.0]
    );

    Image::filled(5, 2, &[0.0, 0.0, 0.0])
        .save_png(&folder.join("img11.png"))
        .unwrap();
    let err = read_video(&folder).unwrap_err().to_string();
    assert!(err.contains("img11.png") && err.contains("5x2"), "{err}");
}

#[test]
fn errors_name_the_file_and_the_problem() {
    let dir = tempfile::tempdir().unwrap();
    let frames = animation(32, 32, 3);
    let opts = VideoOptions::default();
    let message = |r: Result<(Vec<Image>, f32)>| r.map(|_| ()).unwrap_err().to_string();

    let missing = dir.path().join("missing.mp4");
    let err = message(read_video(&missing));
    assert!(
        err.contains("missing.mp4") && err.contains("No such file"),
        "{err}"
    );
    let err = message(read_video(&dir.path().join("missing.gif")));
    assert!(err.contains("missing.gif"), "{err}");
    let err = message(read_video(&dir.path().join("no_such_folder")));
    assert!(err.contains("no_such_folder"), "{err}");

    // Truncated MP4: the `moov` box (written last) is gone.
    let whole = dir.path().join("whole.mp4");
    write_video(&whole, &frames, 10.0, &opts).unwrap();
    let bytes = std::fs::read(&whole).unwrap();
    let cut = dir.path().join("cut.mp4");
    std::fs::write(&cut, &bytes[..bytes.len() * 2 / 3]).unwrap();
    let err = message(read_video(&cut));
    assert!(err.contains("cut.mp4") && err.contains("MP4"), "{err}");
    assert_eq!(err.lines().count(), 1);

    // Corrupted H.264 inside an intact container: a broken NAL length, then broken slice data.
    let mdat = bytes.windows(4).position(|w| w == b"mdat").unwrap();
    let bad = dir.path().join("garbled.mp4");
    for (offset, problem) in [(16, "bad NAL length"), (100, "bitstream error")] {
        let mut garbled = bytes.clone();
        for b in &mut garbled[mdat + offset..mdat + offset + 40] {
            *b ^= 0x5a;
        }
        std::fs::write(&bad, &garbled).unwrap();
        let err = message(read_video(&bad));
        assert!(
            err.contains("garbled.mp4") && err.contains("corrupt H.264 data"),
            "{err}"
        );
        assert!(err.contains(problem), "{err}");
    }

    let err = message(read_video(&fixture("testsrc_hevc.mp4")));
    assert!(
        err.contains("testsrc_hevc.mp4") && err.contains("HEVC"),
        "{err}"
    );

    let not_gif = dir.path().join("fake.gif");
    std::fs::write(&not_gif, b"GIF89a garbage").unwrap();
    let err = message(read_video(&not_gif));
    assert!(err.contains("fake.gif") && err.contains("GIF"), "{err}");

    let err = write_video(&dir.path().join("clip.avi"), &frames, 10.0, &opts)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("clip.avi") && err.contains("unsupported video container"),
        "{err}"
    );
    let err = message(read_video(&dir.path().join("clip.webm")));
    assert!(err.contains("clip.webm") && err.contains(".webm"), "{err}");

    let target = dir.path().join("out.mp4");
    let rgba = vec![Image::filled(8, 8, &[0.0, 0.0, 0.0, 1.0])];
    let err = write_video(&target, &rgba, 10.0, &opts)
        .unwrap_err()
        .to_string();
    assert!(err.contains("out.mp4") && err.contains("RGBA"), "{err}");
    let mut nan = frames.clone();
    nan[2].data[5] = f32::NAN;
    let err = write_video(&target, &nan, 10.0, &opts)
        .unwrap_err()
        .to_string();
    assert!(err.contains("frame 2") && err.contains("NaN"), "{err}");
    let mixed = vec![frames[0].clone(), Image::new(16, 32, 3)];
    let err = write_video(&target, &mixed, 10.0, &opts)
        .unwrap_err()
        .to_string();
    assert!(err.contains("frame 1 is 16x32"), "{err}");
    let err = write_video(&target, &[], 10.0, &opts)
        .unwrap_err()
        .to_string();
    assert!(err.contains("no frames"), "{err}");
    let err = write_video(&target, &frames, f32::NAN, &opts)
        .unwrap_err()
        .to_string();
    assert!(err.contains("frame rate"), "{err}");
    assert!(!target.exists(), "a failed write must leave nothing behind");
}

#[test]
fn grey_frames_are_written_as_rgb() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("grey.mp4");
    let grey: Vec<Image> = (0..3)
        .map(|k| Image::filled(16, 16, &[0.25 * k as f32]))
        .collect();
    write_video(&path, &grey, 10.0, &VideoOptions::default()).unwrap();
    let (back, _) = read_video(&path).unwrap();
    for (k, f) in back.iter().enumerate() {
        for &v in f.pixel(8, 8) {
            assert!((v - 0.25 * k as f32).abs() < 0.02, "{k}: {v}");
        }
    }
}

/// Seekable IDR frames where `keyframe_interval` asks, as FFmpeg's prober sees them.
#[test]
fn mp4_keyframes_follow_the_interval() {
    let dir = tempfile::tempdir().unwrap();
    let frames = animation(64, 48, 130);
    for (interval, expected) in [(60, vec![0, 60, 120]), (25, vec![0, 25, 50, 75, 100, 125])] {
        let path = dir.path().join(format!("kf{interval}.mp4"));
        let opts = VideoOptions {
            keyframe_interval: interval,
            ..VideoOptions::default()
        };
        write_video(&path, &frames, 30.0, &opts).unwrap();
        let csv = run_ok(
            ffmpeg_tool("ffprobe")
                .args([
                    "-select_streams",
                    "v:0",
                    "-show_entries",
                    "packet=flags",
                    "-of",
                    "csv",
                ])
                .arg(&path),
        );
        let keys: Vec<usize> = String::from_utf8(csv)
            .unwrap()
            .lines()
            .enumerate()
            .filter(|(_, line)| line.contains(",K"))
            .map(|(i, _)| i)
            .collect();
        assert_eq!(keys, expected, "keyframe_interval {interval}");
    }
}
