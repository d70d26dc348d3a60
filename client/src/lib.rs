//! # bspvt (client)
//!
//! Reads baked BSPVT trees and shades with them. [`visibility`]: the visible fraction of each
//! light polygon from each vertex (eq. 2 of paper 000 with f_r = 1). [`ggx`]: the reference
//! GGX BRDF.

pub mod bench;
pub mod compare;
pub mod frame;
pub mod ggx;
pub mod groundtruth;
pub mod light;
pub mod ltc;
pub mod mitsuba;
pub mod penumbra;
pub mod play;
pub mod render;
pub mod report;
pub mod session;
pub mod sg;
pub mod shade;
pub mod stream;
pub mod texture;
pub mod viewer;
pub mod visibility;
