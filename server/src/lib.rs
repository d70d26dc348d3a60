//! # bspvt-server
//!
//! The bake engine of bspvt: per-vertex ray-cast visibility cube maps ([`bake::cubemap`],
//! [`bake::raycast`] on an obvhs CWBVH) fitted into BSPVTs ([`bake::fit`]), encoded in chunks
//! ([`bspvt_proto::encoding`]). [`bench`] measures it; [`stats`] reports a bake.

pub mod bake;
pub mod bench;
#[cfg(feature = "service")]
pub mod service;
pub mod stats;
