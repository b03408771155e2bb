//! What a caller chooses when writing and reading videos.

/// How hard the H.264 encoder compresses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum H264Quality {
    /// A fixed quantiser, 12 (finest OpenH264 allows in its rate-controlled modes; lower values
    /// act as 12) to 51 (smallest file); every frame gets the same quantisation whatever its
    /// content. H.264's quantiser step doubles every 6 points.
    ConstantQp(u8),
    /// A target average bitrate; quality then varies with content. Frames are never dropped to
    /// meet it (the frame count must survive), so a target too low for the content is
    /// overshot rather than met.
    Bitrate { bits_per_second: u32 },
}

/// Default quantiser. On the smooth synthetic animation of the round-trip test it gives
/// ≥ 38.3 dB PSNR on every frame at 0.35 bit/pixel (128×96, 24 frames) and ≥ 43.9 dB at
/// 0.11 bit/pixel (512×512, 60 frames), within ~2.5 dB of what 4:2:0 chroma subsampling alone
/// allows; QP 12 / 24 / 30 give ≥ 39.6 / 36.5 / 33.9 dB at 0.57 / 0.22 / 0.15 bit/pixel.
pub const DEFAULT_QP: u8 = 18;

impl Default for H264Quality {
    fn default() -> Self {
        H264Quality::ConstantQp(DEFAULT_QP)
    }
}

/// What to do with an odd width or height for H.264 4:2:0 (which needs both even).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum OddSizePolicy {
    /// Add one row/column repeating the last one (keeps every pixel; output grows by one).
    #[default]
    PadEdge,
    /// Drop the last row/column.
    Crop,
}

/// Options of [`write_video`](crate::write_video); each applies to the containers named in its doc.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct VideoOptions {
    /// MP4: quantiser or bitrate.
    pub quality: H264Quality,
    /// MP4: an IDR (seekable) frame every this many frames; 0 = only the first frame.
    pub keyframe_interval: u32,
    /// MP4: odd sizes are padded or cropped.
    pub odd_size: OddSizePolicy,
    /// GIF: NeuQuant sampling factor, 1 (best palette, slowest) to 30 (fastest). The default 3
    /// costs ~25 ms per 256² frame per core and is ~2 dB better than the `gif` crate's 10.
    pub gif_speed: i32,
}

impl Default for VideoOptions {
    fn default() -> Self {
        Self {
            quality: H264Quality::default(),
            keyframe_interval: 60,
            odd_size: OddSizePolicy::default(),
            gif_speed: 3,
        }
    }
}

/// Options of [`read_video_with`](crate::read_video_with).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReadOptions {
    /// The colour transparent GIF/PNG pixels are composited over (sR'G'B' in `[0, 1]`).
    pub background: [f32; 3],
}

impl Default for ReadOptions {
    fn default() -> Self {
        Self {
            background: [1.0, 1.0, 1.0],
        }
    }
}
