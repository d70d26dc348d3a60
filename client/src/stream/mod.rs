//! Streaming client: a scene's trees from a bspvt service, progressively, with an on-disk cache.
//!
//! [`remote::Remote`] speaks the HTTP API; [`fetch::spawn`] fills the trees on a background
//! thread (view-first order, resume after drops, cache); [`trees::StreamedTrees`] is what the
//! renderer reads, frame by frame; [`source::open`] turns what a user names (a URL, a scene id,
//! a scene file, a mesh) into a served scene, starting an embedded service when needed;
//! [`error::StreamError`] says which failures are final (404, 410, refused) and which are
//! retried (dropped connections, a busy service).

pub mod cache;
pub mod error;
pub mod fetch;
mod form;
pub mod frames;
pub mod remote;
pub mod source;
pub mod trees;
