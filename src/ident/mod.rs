//! Black-box identification of the carrier (seed chapter 4): ARX/ARMAX structures, recursive
//! least squares with forgetting (f32, U-D factorised, for the MCU), recursive extended least
//! squares, batch least squares (f64 reference), PRBS excitation and validation.
//!
//! Glossary: θ — parameter vector; φ — regressor; P — parameter covariance (scaled);
//! λ_f — forgetting factor; ε — a-priori prediction error; RELS — recursive extended least
//! squares, RLS on φ extended with past residuals to estimate C of an ARMAX model
//! (Ljung 1999, §11.3 "pseudolinear regression"); nk — delay in samples.

pub mod batch;
pub mod model;
pub mod prbs;
pub mod recursive;
pub mod rls;
pub mod validate;
