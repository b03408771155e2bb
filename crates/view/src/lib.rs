//! `fewview view`: an interactive viewer of a run in the browser. [`Run::open`] reads a run
//! directory (or [`Run::from_ply`] a single Gaussian PLY), checks what the page will need
//! before anything is served, and [`server::serve`] serves the page on loopback.
//!
//! The page (`web/view/`, embedded in the binary, nothing fetched at run time) draws the
//! Gaussians itself with WebGL2, with the projection, colour and compositing rules of
//! `fewview_splat::raster`, streaming the PLY as it arrives; a surface run's mesh is drawn as
//! a shaded triangle mesh, and the points of a `fewview poses` model as dots. Beside the 3D
//! view it shows the run's cameras (training and held-out, the initial and refined poses of a
//! surface run, or the estimated cameras of a poses folder), `metrics.json` (a poses folder's
//! report), the held-out renders beside their ground truth and the run's videos.

pub mod error;
pub mod ply;
pub mod run;
pub mod server;

pub use error::ViewError;
pub use run::{OpenOptions, Run, RunKind};
