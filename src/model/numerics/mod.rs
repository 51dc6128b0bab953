//! The numerical kernels the rungs share: Gauss-Legendre quadrature (`quadrature.rs`), the
//! specular node loop as SIMD code chosen at run time (`lobe_quadrature.rs`, `lanes.rs`) and
//! inline atan2/asin/acos/sin/cos for the geometry (`elementary.rs`), each tested against std
//! to a few ulp. A reader looking for a rung finds it one level up, in `src/model/`.

pub mod elementary;
pub mod lanes;
pub mod lobe_quadrature;
pub mod quadrature;
