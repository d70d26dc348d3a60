//! # bspvt (client)
//!
//! Reads baked BSPVT trees and evaluates light visibility from them. Today: the visible
//! fraction of each light polygon from each vertex ([`visibility`]), which is eq. 2 of paper
//! 000 with f_r = 1 — the shadow term the LTC shading (next issue) weights per piece.

pub mod visibility;
