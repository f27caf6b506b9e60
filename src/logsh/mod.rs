//! Log-SH building blocks of paper 000 at any order: height-field slices and wedges
//! (Eq. 15-23), sphere caps (Eq. 24-26) and BRDF lobes (Eq. 27), all as log vectors that
//! are summed per pixel and exponentiated once.
pub mod cap;
pub mod lobe;
pub mod minimise;
pub mod slice;
pub mod training;
pub mod wedge;

pub use cap::{cap_log_zh, cap_scale, own_sphere_holds, view_blocker, BlockerView, OWN_SPHERE_REACH};
pub use lobe::{
    lobe_exp_error, lobe_log_zh, lobe_log_zh_as, lobe_zh, optimal_lobe_epsilon, shared_optimal_lobe_epsilon, Lobe,
};
pub use slice::{nlp_slice, nlp_slice_of_sine};
pub use training::training_log_vectors;
pub use wedge::{WedgeOperator, WedgeTurn};
