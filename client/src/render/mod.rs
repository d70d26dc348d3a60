//! The headless renderer: camera, primary visibility, per-frame shading, image output.

pub mod camera;
pub mod gbuffer;
pub mod image;
pub mod path;
pub mod posed;
pub mod renderer;
pub mod sequence;
