//! Spherical harmonics at any order: basis, quadrature, rotation, products and
//! exponentiation. The conventions are stated once, in [`basis`].
pub mod basis;
pub mod exp;
pub mod folded;
pub mod product;
pub mod quadrature;
pub mod rotation;
pub mod separable;

pub use basis::{coefficient_count, eval_basis, eval_expansion, index, Real, MAX_COEFFICIENTS, MAX_ORDER, MIN_ORDER};
pub use exp::{exp_hyb, exp_series, ExactExp, ExpMethod, OlTable};
pub use folded::FoldedQuadrature;
pub use product::TriplingTensor;
pub use quadrature::SphereQuadrature;
pub use rotation::{add_rotated_zonal, rotate_z, rotate_zonal};
pub use separable::SeparableQuadrature;
