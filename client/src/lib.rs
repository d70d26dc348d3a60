//! # bspvt-client
//!
//! The bspvt client library: streams baked BSPVT trees from a service and shades polygonal
//! lights with them (LTC GGX over the pieces of the light the trees cut, paper 000), beside the
//! sibling methods (spherical-Gaussian environment light with an SSDF, paper 001; ray-traced
//! point-light penumbrae, paper 003), the baselines and the Monte Carlo references.
//!
//! Layers, bottom up (a module only uses modules of its own layer or below):
//!
//! 1. kernels, free of I/O: [`ggx`], [`ltc`], [`shade`], [`sg`]'s lobes, [`texture`], [`light`];
//! 2. [`frame`]: the image, camera, G-buffer, BRDF and shadow-ray types every method shares;
//!    [`envmap`]: the environment map; [`sky`]: the map as textured quad lights at infinity;
//!    [`sky_cells`]: the sphere of directions as world-fixed cells, for a map that turns;
//! 3. [`render`] (per-vertex / per-pixel frames), [`gpu`] (the same on the GPU),
//!    [`groundtruth`], [`penumbra`], [`sg`], [`ratio`];
//! 4. [`method`]: the [`method::FrameMethod`] interface and its registry, one file per method;
//! 5. [`stream`] (the service's client), [`session`] (what a viewer shows), [`viewer`].
//!
//! Must not depend on: the baking service (`bspvt-server`), axum, a database, clap. The
//! embedded service that `bspvt demo` starts comes from the command line's `service` feature
//! through [`stream::source::Embedded`].

#![warn(unreachable_pub, missing_docs)]

pub mod envmap;
pub mod frame;
pub use bspvt_shaders::ggx;
pub mod gpu;
pub mod groundtruth;
pub mod light;
pub mod ltc;
pub mod method;
pub mod penumbra;
pub mod ratio;
pub mod render;
pub mod scene;
pub mod session;
pub mod sg;
pub mod shade;
pub mod sky;
pub mod sky_cells;
pub mod stream;
pub mod texture;
pub mod viewer;
pub mod visibility;
