//! # bspvt-proto
//!
//! The shared language of the bspvt baking server and its streaming client:
//!
//! - [`scene`]: the scene model and its JSON file format; [`Mesh`] (with [`Aabb`]) and
//!   [`import`] (glTF, OBJ, PLY) for geometry; [`builtin`] procedural scenes that need no
//!   download.
//! - [`motion`]: how a scene's meshes are placed and move over an animation cycle (run-time
//!   methods).
//! - [`cubemap`]: the world-aligned cube-map layout every vertex's visibility is sampled on.
//! - [`bspvt`]: Binary Space Partitioning Visibility Trees — quantised split lines, the per-face
//!   tree, the point query and the split of a spherical polygon into pieces with leaf values.
//! - [`sphere`]: spherical polygons (great-circle clipping, solid angle).
//! - [`encoding`]: the compact, versioned, checksummed chunk encoding of trees.
//! - [`api`]: the wire types of the baking service's HTTP API (status, job state, errors,
//!   the stored scene), so that a client needs no server code.
//! - [`texture`]: surface textures (decoded images, bilinear sampling) and the material they
//!   modulate.
//! - [`paths`]: where files not given on the command line are looked for, at run time.
//!
//! - [`error`]: the errors of user-supplied data; [`hash`]: FNV-1a for content identity.
//!
//! Math kernels here do no I/O; only [`import`] and [`scene`] loaders touch files.
//! Must not depend on: the other bspvt crates (this is the bottom of their graph), ray
//! casting, HTTP, a database, or anything of rendering.

#![warn(unreachable_pub, missing_docs)]

pub mod api;
pub mod bspvt;
pub(crate) mod camera;
pub mod cubemap;
pub mod encoding;
pub(crate) mod environment;
pub mod error;
pub mod hash;
pub mod import;
pub(crate) mod light;
pub(crate) mod material;
pub(crate) mod mesh;
pub mod motion;
pub mod paths;
pub mod scene;
pub mod sphere;
pub mod srgb;
pub mod texture;

pub use error::{DecodeError, MeshError, SceneError};
pub use mesh::{Aabb, Mesh};
pub use scene::builtin;
pub use scene::{BakeSettings, Scene, SplitMethod};
