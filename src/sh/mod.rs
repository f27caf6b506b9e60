//! Spherical harmonics at any order: basis, quadrature, rotation, products and
//! exponentiation. The conventions are stated once, in [`basis`].
pub mod basis;
pub mod quadrature;

pub use basis::{coefficient_count, eval_basis, eval_expansion, index, Real, MAX_COEFFICIENTS, MAX_ORDER, MIN_ORDER};
pub use quadrature::SphereQuadrature;
