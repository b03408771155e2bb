//! `.mp4` files with one H.264 video track: encoding with Cisco's OpenH264 (built from the
//! source bundled in the `openh264` crate), muxing/demuxing with the `mp4` crate, and the
//! R'G'B' ↔ Y'CbCr conversion of [`super::color`].
//!
//! What we write: H.264 Constrained Baseline (plays everywhere; no B-frames, so decode order is
//! display order and no `ctts`/edit list is needed) at the lowest sufficient level from 3.0
//! up ([`h264_level`]), yuv420p, BT.709 limited range signalled in the SPS VUI (colour
//! primaries, transfer and matrix all BT.709), an IDR every [`VideoOptions::keyframe_interval`] frames for seeking, constant frame duration
//! `1000 / round(1000 · fps)` s. Parameter sets live in the `avcC` box (ISO/IEC 14496-15), and
//! are also repeated in-band before each IDR, as OpenH264 emits them (allowed for `avc1`).
//!
//! What we read: the first H.264 (`avc1`) video track of a non-fragmented MP4, 8-bit 4:2:0, any
//! profile OpenH264 decodes (Baseline, Main and High, B-frames included), the colour matrix
//! and range taken from the SPS VUI (unspecified ⇒ BT.601 limited, as FFmpeg assumes).

use std::io::{BufReader, Cursor};
use std::path::Path;

use openh264::OpenH264API;
use openh264::decoder::{Decoder, DecoderConfig, Flush};
use openh264::encoder::{
    BitRate, Encoder, EncoderConfig, FrameRate, FrameType, IntraFramePeriod, Level, QpRange,
    RateControlMode, VuiConfig,
};
use openh264::formats::{YUVBuffer, YUVSource};

use super::color::{Matrix, Yuv420, YuvFormat, rgb_to_yuv420, yuv420_to_rgb};
use super::options::{H264Quality, OddSizePolicy, VideoOptions};
use fewview_scene::Image;
use fewview_scene::error::{Result, SceneError};

/// NAL unit types (ITU-T H.264 Table 7-1) we treat specially.
const NAL_SPS: u8 = 7;
const NAL_PPS: u8 = 8;
/// Ticks per frame in the track timescale; the timescale is `round(1000 · fps)`.
const TICKS_PER_FRAME: u32 = 1000;

/// The highest frame rate an MP4 written here can record: the track timescale,
/// `TICKS_PER_FRAME` ticks a frame, is a 32-bit field, so a faster rate would be saved wrong
/// (the timescale saturates).
pub const MAX_MP4_FPS: f32 = (u32::MAX / TICKS_PER_FRAME) as f32;

/// The even frame size that 4:2:0 can carry for a `width × height` input.
pub(crate) fn coded_size(width: usize, height: usize, policy: OddSizePolicy) -> (usize, usize) {
    match policy {
        OddSizePolicy::PadEdge => (width + width % 2, height + height % 2),
        OddSizePolicy::Crop => (width - width % 2, height - height % 2),
    }
}

/// `img` (RGB) padded by edge replication or cropped to `(w, h)`.
fn fit_to(img: &Image, (w, h): (usize, usize)) -> Image {
    if (w, h) == (img.width, img.height) {
        return img.clone();
    }
    let mut out = Image::new(w, h, 3);
    for y in 0..h {
        let sy = y.min(img.height - 1);
        for x in 0..w {
            let sx = x.min(img.width - 1);
            let src = img.index(sx, sy, 0);
            let dst = out.index(x, y, 0);
            out.data[dst..dst + 3].copy_from_slice(&img.data[src..src + 3]);
        }
    }
    out
}

/// Splits an Annex B byte stream (start codes `00 00 01` / `00 00 00 01`) into NAL units
/// without their start codes or trailing zero bytes.
fn split_annex_b(stream: &[u8]) -> Vec<&[u8]> {
    let mut starts = Vec::new(); // index of the first byte after each start code
    let mut i = 0;
    while i + 2 < stream.len() {
        if stream[i] == 0 && stream[i + 1] == 0 && stream[i + 2] == 1 {
            starts.push(i + 3);
            i += 3;
        } else {
            i += 1;
        }
    }
    let mut units = Vec::with_capacity(starts.len());
    for (k, &s) in starts.iter().enumerate() {
        let mut end = starts.get(k + 1).map_or(stream.len(), |&n| n - 3);
        while end > s && stream[end - 1] == 0 {
            end -= 1;
        }
        if end > s {
            units.push(&stream[s..end]);
        }
    }
    units
}

/// One encoded access unit, as length-prefixed NAL units for the `mdat`.
struct EncodedFrame {
    avcc: Vec<u8>,
    is_sync: bool,
}

/// The encoded stream: parameter sets for `avcC` and one access unit per frame.
struct EncodedStream {
    sps: Vec<u8>,
    pps: Vec<u8>,
    frames: Vec<EncodedFrame>,
    width: usize,
    height: usize,
}

/// An H.264 level (ITU-T H.264 Annex A) and its bitrate ceiling.
#[derive(Clone, Copy, Debug)]
pub(crate) struct H264Level {
    level: Level,
    /// MaxBR × cpbBrNalFactor, bit/s.
    max_nal_bitrate: u32,
}

/// The lowest H.264 level from 3.0 up whose limits (ITU-T H.264 Table A-1: MaxFS frame size
/// and MaxMBPS macroblock rate, and Annex A.3.1's `width, height ≤ √(8 · MaxFS)` macroblocks)
/// admit `width × height` at `fps`. OpenH264 otherwise writes level 5.0 whatever the size,
/// which some hardware decoders refuse; 3.0 is the floor every player supports. `None` when
/// even level 5.2 is exceeded (the caller then leaves the choice to OpenH264).
pub(crate) fn h264_level(width: usize, height: usize, fps: f32) -> Option<H264Level> {
    // (level, MaxMBPS, MaxFS, MaxBR in 1000 bit/s for Baseline/Main/Extended)
    const LEVELS: [(Level, f64, f64, u32); 9] = [
        (Level::Level_3_0, 40_500.0, 1_620.0, 10_000),
        (Level::Level_3_1, 108_000.0, 3_600.0, 14_000),
        (Level::Level_3_2, 216_000.0, 5_120.0, 20_000),
        (Level::Level_4_0, 245_760.0, 8_192.0, 20_000),
        (Level::Level_4_1, 245_760.0, 8_192.0, 50_000),
        (Level::Level_4_2, 522_240.0, 8_704.0, 50_000),
        (Level::Level_5_0, 589_824.0, 22_080.0, 135_000),
        (Level::Level_5_1, 983_040.0, 36_864.0, 240_000),
        (Level::Level_5_2, 2_073_600.0, 36_864.0, 240_000),
    ];
    let (mbs_w, mbs_h) = (width.div_ceil(16) as f64, height.div_ceil(16) as f64);
    let frame_mbs = mbs_w * mbs_h;
    LEVELS
        .iter()
        .find(|(_, max_mbps, max_fs, _)| {
            let side = (8.0 * max_fs).sqrt();
            frame_mbs <= *max_fs
                && mbs_w <= side
                && mbs_h <= side
                && frame_mbs * fps as f64 <= *max_mbps
        })
        .map(|&(level, _, _, max_br)| H264Level {
            level,
            // Table A-1 counts MaxBR in units of cpbBrNalFactor = 1200 bit/s at the NAL level.
            max_nal_bitrate: max_br * 1200,
        })
}

fn encoder_config(width: usize, height: usize, fps: f32, opts: &VideoOptions) -> EncoderConfig {
    let mut config = EncoderConfig::new()
        .max_frame_rate(FrameRate::from_hz(fps))
        // Dropping frames would change the frame count and the timing.
        .skip_frames(false)
        .intra_frame_period(IntraFramePeriod::from_num_frames(opts.keyframe_interval))
        // One thread: OpenH264's output is then a pure function of the input.
        .num_threads(1)
        .vui(VuiConfig::bt709())
        // Background detection (meant for video calls) leaves macroblocks it deems static
        // un-updated; on renders it cost up to 8 dB on individual frames in our tests.
        .background_detection(false);
    let level = h264_level(width, height, fps);
    if let Some(level) = level {
        config = config.level(level.level);
    }
    match opts.quality {
        H264Quality::ConstantQp(qp) => {
            let qp = qp.min(51);
            // A one-point QP range pins the quantiser, so the bitrate target steers nothing;
            // it is set to the level's ceiling because OpenH264 raises the level to fit any
            // larger target. (No HRD parameters are written, so players enforce no bitrate.)
            let ceiling = level.map_or(100_000_000, |l| l.max_nal_bitrate);
            config
                .rate_control_mode(RateControlMode::Quality)
                .qp(QpRange::new(qp, qp))
                .bitrate(BitRate::from_bps(ceiling))
        }
        H264Quality::Bitrate { bits_per_second } => config
            .rate_control_mode(RateControlMode::Bitrate)
            .bitrate(BitRate::from_bps(bits_per_second)),
    }
}

/// Stops OpenH264 from printing to stderr (a library must not print; failures still come back
/// as error codes). `openh264` sets the trace level only after the encoder's lazy
/// initialisation, whose parameter warnings would otherwise be printed on every video.
fn silence(encoder: &mut Encoder) {
    let mut level: u32 = openh264_sys2::WELS_LOG_QUIET as u32;
    // SAFETY: the raw API belongs to a live encoder; OpenH264 accepts TRACE_LEVEL before
    // initialisation (welsEncoderExt.cpp, SetOption) and reads one u32 through the pointer,
    // which outlives the call.
    unsafe {
        encoder.raw_api().set_option(
            openh264_sys2::ENCODER_OPTION_TRACE_LEVEL,
            (&raw mut level).cast(),
        );
    }
}

fn encode(path: &Path, frames: &[Image], fps: f32, opts: &VideoOptions) -> Result<EncodedStream> {
    let (w, h) = coded_size(frames[0].width, frames[0].height, opts.odd_size);
    if w == 0 || h == 0 {
        return Err(SceneError::invalid(
            path,
            format!(
                "{}x{} frames are too small for H.264 4:2:0 after cropping to even size",
                frames[0].width, frames[0].height
            ),
        ));
    }
    if w.max(h) > 3840 || w.min(h) > 2160 {
        return Err(SceneError::invalid(
            path,
            format!("{w}x{h} exceeds OpenH264's limit of 3840x2160 (or 2160x3840)"),
        ));
    }
    let fail = |what: &str, e: openh264::Error| {
        SceneError::format(
            path,
            format!("H.264 encoder failed {what}: {}", describe(&e)),
        )
    };
    let mut encoder =
        Encoder::with_api_config(OpenH264API::from_source(), encoder_config(w, h, fps, opts))
            .map_err(|e| fail("to start", e))?;
    silence(&mut encoder);
    let mut stream = EncodedStream {
        sps: Vec::new(),
        pps: Vec::new(),
        frames: Vec::with_capacity(frames.len()),
        width: w,
        height: h,
    };
    for (index, frame) in frames.iter().enumerate() {
        let yuv = rgb_to_yuv420(&fit_to(frame, (w, h)), YuvFormat::WRITE);
        let source = YUVBuffer::from_vec(yuv.to_i420(), w, h);
        let millis = (index as f64 * 1000.0 / fps as f64).round() as u64;
        let bitstream = encoder
            .encode_at(&source, openh264::Timestamp::from_millis(millis))
            .map_err(|e| fail(&format!("on frame {index}"), e))?;
        let frame_type = bitstream.frame_type();
        if !matches!(frame_type, FrameType::IDR | FrameType::I | FrameType::P) {
            return Err(SceneError::format(
                path,
                format!("H.264 encoder produced no picture for frame {index} ({frame_type:?})"),
            ));
        }
        let annex_b = bitstream.to_vec();
        let mut avcc = Vec::with_capacity(annex_b.len());
        for nal in split_annex_b(&annex_b) {
            match nal[0] & 0x1f {
                NAL_SPS if stream.sps.is_empty() => stream.sps = nal.to_vec(),
                NAL_PPS if stream.pps.is_empty() => stream.pps = nal.to_vec(),
                _ => {}
            }
            avcc.extend_from_slice(&(nal.len() as u32).to_be_bytes());
            avcc.extend_from_slice(nal);
        }
        stream.frames.push(EncodedFrame {
            avcc,
            is_sync: frame_type == FrameType::IDR,
        });
    }
    if stream.sps.is_empty() || stream.pps.is_empty() {
        return Err(SceneError::format(
            path,
            "H.264 encoder emitted no sequence/picture parameter set",
        ));
    }
    Ok(stream)
}

/// The MP4 track timescale for `fps` (ticks per second; one frame lasts [`TICKS_PER_FRAME`]).
fn timescale(fps: f32) -> u32 {
    ((fps as f64) * TICKS_PER_FRAME as f64).round().max(1.0) as u32
}

fn mux(stream: &EncodedStream, fps: f32) -> ::mp4::Result<Vec<u8>> {
    let brand = |s: &str| s.parse::<::mp4::FourCC>().expect("four ASCII characters");
    let config = ::mp4::Mp4Config {
        major_brand: brand("isom"),
        minor_version: 512,
        compatible_brands: vec![brand("isom"), brand("iso2"), brand("avc1"), brand("mp41")],
        timescale: 1000,
    };
    let mut writer = ::mp4::Mp4Writer::write_start(Cursor::new(Vec::new()), &config)?;
    writer.add_track(&::mp4::TrackConfig {
        track_type: ::mp4::TrackType::Video,
        timescale: timescale(fps),
        language: "und".to_string(),
        media_conf: ::mp4::MediaConfig::AvcConfig(::mp4::AvcConfig {
            width: stream.width as u16,
            height: stream.height as u16,
            seq_param_set: stream.sps.clone(),
            pic_param_set: stream.pps.clone(),
        }),
    })?;
    for (i, frame) in stream.frames.iter().enumerate() {
        writer.write_sample(
            1,
            &::mp4::Mp4Sample {
                start_time: i as u64 * TICKS_PER_FRAME as u64,
                duration: TICKS_PER_FRAME,
                rendering_offset: 0,
                is_sync: frame.is_sync,
                bytes: bytes::Bytes::copy_from_slice(&frame.avcc),
            },
        )?;
    }
    writer.write_end()?;
    Ok(writer.into_writer().into_inner())
}

/// Encodes validated RGB `frames` to an H.264 MP4 at `path`, atomically.
pub(crate) fn write_mp4(
    path: &Path,
    frames: &[Image],
    fps: f32,
    opts: &VideoOptions,
) -> Result<()> {
    if fps > MAX_MP4_FPS {
        return Err(SceneError::invalid(
            path,
            format!(
                "MP4 cannot record {fps} fps: its 32-bit track timescale holds at most {MAX_MP4_FPS} fps"
            ),
        ));
    }
    let stream = encode(path, frames, fps, opts)?;
    let bytes = mux(&stream, fps)
        .map_err(|e| SceneError::format(path, format!("cannot write MP4 container: {e}")))?;
    fewview_scene::atomic::write_bytes(path, &bytes)
}

/// The video track of an MP4, demuxed: parameter sets, samples as length-prefixed NAL units.
struct Demuxed {
    parameter_sets: Vec<Vec<u8>>,
    length_size: usize,
    samples: Vec<Vec<u8>>,
    fps: f32,
}

fn demux(path: &Path) -> Result<Demuxed> {
    let file = std::fs::File::open(path).map_err(|e| SceneError::io(path, e))?;
    let size = file.metadata().map_err(|e| SceneError::io(path, e))?.len();
    let corrupt =
        |e: ::mp4::Error| SceneError::format(path, format!("corrupt or unreadable MP4: {e}"));
    let mut reader = ::mp4::Mp4Reader::read_header(BufReader::new(file), size).map_err(corrupt)?;
    if reader.is_fragmented() {
        return Err(SceneError::format(path, "fragmented MP4 is not supported"));
    }

    let mut video_tracks: Vec<&::mp4::Mp4Track> = reader
        .tracks()
        .values()
        .filter(|t| matches!(t.track_type(), Ok(::mp4::TrackType::Video)))
        .collect();
    video_tracks.sort_by_key(|t| t.track_id());
    let Some(track) = video_tracks.first() else {
        return Err(SceneError::format(path, "MP4 has no video track"));
    };
    let stsd = &track.trak.mdia.minf.stbl.stsd;
    let Some(avc1) = stsd.avc1.as_ref() else {
        let codec = if stsd.hev1.is_some() {
            "H.265/HEVC (hev1)".to_string()
        } else if stsd.vp09.is_some() {
            "VP9 (vp09)".to_string()
        } else {
            "an unknown codec".to_string()
        };
        return Err(SceneError::format(
            path,
            format!("unsupported video codec {codec}: only H.264 (avc1) MP4 is supported"),
        ));
    };
    let avcc = &avc1.avcc;
    let parameter_sets = avcc
        .sequence_parameter_sets
        .iter()
        .chain(&avcc.picture_parameter_sets)
        .map(|n| n.bytes.clone())
        .collect();
    let length_size = (avcc.length_size_minus_one & 0b11) as usize + 1;
    let track_id = track.track_id();
    let track_timescale = track.timescale();
    let sample_count = track.sample_count();
    let total_ticks: u64 = track
        .trak
        .mdia
        .minf
        .stbl
        .stts
        .entries
        .iter()
        .map(|e| e.sample_count as u64 * e.sample_delta as u64)
        .sum();
    if sample_count == 0 {
        return Err(SceneError::format(path, "MP4 video track has no frames"));
    }
    let fps = if total_ticks > 0 {
        (sample_count as f64 * track_timescale as f64 / total_ticks as f64) as f32
    } else {
        return Err(SceneError::format(
            path,
            "MP4 video track has zero duration",
        ));
    };

    let mut samples = Vec::with_capacity(sample_count as usize);
    for id in 1..=sample_count {
        match reader.read_sample(track_id, id).map_err(corrupt)? {
            Some(s) => samples.push(s.bytes.to_vec()),
            None => {
                return Err(SceneError::format(
                    path,
                    format!("corrupt MP4: sample {id} of {sample_count} is missing"),
                ));
            }
        }
    }
    Ok(Demuxed {
        parameter_sets,
        length_size,
        samples,
        fps,
    })
}

/// A one-line description of an OpenH264 failure: the decoder's status flags by name
/// (`DECODING_STATE` in OpenH264's `codec_def.h`), or the encoder's return code.
fn describe(e: &openh264::Error) -> String {
    const STATES: [(i64, &str); 11] = [
        (0x01, "frame pending"),
        (0x02, "reference lost"),
        (0x04, "bitstream error"),
        (0x08, "dependent layer lost"),
        (0x10, "no parameter sets"),
        (0x20, "data error concealed"),
        (0x40, "reference list error"),
        (0x1000, "invalid argument"),
        (0x2000, "not initialised"),
        (0x4000, "out of memory"),
        (0x8000, "destination buffer too small"),
    ];
    let code = e.native_code();
    let names: Vec<&str> = STATES
        .iter()
        .filter(|(bit, _)| code & bit != 0)
        .map(|s| s.1)
        .collect();
    if names.is_empty() {
        format!("OpenH264 status {code:#x}")
    } else {
        format!("{} (OpenH264 status {code:#x})", names.join(", "))
    }
}

/// Appends `nal` to `out` with an Annex B start code.
fn push_annex_b(out: &mut Vec<u8>, nal: &[u8]) {
    out.extend_from_slice(&[0, 0, 0, 1]);
    out.extend_from_slice(nal);
}

/// Converts one length-prefixed sample to Annex B; `None` when a length runs past the end.
fn avcc_to_annex_b(sample: &[u8], length_size: usize, out: &mut Vec<u8>) -> Option<()> {
    out.clear();
    let mut rest = sample;
    while !rest.is_empty() {
        if rest.len() < length_size {
            return None;
        }
        let len = rest[..length_size]
            .iter()
            .fold(0usize, |acc, &b| (acc << 8) | b as usize);
        rest = &rest[length_size..];
        if len > rest.len() {
            return None;
        }
        push_annex_b(out, &rest[..len]);
        rest = &rest[len..];
    }
    Some(())
}

/// Colour format and sanity checks from the first SPS (ITU-T H.264 7.3.2.1.1 and Annex E).
fn stream_format(path: &Path, sps_nal: &[u8]) -> Result<YuvFormat> {
    use h264_reader::nal::sps::{ChromaFormat, SeqParameterSet};
    let bad = |m: String| SceneError::format(path, m);
    let rbsp = h264_reader::rbsp::decode_nal(sps_nal)
        .map_err(|e| bad(format!("corrupt H.264 sequence parameter set: {e}")))?;
    let sps = SeqParameterSet::from_bits(h264_reader::rbsp::BitReader::new(&*rbsp))
        .map_err(|e| bad(format!("corrupt H.264 sequence parameter set: {e:?}")))?;
    if sps.chroma_info.chroma_format != ChromaFormat::YUV420 {
        return Err(bad(format!(
            "unsupported H.264 chroma format {:?} (only 4:2:0 is supported)",
            sps.chroma_info.chroma_format
        )));
    }
    if sps.chroma_info.bit_depth_luma_minus8 != 0 || sps.chroma_info.bit_depth_chroma_minus8 != 0 {
        return Err(bad(format!(
            "unsupported H.264 bit depth {} (only 8-bit is supported)",
            8 + sps.chroma_info.bit_depth_luma_minus8
        )));
    }
    let signal = sps
        .vui_parameters
        .as_ref()
        .and_then(|v| v.video_signal_type.as_ref());
    let full_range = signal.is_some_and(|s| s.video_full_range_flag);
    let matrix_code = signal
        .and_then(|s| s.colour_description.as_ref())
        .map(|c| c.matrix_coefficients);
    let matrix = match matrix_code {
        Some(1) => Matrix::Bt709,
        Some(9) => Matrix::Bt2020,
        // 5, 6 (BT.601), 2 (unspecified) and an absent VUI: BT.601, FFmpeg's assumption.
        Some(2 | 5 | 6) | None => Matrix::Bt601,
        Some(other) => {
            return Err(bad(format!(
                "unsupported H.264 colour matrix (matrix_coefficients = {other})"
            )));
        }
    };
    Ok(YuvFormat { matrix, full_range })
}

/// Decodes the MP4 at `path` to 8-bit Y'CbCr 4:2:0 pictures in display order, with the colour
/// format the stream declares and its frame rate.
pub(crate) fn decode_mp4_yuv(path: &Path) -> Result<(Vec<Yuv420>, YuvFormat, f32)> {
    // The `mp4` crate may panic on adversarial box tables; a corrupt file must be an error.
    let demuxed = std::panic::catch_unwind(|| demux(path)).unwrap_or_else(|_| {
        Err(SceneError::format(
            path,
            "corrupt MP4: malformed box tables",
        ))
    })?;
    let sps = demuxed
        .parameter_sets
        .iter()
        .find(|n| n.first().is_some_and(|b| b & 0x1f == NAL_SPS))
        .ok_or_else(|| SceneError::format(path, "MP4 avcC box has no sequence parameter set"))?;
    let format = stream_format(path, sps)?;

    let decoder_error = |e: openh264::Error| {
        SceneError::format(
            path,
            format!("H.264 decoder failed to start: {}", describe(&e)),
        )
    };
    let config = DecoderConfig::new().flush_after_decode(Flush::NoFlush);
    let mut decoder =
        Decoder::with_api_config(OpenH264API::from_source(), config).map_err(decoder_error)?;
    let mut pictures = Vec::with_capacity(demuxed.samples.len());
    let take = |yuv: &openh264::decoder::DecodedYUV<'_>| {
        Yuv420::from_strided(yuv.dimensions(), (yuv.y(), yuv.u(), yuv.v()), yuv.strides())
    };

    let mut packet = Vec::new();
    for ps in &demuxed.parameter_sets {
        push_annex_b(&mut packet, ps);
    }
    decoder.decode(&packet).map_err(|e| {
        SceneError::format(
            path,
            format!("corrupt H.264 parameter sets: {}", describe(&e)),
        )
    })?;
    for (index, sample) in demuxed.samples.iter().enumerate() {
        avcc_to_annex_b(sample, demuxed.length_size, &mut packet).ok_or_else(|| {
            SceneError::format(
                path,
                format!("corrupt H.264 data in frame {index}: bad NAL length"),
            )
        })?;
        let decoded = decoder.decode(&packet).map_err(|e| {
            SceneError::format(
                path,
                format!("corrupt H.264 data in frame {index}: {}", describe(&e)),
            )
        })?;
        if let Some(yuv) = decoded {
            pictures.push(take(&yuv));
        }
    }
    let rest = decoder.flush_remaining().map_err(|e| {
        SceneError::format(
            path,
            format!("corrupt H.264 data at the end: {}", describe(&e)),
        )
    })?;
    pictures.extend(rest.iter().map(take));

    if pictures.len() != demuxed.samples.len() {
        return Err(SceneError::format(
            path,
            format!(
                "corrupt H.264 stream: decoded {} pictures from {} frames",
                pictures.len(),
                demuxed.samples.len()
            ),
        ));
    }
    Ok((pictures, format, demuxed.fps))
}

/// Reads an H.264 MP4 as RGB frames and its frame rate.
pub(crate) fn read_mp4(path: &Path) -> Result<(Vec<Image>, f32)> {
    let (pictures, format, fps) = decode_mp4_yuv(path)?;
    let frames = pictures.iter().map(|p| yuv420_to_rgb(p, format)).collect();
    Ok((frames, fps))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn annex_b_split_and_length_prefix_round_trip() {
        let stream = [
            0, 0, 0, 1, 0x67, 1, 2, 0, 0, 1, 0x68, 3, 0, 0, 0, 0, 1, 0x65, 9, 9,
        ];
        let units = split_annex_b(&stream);
        assert_eq!(
            units,
            vec![&[0x67, 1, 2][..], &[0x68, 3][..], &[0x65, 9, 9][..]]
        );
        let mut avcc = Vec::new();
        for u in &units {
            avcc.extend_from_slice(&(u.len() as u32).to_be_bytes());
            avcc.extend_from_slice(u);
        }
        let mut back = Vec::new();
        avcc_to_annex_b(&avcc, 4, &mut back).unwrap();
        assert_eq!(split_annex_b(&back), units);
        assert!(avcc_to_annex_b(&avcc[..avcc.len() - 1], 4, &mut back).is_none());
    }

    #[test]
    fn odd_sizes_pad_or_crop_to_even() {
        assert_eq!(coded_size(33, 21, OddSizePolicy::PadEdge), (34, 22));
        assert_eq!(coded_size(33, 21, OddSizePolicy::Crop), (32, 20));
        assert_eq!(coded_size(32, 20, OddSizePolicy::PadEdge), (32, 20));
        let mut img = Image::new(3, 1, 3);
        img.data = vec![0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9];
        let padded = fit_to(&img, (4, 2));
        assert_eq!(padded.pixel(3, 1), &[0.7, 0.8, 0.9]);
        assert_eq!(padded.pixel(1, 1), &[0.4, 0.5, 0.6]);
        assert_eq!(timescale(29.97), 29970);
    }

    /// Levels of common formats, as Table A-1 assigns them.
    #[test]
    fn levels_follow_table_a1() {
        let name = |w, h, fps| h264_level(w, h, fps).map(|l| format!("{:?}", l.level));
        assert_eq!(name(128, 96, 24.0), Some("Level_3_0".into()));
        assert_eq!(name(720, 576, 25.0), Some("Level_3_0".into())); // 1620 MBs at 40 500 MB/s
        assert_eq!(name(1280, 720, 30.0), Some("Level_3_1".into()));
        assert_eq!(name(1280, 720, 60.0), Some("Level_3_2".into()));
        assert_eq!(name(1920, 1080, 30.0), Some("Level_4_0".into()));
        assert_eq!(name(1920, 1080, 60.0), Some("Level_4_2".into()));
        assert_eq!(name(3840, 2160, 30.0), Some("Level_5_1".into()));
        assert_eq!(name(3840, 2160, 120.0), None);
        // A 204-macroblock-wide strip fits level 3.0's MaxFS but not its √(8 · MaxFS) = 113.8
        // macroblocks, nor 3.2's 202.4; level 4.0 (256) admits it.
        assert_eq!(name(3264, 16, 30.0), Some("Level_4_0".into()));
        assert_eq!(name(3232, 16, 30.0), Some("Level_3_2".into()));
        assert_eq!(timescale(24.0), 24000);
    }
}
