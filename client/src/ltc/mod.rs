//! Linearly transformed cosines (Heitz, Dupuy, Hill, Neubelt 2016): the GGX lobe approximated
//! by a clamped cosine transformed by a 3×3 matrix M, so that its integral over a polygon is
//! the cosine integral (form factor) of the polygon transformed by M⁻¹.
//!
//! - [`fit`]: the project's own fit of M, the magnitude and the Fresnel term (the table in
//!   `assets/ltc/` and the `bspvt ltc-fit` command that regenerates it);
//! - [`table`]: the table and its lookup by roughness and view angle;
//! - [`polygon`]: the polygon integral (horizon clip, stable edge integral).

pub mod polygon;
pub use bspvt_shaders::ltc_table as table;
