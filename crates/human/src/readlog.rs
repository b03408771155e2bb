//! A record of every file a dataset reads, so that "held-out cameras and test frames are never
//! read during training" is a property a test can check rather than a promise.
//!
//! Datasets record two kinds of reads: [`ReadKind::Header`] when opening checks a file's shape
//! or size (array headers, image dimensions) without taking its values, and
//! [`ReadKind::Content`] when per-`(camera, frame)` data is read. Whole-sequence arrays (joints)
//! are read one frame's rows at a time, so each content read belongs to one camera and frame.

use std::path::{Path, PathBuf};
use std::sync::Mutex;

/// What a read took from the file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ReadKind {
    /// Shape or size only (checked when a dataset is opened).
    Header,
    /// Pixel or joint values.
    Content,
}

/// One file read.
#[derive(Clone, Debug, PartialEq)]
pub struct Read {
    pub path: PathBuf,
    pub kind: ReadKind,
    /// The camera the data belongs to (`None` for per-frame data such as 3D joints).
    pub camera: Option<usize>,
    /// The frame the data belongs to (`None` for headers of whole-sequence files).
    pub frame: Option<usize>,
}

/// A thread-safe, append-only list of reads.
#[derive(Debug, Default)]
pub struct ReadLog {
    reads: Mutex<Vec<Read>>,
}

impl ReadLog {
    pub fn record(&self, path: &Path, kind: ReadKind, camera: Option<usize>, frame: Option<usize>) {
        let read = Read {
            path: path.to_path_buf(),
            kind,
            camera,
            frame,
        };
        // A poisoned lock only means another thread panicked mid-push; the list is still valid.
        let mut reads = self
            .reads
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        reads.push(read);
    }

    /// Every read so far, in order.
    pub fn reads(&self) -> Vec<Read> {
        self.reads
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .clone()
    }

    /// The content reads so far.
    pub fn content_reads(&self) -> Vec<Read> {
        let reads = self.reads();
        reads
            .into_iter()
            .filter(|r| r.kind == ReadKind::Content)
            .collect()
    }

    /// Number of reads so far.
    pub fn len(&self) -> usize {
        self.reads
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}
