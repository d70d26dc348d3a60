//! # bspvt-server
//!
//! The HTTP baking service of bspvt ([`service`]): uploads become checked scenes, bakes run as
//! queued, resumable jobs of chunks (the [`bspvt_bake`] engine), chunks are durable before they
//! are reported, and trees stream to clients as they are baked. [`bench`](mod@bench) is the bake's
//! benchmark (`bspvt-server bench`).
//!
//! Owns: the job store (SQLite), chunk files, the axum API. Wire types shared with clients
//! live in [`bspvt_proto::api`]. Must not depend on: the client crates.

#![warn(unreachable_pub, missing_docs)]

pub mod bench;
pub mod service;
