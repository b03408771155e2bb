//! Joint optimisation of the field and the camera poses (the surface paper §3.5):
//!
//! `L = L_C + λ_u L_u + λ_geo L_geo` with `L_C = colour + λ_M.C. L_M.C.` (Eq. 10),
//! `L_u = L_u,ncc + λ_u,gc L_u,gc` (Eqs. 6, 7, 11), `L_geo = L_Eik + λ_pSDF L_pSDF` (Eqs. 8, 9),
//! plus NeuS's mask loss when masks are used.
//!
//! Each iteration draws random pixels of random training views and a batch of correspondences
//! (both ends rendered), samples the rays (NeuS up-sampling, no gradient), renders them with
//! gradients to the field and the poses, and takes one Adam step for the field and one for the
//! poses (separate optimisers, the surface paper §B.1). All randomness comes from
//! `(seed, iteration)`, so a run resumed from a checkpoint repeats the uninterrupted run.

pub mod config;
pub mod state;
pub mod trainer;

pub use config::{LossConfig, TrainConfig};
pub use state::{StepStats, TrainState, TrainView};
pub use trainer::Trainer;
